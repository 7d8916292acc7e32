//! The simulator's fault-injection language: one command a line, from stdin or a script file.

use std::time::Duration;

use scout_protocol::Motor;
use scout_protocol::can::CanFrame;

use crate::chassis::{Injection, MotorValue, Protection, Warning};

/// The language's reference, printed by `help` and on a parse error.
pub const HELP: &str = "\
commands (one a line; # starts a comment):
  estop on|off                 emergency stop pressed / released
  rc on|off                    RC transmitter on (host commands ignored) / off
  standby                      v2 firmware falls back to standby by itself (v1: nothing)
  protect overtemp|overcurrent latch a protection (cleared by the fault-clear code)
  warn overtemp|overcurrent on|off   force a warning / back to automatic
  motor-fault N on|off         motor N (1..4) communication fault
  battery VOLTS                set the battery's voltage at rest; it sags under load
                               (22.5 V warning, 22 V cut-off)
  charger AMPS                 a charger feeding AMPS (0: unplugged); it stops when full
  motor N current|rpm|driver-temp|motor-temp VALUE   pin a motor value
  motor N auto                 unpin motor N's values
  garbage N                    write N random bytes onto the link
  frame ID HEX                 send one CAN frame (ID and up to 8 bytes in hex, e.g.
                               `frame 291 0100000000000000`): another node, another model
  corrupt N                    send the next N feedback frames with a bad checksum
  silence MS                   send nothing for MS milliseconds
  unplug MS                    close the port, come back after MS milliseconds
  stats                        print the statistics JSON line on stdout
  wait MS                      pause the script for MS milliseconds
  quit                         exit (also Ctrl-C / SIGTERM)";

/// One command of the language.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimCommand {
    /// Change the chassis' condition.
    Inject(Injection),
    /// Write this many random bytes onto the link.
    Garbage(usize),
    /// Send this frame once, as it is (another node on the bus, another model's feedback).
    Frame(CanFrame),
    /// Corrupt the checksum of the next this many feedback frames.
    Corrupt(u32),
    /// Send nothing for this long.
    Silence(Duration),
    /// Close the port and come back after this long.
    Unplug(Duration),
    /// Print the statistics.
    Stats,
    /// Pause the script.
    Wait(Duration),
    /// Exit.
    Quit,
    /// Print the language's reference.
    Help,
}

/// A line that is not a command, with the reason.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{reason} in `{line}` (type `help` for the commands)")]
pub struct ParseError {
    line: String,
    reason: Reason,
}

/// Why a line is not a command.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Reason {
    /// No command word.
    #[error("empty command")]
    Empty,
    /// A command word, or its arguments, the language does not have.
    #[error("unknown command or arguments for `{0}`")]
    Command(String),
    /// A motor value the language does not have.
    #[error("unknown motor value `{0}`")]
    MotorValue(String),
    /// Neither `on` nor `off`.
    #[error("expected on or off, found `{0}`")]
    OnOff(String),
    /// Not a motor number.
    #[error("motor must be 1..4, found `{0}`")]
    Motor(String),
    /// Not a whole number.
    #[error("expected a whole number, found `{0}`")]
    Whole(String),
    /// Not a finite number.
    #[error("expected a number, found `{0}`")]
    Number(String),
    /// Not a CAN frame.
    #[error("expected a CAN id (hex, up to 7FF) and up to 8 bytes in hex, found `{0}`")]
    Frame(String),
}

/// Parses one line; `Ok(None)` for blank lines and comments.
pub fn parse(line: &str) -> Result<Option<SimCommand>, ParseError> {
    let text = line.split('#').next().unwrap_or("").trim();
    if text.is_empty() {
        return Ok(None);
    }
    let words: Vec<&str> = text.split_ascii_whitespace().collect();
    parse_words(&words).map(Some).map_err(|reason| ParseError {
        line: text.into(),
        reason,
    })
}

fn parse_words(words: &[&str]) -> Result<SimCommand, Reason> {
    use SimCommand::*;
    Ok(match words {
        ["estop", state] => Inject(Injection::EStop(on_off(state)?)),
        ["rc", state] => Inject(Injection::Rc(on_off(state)?)),
        ["standby"] => Inject(Injection::Standby),
        ["protect", "overtemp"] => Inject(Injection::Protect(Protection::DriverOvertemp)),
        ["protect", "overcurrent"] => Inject(Injection::Protect(Protection::MotorOvercurrent)),
        ["warn", "overtemp", state] => {
            Inject(Injection::Warn(Warning::DriverOvertemp, on_off(state)?))
        }
        ["warn", "overcurrent", state] => {
            Inject(Injection::Warn(Warning::MotorOvercurrent, on_off(state)?))
        }
        ["motor-fault", n, state] => Inject(Injection::MotorCommFault(motor(n)?, on_off(state)?)),
        ["battery", volts] => Inject(Injection::Battery(finite(volts)?)),
        ["charger", amps] => Inject(Injection::Charger(finite(amps)?)),
        ["motor", n, "auto"] => Inject(Injection::UnpinMotor(motor(n)?)),
        ["motor", n, field, value] => {
            let field = match *field {
                "current" => MotorValue::Current,
                "rpm" => MotorValue::Rpm,
                "driver-temp" => MotorValue::DriverTemperature,
                "motor-temp" => MotorValue::MotorTemperature,
                other => return Err(Reason::MotorValue(other.into())),
            };
            Inject(Injection::PinMotor(motor(n)?, field, finite(value)?))
        }
        ["garbage", n] => Garbage(number(n)?),
        ["frame", id, data] => Frame(frame(id, data)?),
        ["corrupt", n] => Corrupt(number(n)?),
        ["silence", ms] => Silence(millis(ms)?),
        ["unplug", ms] => Unplug(millis(ms)?),
        ["wait", ms] => Wait(millis(ms)?),
        ["stats"] => Stats,
        ["quit" | "exit"] => Quit,
        ["help"] => Help,
        [command, ..] => return Err(Reason::Command((*command).into())),
        [] => return Err(Reason::Empty),
    })
}

