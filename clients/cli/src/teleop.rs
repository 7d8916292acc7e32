//! `scout teleop`: keyboard teleop in the terminal, with the state shown live, on this host or
//! through zenoh (`--remote`). The terminal is restored on every way out: quit, error, panic.

use std::io::Write;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Args;
use crossterm::event::{self, Event, KeyCode, KeyEvent, KeyEventKind, KeyModifiers};
use crossterm::{cursor, execute, terminal};
use scout_clients::client::{Robot, StateSubscriber};
use scout_clients::control::{ControlError, Controller, StatusReader};
use scout_clients::interface::control::OPERATOR;
use scout_clients::interface::json::{state_json, status_json};
use scout_clients::remote::{RemoteAnswer, RemoteController, RemoteError, RemoteStates};
use scout_clients::{Class, ReleaseTarget, monotonic_ns};
use serde_json::Value;

use crate::control::{REMOTE_DRIVE_LIFE, describe};
use crate::{RemoteArgs, RobotArgs};

/// Commands go out at 50 Hz.
const PERIOD: Duration = Duration::from_millis(20);
/// One key press changes the speed by this much.
const LINEAR_STEP: f64 = 0.1;
const LATERAL_STEP: f64 = 0.1;
const ANGULAR_STEP: f64 = 0.1;

#[derive(Debug, Args)]
pub struct TeleopArgs {
    #[command(flatten)]
    robot: RobotArgs,
    /// This client's name; with --remote, the peer name in the command keys (default
    /// `operator`), which your certificate's access control must allow.
    #[arg(long, value_name = "NAME")]
    client: Option<String>,
    // With --remote: drives go on the fast lane, the state and status come through zenoh.
    #[command(flatten)]
    remote: RemoteArgs,
}

/// Raw mode and the alternate screen while it lives; the terminal as it was after.
struct TerminalGuard;

impl TerminalGuard {
    fn enter() -> std::io::Result<Self> {
        terminal::enable_raw_mode()?;
        let guard = Self;
        execute!(
            std::io::stdout(),
            terminal::EnterAlternateScreen,
            cursor::Hide
        )?;
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            restore();
            previous(info);
        }));
        Ok(guard)
    }
}

fn restore() {
    let _ = execute!(
        std::io::stdout(),
        cursor::Show,
        terminal::LeaveAlternateScreen
    );
    let _ = terminal::disable_raw_mode();
}

impl Drop for TerminalGuard {
    fn drop(&mut self) {
        restore();
    }
}

/// What a key asks for.
#[derive(Debug, PartialEq)]
enum Key {
    /// A change of the speeds asked for: forward m/s, leftward m/s, rad/s.
    Speed(f64, f64, f64),
    Zero,
    EStop,
    Release,
    Quit,
    Other,
}

fn key(event: KeyEvent) -> Key {
    let ctrl_c =
        event.modifiers.contains(KeyModifiers::CONTROL) && event.code == KeyCode::Char('c');
    match event.code {
        _ if ctrl_c => Key::Quit,
        KeyCode::Up | KeyCode::Char('w') => Key::Speed(LINEAR_STEP, 0.0, 0.0),
        KeyCode::Down | KeyCode::Char('s') => Key::Speed(-LINEAR_STEP, 0.0, 0.0),
        // Shifted, sideways (a chassis that moves sideways; any other refuses it).
        KeyCode::Left if event.modifiers.contains(KeyModifiers::SHIFT) => {
            Key::Speed(0.0, LATERAL_STEP, 0.0)
        }
        KeyCode::Right if event.modifiers.contains(KeyModifiers::SHIFT) => {
            Key::Speed(0.0, -LATERAL_STEP, 0.0)
        }
        KeyCode::Char('A') => Key::Speed(0.0, LATERAL_STEP, 0.0),
        KeyCode::Char('D') => Key::Speed(0.0, -LATERAL_STEP, 0.0),
        KeyCode::Left | KeyCode::Char('a') => Key::Speed(0.0, 0.0, ANGULAR_STEP),
        KeyCode::Right | KeyCode::Char('d') => Key::Speed(0.0, 0.0, -ANGULAR_STEP),
        KeyCode::Char(' ') => Key::Zero,
        KeyCode::Char('e') => Key::EStop,
        KeyCode::Char('r') => Key::Release,
        KeyCode::Char('q') | KeyCode::Esc => Key::Quit,
        _ => Key::Other,
    }
}

