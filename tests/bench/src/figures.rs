//! Figures from samples: latency summaries, tick-interval statistics, and the simulator's trace
//! of the wire read back.

use std::path::Path;

use anyhow::Context;
use serde_json::{Value, json};

/// A latency distribution: p50, p99, p99.9, max and the count, in the unit of the samples.
#[derive(Debug, Clone, Copy, Default)]
pub struct Summary {
    pub n: usize,
    pub p50: f64,
    pub p99: f64,
    pub p999: f64,
    pub max: f64,
}

impl Summary {
    pub fn of(samples: &[f64]) -> Summary {
        if samples.is_empty() {
            return Summary::default();
        }
        let mut sorted = samples.to_vec();
        sorted.sort_by(f64::total_cmp);
        let at = |q: f64| sorted[((sorted.len() as f64 * q) as usize).min(sorted.len() - 1)];
        Summary {
            n: sorted.len(),
            p50: at(0.5),
            p99: at(0.99),
            p999: at(0.999),
            max: sorted[sorted.len() - 1],
        }
    }

    pub fn json(&self) -> Value {
        json!({ "p50": round(self.p50), "p99": round(self.p99), "p999": round(self.p999),
                "max": round(self.max), "n": self.n })
    }

    /// `p50 / p99 / p99.9 / max (n)` for the table.
    pub fn row(&self) -> String {
        format!(
            "{:.1} / {:.1} / {:.1} / {:.1} ({})",
            self.p50, self.p99, self.p999, self.max, self.n
        )
    }
}

/// Three decimals: figures, not noise.
pub fn round(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// Intervals between motion commands, ms: mean, p99 deviation from 20 ms, max, and how many
/// exceeded 25 and 40 ms.
#[derive(Debug, Clone, Default)]
pub struct Ticks {
    pub intervals_ms: Vec<f64>,
}

impl Ticks {
    pub fn json(&self) -> Value {
        let n = self.intervals_ms.len();
        let deviations: Vec<f64> = self
            .intervals_ms
            .iter()
            .map(|ms| (ms - 20.0).abs())
            .collect();
        json!({
            "mean": round(self.intervals_ms.iter().sum::<f64>() / n.max(1) as f64),
            "p99_dev": round(Summary::of(&deviations).p99),
            "max": round(self.intervals_ms.iter().copied().fold(0.0, f64::max)),
            "over_25": self.intervals_ms.iter().filter(|ms| **ms > 25.0).count(),
            "over_40": self.intervals_ms.iter().filter(|ms| **ms > 40.0).count(),
            "n": n,
        })
    }
}

/// The simulator's trace (`scout-sim --trace`): feedback written, commands read, actual speed.
#[derive(Debug, Default)]
pub struct Trace {
    /// Feedback batches written, ns.
    pub feedback: Vec<u64>,
    /// Motion commands read: ns, linear m/s.
    pub commands: Vec<(u64, f64)>,
    /// Actual linear speed changes: ns, m/s.
    pub actual: Vec<(u64, f64)>,
}

impl Trace {
    pub fn read(path: &Path) -> anyhow::Result<Trace> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("reading the trace {}", path.display()))?;
        let mut trace = Trace::default();
        for line in text.lines() {
            let mut fields = line.split(' ');
            let kind = fields.next();
            let (Some(ns), value) = (fields.next().and_then(|f| f.parse().ok()), fields.next())
            else {
                continue;
            };
            let value = value.and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
            match kind {
                Some("F") => trace.feedback.push(ns),
                Some("C") => trace.commands.push((ns, value)),
                Some("A") => trace.actual.push((ns, value)),
                _ => {}
            }
        }
        Ok(trace)
    }

    /// The last feedback written at or before `ns`.
    pub fn feedback_before(&self, ns: u64) -> Option<u64> {
        let index = self.feedback.partition_point(|&at| at <= ns);
        index.checked_sub(1).map(|i| self.feedback[i])
    }

    /// The first command read after `ns` whose linear speed satisfies `wanted`.
    pub fn first_command_after(&self, ns: u64, wanted: impl Fn(f64) -> bool) -> Option<u64> {
        let start = self.commands.partition_point(|&(at, _)| at <= ns);
        self.commands[start..]
            .iter()
            .find(|(_, linear)| wanted(*linear))
            .map(|&(at, _)| at)
    }

    /// The first moment after `ns` the chassis was at rest.
    pub fn at_rest_after(&self, ns: u64) -> Option<u64> {
        let start = self.actual.partition_point(|&(at, _)| at <= ns);
        self.actual[start..]
            .iter()
            .find(|(_, linear)| *linear == 0.0)
            .map(|&(at, _)| at)
    }

    /// Intervals between the commands read within `[from, to]`, ms.
    pub fn ticks(&self, from: u64, to: u64) -> Ticks {
        let times: Vec<u64> = self
            .commands
            .iter()
            .map(|&(at, _)| at)
            .filter(|at| (from..=to).contains(at))
            .collect();
        Ticks {
            intervals_ms: times
                .windows(2)
                .map(|pair| (pair[1] - pair[0]) as f64 / 1e6)
                .collect(),
        }
    }
}

/// Reads a recording of whitespace-separated u64 columns, one row a line.
pub fn read_rows(path: &Path) -> anyhow::Result<Vec<Vec<u64>>> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(text
        .lines()
        .map(|line| {
            line.split(' ')
                .filter_map(|field| field.parse().ok())
                .collect()
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_a_known_distribution() {
        let samples: Vec<f64> = (1..=1000).map(f64::from).collect();
        let summary = Summary::of(&samples);
        assert_eq!(summary.n, 1000);
        assert_eq!(summary.p50, 501.0);
        assert_eq!(summary.p99, 991.0);
        assert_eq!(summary.p999, 1000.0);
        assert_eq!(summary.max, 1000.0);
    }

    #[test]
    fn the_trace_answers_before_and_after() {
        let trace = Trace {
            feedback: vec![10, 20, 30],
            commands: vec![(5, 0.0), (15, 0.3), (25, 0.0)],
            actual: vec![(12, 0.1), (28, 0.0)],
        };
        assert_eq!(trace.feedback_before(25), Some(20));
        assert_eq!(trace.feedback_before(5), None);
        assert_eq!(trace.first_command_after(5, |l| l > 0.0), Some(15));
        assert_eq!(trace.first_command_after(15, |l| l == 0.0), Some(25));
        assert_eq!(trace.at_rest_after(12), Some(28));
        let ticks = trace.ticks(0, 30);
        assert_eq!(ticks.intervals_ms, vec![10.0 / 1e6, 10.0 / 1e6]);
    }
}
