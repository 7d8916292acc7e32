//! One check's result: its name, its verdict, what was found and, when it did not pass, the fix;
//! printed as a line for people or as one JSON object.

use scout_interface::failure::Failure;
use serde_json::{Value, json};

/// How a check came out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Fine.
    Pass,
    /// Works, but worth knowing (the exit code stays 0).
    Warn,
    /// Broken: the exit code is 1.
    Fail,
    /// Not run: an earlier check failed or it does not apply.
    Skip,
}

impl Verdict {
    /// Its name in the output.
    pub fn name(self) -> &'static str {
        match self {
            Self::Pass => "pass",
            Self::Warn => "warn",
            Self::Fail => "fail",
            Self::Skip => "skip",
        }
    }
}

/// One check's result.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Check {
    /// What was checked (`device`, `can.bitrate`, `chassis.estop`...).
    pub name: &'static str,
    /// How it came out.
    pub verdict: Verdict,
    /// What was found.
    pub detail: String,
    /// What to do, when it did not pass.
    pub fix: Option<String>,
}

impl Check {
    /// A passed check.
    pub fn pass(name: &'static str, detail: impl Into<String>) -> Self {
        Self {
            name,
            verdict: Verdict::Pass,
            detail: detail.into(),
            fix: None,
        }
    }

    /// A warning, with what to do.
    pub fn warn(name: &'static str, detail: impl Into<String>, fix: impl Into<String>) -> Self {
        Self {
            name,
            verdict: Verdict::Warn,
            detail: detail.into(),
            fix: Some(fix.into()),
        }
    }

    /// A failure, with the fix.
    pub fn fail(name: &'static str, detail: impl Into<String>, fix: impl Into<String>) -> Self {
        Self {
            name,
            verdict: Verdict::Fail,
            detail: detail.into(),
            fix: Some(fix.into()),
        }
    }

    /// A check not run, and why.
    pub fn skip(name: &'static str, why: impl Into<String>) -> Self {
        Self {
            name,
            verdict: Verdict::Skip,
            detail: why.into(),
            fix: None,
        }
    }

    /// One line for people: `[fail] name: detail` and the fix on the next line.
    pub fn line(&self) -> String {
        let mut line = format!("[{}] {}: {}", self.verdict.name(), self.name, self.detail);
        if let Some(fix) = &self.fix {
            line.push_str("\n       fix: ");
            line.push_str(fix);
        }
        line
    }

    /// One JSON object: `check`, `verdict`, `detail`, `fix` (null when none).
    pub fn json(&self) -> Value {
        json!({
            "check": self.name,
            "verdict": self.verdict.name(),
            "detail": self.detail,
            "fix": self.fix,
        })
    }
}

/// The exit code for these checks: [`Failure::Failed`]'s when one failed, else 0.
pub fn exit_code(checks: &[Check]) -> u8 {
    if checks.iter().any(|check| check.verdict == Verdict::Fail) {
        Failure::Failed.exit_code()
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_prints_its_fix_and_makes_the_exit_code_1() {
        let fail = Check::fail("device", "no /dev/ttyUSB0", "plug the adapter in");
        assert_eq!(
            fail.line(),
            "[fail] device: no /dev/ttyUSB0\n       fix: plug the adapter in"
        );
        assert_eq!(fail.json()["verdict"], "fail");
        assert_eq!(fail.json()["fix"], "plug the adapter in");
        let warn = Check::warn("chassis.battery", "22.9 V", "charge it");
        let pass = Check::pass("traffic", "50 frames");
        assert_eq!(pass.json()["fix"], Value::Null);
        assert_eq!(exit_code(&[pass.clone(), warn.clone()]), 0);
        assert_eq!(exit_code(&[pass, warn, fail]), 1);
        assert_eq!(exit_code(&[]), 0);
    }
}