/// The robot the keys drive: on this host (iceoryx2), or through zenoh (`--remote`).
#[expect(clippy::large_enum_variant, reason = "one per process, never moved")]
enum Link {
    Local {
        controller: Controller,
        state: StateSubscriber,
        status: StatusReader,
        _robot: Robot,
    },
    Remote {
        controller: RemoteController,
        state: RemoteStates,
        status: RemoteStates,
        /// Whether control was taken and no answer has said it ended since.
        control: bool,
    },
}

/// What one drive command met.
enum Driven {
    /// The gateway's answer, in words.
    Answer(String),
    /// Sent on the fast lane; no answer to it.
    Sent,
    /// Control ended (a stop, a gap, a release, a takeover): a key press takes it again.
    Lost(String),
}

/// A remote command's answer in words.
fn describe_remote(answer: &Result<RemoteAnswer, RemoteError>) -> String {
    match answer {
        Ok(RemoteAnswer { clamped: true, .. }) => "accepted (clamped to the speed caps)".into(),
        Ok(_) => "accepted".into(),
        Err(error) => error.to_string(),
    }
}

impl Link {
    fn connect(args: &TeleopArgs) -> anyhow::Result<Self> {
        let robot_name = &args.robot.name;
        if let Some(settings) = args.remote.settings() {
            let peer = args.client.clone().unwrap_or_else(|| OPERATOR.to_owned());
            return Ok(Self::Remote {
                controller: RemoteController::connect(&settings, robot_name, &peer)?,
                state: RemoteStates::connect(&settings, robot_name)?,
                status: RemoteStates::connect_status(&settings, robot_name)?,
                control: false,
            });
        }
        let robot = Robot::connect(robot_name)?;
        let name = args
            .client
            .clone()
            .unwrap_or_else(|| format!("teleop-{}", std::process::id()));
        Ok(Self::Local {
            controller: robot.controller(&name, Some(Class::Teleop))?,
            state: robot.subscribe()?,
            status: robot.status()?,
            _robot: robot,
        })
    }

    fn has_control(&self) -> bool {
        match self {
            Self::Local { controller, .. } => controller.lease().is_some(),
            Self::Remote { control, .. } => *control,
        }
    }

    /// Takes control as teleop: the answer in words.
    fn take_control(&mut self) -> String {
        match self {
            Self::Local { controller, .. } => describe(&controller.take_control()),
            Self::Remote {
                controller,
                control,
                ..
            } => {
                let answer = controller.take_control(Class::Teleop);
                *control = answer.is_ok();
                describe_remote(&answer)
            }
        }
    }

    /// One drive command; an error when the gateway is gone.
    fn drive(&mut self, (linear, lateral, angular): (f64, f64, f64)) -> anyhow::Result<Driven> {
        match self {
            Self::Local { controller, .. } => {
                match controller.drive_body(linear, lateral, angular, None) {
                    Err(error @ ControlError::NoAnswer { .. }) => Err(error.into()),
                    Err(error) if error.lost_control() => Ok(Driven::Lost(error.to_string())),
                    answer => Ok(Driven::Answer(describe(&answer))),
                }
            }
            Self::Remote {
                controller,
                control,
                ..
            } => match controller.drive_body(linear, lateral, angular, REMOTE_DRIVE_LIFE) {
                Ok(Some(answer)) => Ok(Driven::Answer(describe_remote(&Ok(answer)))),
                Ok(None) => Ok(Driven::Sent),
                Err(error @ RemoteError::Refused { .. }) => {
                    *control = false;
                    Ok(Driven::Lost(error.to_string()))
                }
                Err(error) => Err(error.into()),
            },
        }
    }

    /// Latches a stop owned by this client: the answer in words, and the stop's id.
    fn stop(&mut self) -> (String, Option<u64>) {
        const REASON: &str = "teleop e-stop key";
        match self {
            Self::Local { controller, .. } => {
                let answer = controller.stop(REASON);
                let id = answer.as_ref().ok().and_then(|accepted| accepted.stop);
                (describe(&answer), id)
            }
            Self::Remote {
                controller,
                control,
                ..
            } => {
                let answer = controller.stop(REASON);
                // A stop revokes every lease, this one's too.
                *control &= answer.is_err();
                let id = answer.as_ref().ok().and_then(|accepted| accepted.stop);
                (describe_remote(&answer), id)
            }
        }
    }