fn on_off(word: &str) -> Result<bool, Reason> {
    match word {
        "on" => Ok(true),
        "off" => Ok(false),
        other => Err(Reason::OnOff(other.into())),
    }
}

fn motor(word: &str) -> Result<Motor, Reason> {
    word.parse()
        .ok()
        .and_then(Motor::new)
        .ok_or_else(|| Reason::Motor(word.into()))
}

fn number<T: std::str::FromStr>(word: &str) -> Result<T, Reason> {
    word.parse().map_err(|_| Reason::Whole(word.into()))
}

fn finite(word: &str) -> Result<f64, Reason> {
    match word.parse::<f64>() {
        Ok(value) if value.is_finite() => Ok(value),
        _ => Err(Reason::Number(word.into())),
    }
}

fn frame(id: &str, data: &str) -> Result<CanFrame, Reason> {
    let bad = || Reason::Frame(format!("{id} {data}"));
    let id = u16::from_str_radix(id, 16).map_err(|_| bad())?;
    if !data.len().is_multiple_of(2) || !data.is_ascii() {
        return Err(bad());
    }
    let bytes = (0..data.len())
        .step_by(2)
        .map(|at| u8::from_str_radix(&data[at..at + 2], 16))
        .collect::<Result<Vec<u8>, _>>()
        .map_err(|_| bad())?;
    CanFrame::new(id, &bytes).ok_or_else(bad)
}

fn millis(word: &str) -> Result<Duration, Reason> {
    number(word).map(Duration::from_millis)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_each_command() {
        let motor2 = Motor::new(2).expect("motor 2");
        let cases = [
            ("estop on", SimCommand::Inject(Injection::EStop(true))),
            ("rc off", SimCommand::Inject(Injection::Rc(false))),
            ("standby", SimCommand::Inject(Injection::Standby)),
            (
                "frame 291 0100",
                SimCommand::Frame(CanFrame::new(0x291, &[1, 0]).expect("a frame")),
            ),
            (
                "protect overtemp",
                SimCommand::Inject(Injection::Protect(Protection::DriverOvertemp)),
            ),
            (
                "warn overcurrent on",
                SimCommand::Inject(Injection::Warn(Warning::MotorOvercurrent, true)),
            ),
            (
                "motor-fault 2 on",
                SimCommand::Inject(Injection::MotorCommFault(motor2, true)),
            ),
            ("battery 21.9", SimCommand::Inject(Injection::Battery(21.9))),
            ("charger 10", SimCommand::Inject(Injection::Charger(10.0))),
            (
                "motor 2 current -3.5",
                SimCommand::Inject(Injection::PinMotor(motor2, MotorValue::Current, -3.5)),
            ),
            (
                "motor 2 auto",
                SimCommand::Inject(Injection::UnpinMotor(motor2)),
            ),
            ("garbage 64", SimCommand::Garbage(64)),
            ("corrupt 3", SimCommand::Corrupt(3)),
            (
                "silence 300",
                SimCommand::Silence(Duration::from_millis(300)),
            ),
            (
                "unplug 1500  # come back",
                SimCommand::Unplug(Duration::from_millis(1500)),
            ),
            ("stats", SimCommand::Stats),
            ("wait 20", SimCommand::Wait(Duration::from_millis(20))),
            ("quit", SimCommand::Quit),
        ];
        for (line, expected) in cases {
            assert_eq!(parse(line), Ok(Some(expected)), "{line}");
        }
        assert_eq!(parse("   # only a comment"), Ok(None));
    }

    #[test]
    fn errors_say_what_is_wrong() {
        let error = parse("battery NaN").expect_err("NaN is no voltage");
        assert!(
            error.to_string().contains("expected a number, found `NaN`"),
            "{error}"
        );
        assert!(
            parse("motor 5 auto")
                .expect_err("no motor 5")
                .to_string()
                .contains("motor must be 1..4")
        );
        for bad in [
            "frame 800 00",
            "frame 291 0",
            "frame 291 zz",
            "frame 291 000000000000000000",
        ] {
            assert!(
                parse(bad)
                    .expect_err(bad)
                    .to_string()
                    .contains("expected a CAN id"),
                "{bad}"
            );
        }
        assert!(
            parse("fly away")
                .expect_err("unknown")
                .to_string()
                .contains("unknown command")
        );
    }
}
