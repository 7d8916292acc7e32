//! `scout teleop`: keyboard teleop in the terminal, with the state shown live. The terminal is
//! restored on every way out: quit, error, panic.

use std::io::Write;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Args;
use crossterm::event::{self, Event, KeyCode, KeyEvent, KeyEventKind, KeyModifiers};
use crossterm::{cursor, execute, terminal};
use scout_clients::client::Robot;
use scout_clients::control::ControlError;
use scout_clients::interface::json::{state_json, status_json};
use scout_clients::{Class, ReleaseTarget, monotonic_ns};

use crate::RobotArgs;
use crate::control::describe;

/// Commands go out at 50 Hz.
const PERIOD: Duration = Duration::from_millis(20);
/// One key press changes the speed by this much.
const LINEAR_STEP: f64 = 0.1;
const ANGULAR_STEP: f64 = 0.1;

#[derive(Debug, Args)]
pub struct TeleopArgs {
    #[command(flatten)]
    robot: RobotArgs,
    /// This client's name.
    #[arg(long, value_name = "NAME")]
    client: Option<String>,
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
enum Key {
    Speed(f64, f64),
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
        KeyCode::Up | KeyCode::Char('w') => Key::Speed(LINEAR_STEP, 0.0),
        KeyCode::Down | KeyCode::Char('s') => Key::Speed(-LINEAR_STEP, 0.0),
        KeyCode::Left | KeyCode::Char('a') => Key::Speed(0.0, ANGULAR_STEP),
        KeyCode::Right | KeyCode::Char('d') => Key::Speed(0.0, -ANGULAR_STEP),
        KeyCode::Char(' ') => Key::Zero,
        KeyCode::Char('e') => Key::EStop,
        KeyCode::Char('r') => Key::Release,
        KeyCode::Char('q') | KeyCode::Esc => Key::Quit,
        _ => Key::Other,
    }
}

pub fn run(args: &TeleopArgs) -> anyhow::Result<ExitCode> {
    let robot = Robot::connect(&args.robot.name)?;
    let name = args
        .client
        .clone()
        .unwrap_or_else(|| format!("teleop-{}", std::process::id()));
    let mut controller = robot.controller(&name, Some(Class::Teleop))?;
    let mut action = format!("take control: {}", describe(&controller.take_control()));
    let state = robot.subscribe()?;
    let status = robot.status()?;
    let _guard = TerminalGuard::enter()?;
    let (mut linear, mut angular) = (0.0f64, 0.0f64);
    let mut next = Instant::now();
    let mut last_state = None;
    let mut last_status = None;
    let mut own_stop = 0;
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
                Key::Speed(dl, da) => {
                    if controller.lease().is_none() {
                        // A key press is the deliberate act that takes control again.
                        (linear, angular) = (0.0, 0.0);
                        action = format!("take control: {}", describe(&controller.take_control()));
                    }
                    linear = (linear + dl).clamp(-1.5, 1.5);
                    angular = (angular + da).clamp(-1.0, 1.0);
                }
                Key::Zero => (linear, angular) = (0.0, 0.0),
                Key::EStop => {
                    (linear, angular) = (0.0, 0.0);
                    let answer = controller.stop("teleop e-stop key");
                    if let Ok(accepted) = &answer {
                        own_stop = own_stop.max(accepted.stop.unwrap_or(0));
                    }
                    action = format!("e-stop: {}", describe(&answer));
                }
                Key::Release => {
                    // What the screen shows, and this keyboard's own e-stops: a stop that
                    // latched since is not released.
                    let shown = last_status
                        .as_ref()
                        .map_or(0, |s: &scout_clients::StatusPayload| s.newest_stop);
                    let seen = shown.max(own_stop);
                    action = format!(
                        "release: {}",
                        describe(&controller.release(ReleaseTarget::All, seen))
                    );
                }
                Key::Quit => {
                    let _ = controller.drive(0.0, 0.0);
                    let _ = controller.relinquish();
                    return Ok(ExitCode::SUCCESS);
                }
                Key::Other => {}
            }
        }
        next += PERIOD;
        let answer = if controller.lease().is_some() {
            let result = controller.drive(linear, angular);
            let answer = describe(&result);
            match result {
                Err(error @ ControlError::NoAnswer { .. }) => return Err(error.into()),
                Err(error) if error.lost_control() => {
                    (linear, angular) = (0.0, 0.0);
                    format!("{error} (press a movement key to take control)")
                }
                _ => answer,
            }
        } else {
            "no control: press a movement key to take control".to_owned()
        };
        last_state = state.try_latest()?.or(last_state);
        last_status = status.latest(Duration::ZERO)?.or(last_status);
        let answers = [answer.as_str(), action.as_str()];
        draw(
            &mut out,
            linear,
            angular,
            answers,
            last_state.as_ref(),
            last_status.as_ref(),
        )?;
    }
}

fn draw(
    out: &mut impl Write,
    linear: f64,
    angular: f64,
    [answer, action]: [&str; 2],
    state: Option<&scout_clients::StatePayload>,
    status: Option<&scout_clients::StatusPayload>,
) -> std::io::Result<()> {
    let now = monotonic_ns();
    let mut lines = vec![
        "scout teleop   arrows/WASD speed  space zero  e e-stop  r release  q quit".to_owned(),
        String::new(),
        format!("asking   linear {linear:+.2} m/s   angular {angular:+.2} rad/s"),
        format!("gateway  drive: {answer}   last key: {action}"),
    ];
    if let Some(status) = status {
        let json = status_json(status, now);
        lines.push(format!(
            "arbiter  stop {}   driving {}   output {:+.3} m/s {:+.3} rad/s{}",
            if json["latched"] == true {
                "LATCHED"
            } else {
                "no"
            },
            json["selected"]["client"].as_str().unwrap_or("nobody"),
            json["output"]["linear"].as_f64().unwrap_or(0.0),
            json["output"]["angular"].as_f64().unwrap_or(0.0),
            if json["output"]["limited"] == true {
                " (limited)"
            } else {
                ""
            },
        ));
    }
    if let Some(state) = state {
        let json = state_json(state, now);
        lines.push(format!(
            "chassis  link {}   {}   battery {:.1} V   moving {:+.3} m/s {:+.3} rad/s",
            json["link"]["state"].as_str().unwrap_or("?"),
            json["system"]["state"].as_str().unwrap_or("?"),
            json["system"]["battery_voltage"].as_f64().unwrap_or(0.0),
            json["motion"]["linear"].as_f64().unwrap_or(0.0),
            json["motion"]["angular"].as_f64().unwrap_or(0.0),
        ));
    }
    execute!(
        out,
        cursor::MoveTo(0, 0),
        terminal::Clear(terminal::ClearType::All)
    )?;
    for (row, line) in lines.iter().enumerate() {
        execute!(out, cursor::MoveTo(0, row as u16))?;
        write!(out, "{line}")?;
    }
    out.flush()
}