    /// Releases the stops up to `through` (here every one; through zenoh this peer's own).
    fn release(&mut self, through: u64) -> String {
        match self {
            Self::Local { controller, .. } => {
                describe(&controller.release(ReleaseTarget::All, through))
            }
            Self::Remote { controller, .. } => describe_remote(&controller.release(Some(through))),
        }
    }

    /// Zero speed, then control given back.
    fn quit(&mut self) {
        match self {
            Self::Local { controller, .. } => {
                let _ = controller.drive(0.0, 0.0);
                let _ = controller.relinquish();
            }
            Self::Remote { controller, .. } => {
                let _ = controller.drive(0.0, 0.0, REMOTE_DRIVE_LIFE);
                let _ = controller.relinquish();
            }
        }
    }

    /// The newest state and status, as JSON, into `shown` (what did not change stays).
    fn refresh(&mut self, shown: &mut Shown) -> anyhow::Result<()> {
        match self {
            Self::Local { state, status, .. } => {
                let now = monotonic_ns();
                if let Some(state) = state.try_latest()? {
                    shown.state = Some(state_json(&state, now));
                }
                if let Some(status) = status.latest(Duration::ZERO)? {
                    shown.status = Some(status_json(&status, now));
                }
            }
            Self::Remote { state, status, .. } => {
                while let Some(json) = state.next_timeout(Duration::ZERO)? {
                    shown.state = Some(json);
                }
                while let Some(json) = status.next_timeout(Duration::ZERO)? {
                    shown.status = Some(json);
                }
            }
        }
        Ok(())
    }
}

/// The state and the arbiter's status last shown.
#[derive(Default)]
struct Shown {
    state: Option<Value>,
    status: Option<Value>,
}

pub fn run(args: &TeleopArgs) -> anyhow::Result<ExitCode> {
    let mut link = Link::connect(args)?;
    // Control is taken by the first movement key, never by starting: a running autonomy drives
    // on until a person asks to drive.
    let mut action = "none yet: a movement key takes control".to_owned();
    let _guard = TerminalGuard::enter()?;
    let (mut linear, mut lateral, mut angular) = (0.0f64, 0.0f64, 0.0f64);
    let mut next = Instant::now();
    let mut shown = Shown::default();
    let mut own_stop = 0;
    let mut answer = String::new();
    let mut out = std::io::stdout();
    loop {
        while event::poll(next.saturating_duration_since(Instant::now()))? {
            let Event::Key(event) = event::read()? else {
                continue;
            };
            if event.kind == KeyEventKind::Release {
                continue;
            }
            match key(event) {
                Key::Speed(dl, dy, da) => {
                    if !link.has_control() {
                        // A key press is the deliberate act that takes control again.
                        (linear, lateral, angular) = (0.0, 0.0, 0.0);
                        action = format!("take control: {}", link.take_control());
                    }
                    linear = (linear + dl).clamp(-1.5, 1.5);
                    lateral = (lateral + dy).clamp(-1.5, 1.5);
                    angular = (angular + da).clamp(-1.0, 1.0);
                }
                Key::Zero => (linear, lateral, angular) = (0.0, 0.0, 0.0),
                Key::EStop => {
                    (linear, lateral, angular) = (0.0, 0.0, 0.0);
                    let (answer, id) = link.stop();
                    own_stop = own_stop.max(id.unwrap_or(0));
                    action = format!("e-stop: {answer}");
                }
                Key::Release => {
                    // What the screen shows, and this keyboard's own e-stops: a stop that
                    // latched since is not released.
                    let shown_stop = (shown.status.as_ref())
                        .and_then(|status| status["newest_stop"].as_u64())
                        .unwrap_or(0);
                    action = format!("release: {}", link.release(shown_stop.max(own_stop)));
                }
                Key::Quit => {
                    link.quit();
                    return Ok(ExitCode::SUCCESS);
                }
                Key::Other => {}
            }
        }
        next += PERIOD;
        if link.has_control() {
            match link.drive((linear, lateral, angular))? {
                Driven::Answer(text) => answer = text,
                Driven::Sent if answer.is_empty() => answer = "sent on the fast lane".into(),
                Driven::Sent => {}
                Driven::Lost(error) => {
                    (linear, lateral, angular) = (0.0, 0.0, 0.0);
                    answer = format!("{error} (press a movement key to take control)");
                }
            }
        } else if !answer.ends_with("to take control)") {
            answer = "no control: press a movement key to take control".to_owned();
        }
        link.refresh(&mut shown)?;
        draw(
            &mut out,
            (linear, lateral, angular),
            [&answer, &action],
            &shown,
        )?;
    }
}

fn draw(
    out: &mut impl Write,
    (linear, lateral, angular): (f64, f64, f64),
    [answer, action]: [&str; 2],
    shown: &Shown,
) -> std::io::Result<()> {
    let mut lines = vec![
        "scout teleop   arrows/WASD speed  shift+left/right or A/D sideways  space zero  \
         e e-stop  r release  q quit"
            .to_owned(),
        String::new(),
        format!(
            "asking   linear {linear:+.2} m/s   sideways {lateral:+.2} m/s   angular {angular:+.2} rad/s"
        ),
        format!("gateway  drive: {answer}   last key: {action}"),
    ];
    if let Some(json) = &shown.status {
        lines.push(format!(
            "arbiter  stop {}   driving {}   output {:+.3} m/s {:+.3} m/s sideways {:+.3} rad/s{}",
            if json["latched"] == true {
                "LATCHED"
            } else {
                "no"
            },
            json["selected"]["client"].as_str().unwrap_or("nobody"),
            json["output"]["linear"].as_f64().unwrap_or(0.0),
            json["output"]["lateral"].as_f64().unwrap_or(0.0),
            json["output"]["angular"].as_f64().unwrap_or(0.0),
            if json["output"]["limited"] == true {
                " (limited)"
            } else {
                ""
            },
        ));
    }
    if let Some(json) = &shown.state {
        lines.push(format!(
            "chassis  link {}   {}   battery {:.1} V   moving {:+.3} m/s {:+.3} m/s sideways {:+.3} rad/s",
            json["link"]["state"].as_str().unwrap_or("?"),
            json["system"]["state"].as_str().unwrap_or("?"),
            json["system"]["battery_voltage"].as_f64().unwrap_or(0.0),
            json["motion"]["linear"].as_f64().unwrap_or(0.0),
            json["motion"]["lateral"].as_f64().unwrap_or(0.0),
            json["motion"]["angular"].as_f64().unwrap_or(0.0),
        ));
    }
    // Each line cut to the terminal's width: a longer one would wrap onto the next, which the
    // next line then overwrites in part.
    // A terminal that tells no size (a pseudo-terminal nobody sized) is not cut.
    let width = match terminal::size() {
        Ok((columns, _)) if columns > 0 => usize::from(columns),
        _ => usize::MAX,
    };
    execute!(
        out,
        cursor::MoveTo(0, 0),
        terminal::Clear(terminal::ClearType::All)
    )?;
    for (row, line) in lines.iter().enumerate() {
        execute!(out, cursor::MoveTo(0, row as u16))?;
        write!(out, "{}", fit(line, width))?;
    }
    out.flush()
}

/// `line` cut to `width` characters, its last one `…` when cut.
fn fit(line: &str, width: usize) -> String {
    if line.chars().count() <= width {
        return line.to_owned();
    }
    let mut cut: String = line.chars().take(width.saturating_sub(1)).collect();
    cut.push('…');
    cut
}

#[cfg(test)]
mod tests {
    use super::*;

    fn press(code: KeyCode, modifiers: KeyModifiers) -> Key {
        key(KeyEvent::new(code, modifiers))
    }

    #[test]
    fn shifted_arrows_and_capitals_go_sideways_plain_ones_turn() {
        let (none, shift) = (KeyModifiers::NONE, KeyModifiers::SHIFT);
        let left = Key::Speed(0.0, LATERAL_STEP, 0.0);
        let right = Key::Speed(0.0, -LATERAL_STEP, 0.0);
        assert_eq!(press(KeyCode::Left, shift), left);
        assert_eq!(press(KeyCode::Char('A'), shift), left);
        assert_eq!(press(KeyCode::Right, shift), right);
        assert_eq!(press(KeyCode::Char('D'), shift), right);
        assert_eq!(
            press(KeyCode::Left, none),
            Key::Speed(0.0, 0.0, ANGULAR_STEP)
        );
        assert_eq!(
            press(KeyCode::Char('a'), none),
            Key::Speed(0.0, 0.0, ANGULAR_STEP)
        );
        assert_eq!(
            press(KeyCode::Char('w'), none),
            Key::Speed(LINEAR_STEP, 0.0, 0.0)
        );
        assert_eq!(press(KeyCode::Char('c'), KeyModifiers::CONTROL), Key::Quit);
    }
}
