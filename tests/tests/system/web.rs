//! `scout web` against a real gateway on the simulated chassis: its refusals without a browser,
//! TLS with a self-signed certificate (`web_tls.py`), and the page in a real browser (`web_browser.py`: headless Chromium driven by Selenium):
//! state shown, hold-to-drive and its deadman (letting go, focus, hidden, connection), the
//! E-STOP and release rules, tokens and origins, a phone-sized screen. The screenshots it takes
//! land in `target/web-screenshots` (CI keeps them; `docs/images/scout-web-phone.png` is one).
//!
//! The browser test needs Debian's `chromium` and `chromium-driver` and a Python with
//! `selenium` (`$SCOUT_PYTHON`; `.ci/run` installs them). Without them it skips, saying why,
//! unless `SCOUT_REQUIRE_BROWSER` is set (as in CI): then it fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use scout_system_tests::{
    Background, Gateway, Sim, built_bin_dir, command, connect_within, line_reader, robot_name,
    run_with_input, skip,
};

const CHROMIUM: &str = "/usr/bin/chromium";
const CHROMEDRIVER: &str = "/usr/bin/chromedriver";

fn python() -> String {
    std::env::var("SCOUT_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// Why the browser test cannot run here, if it cannot; panics instead where it is required.
fn browser_missing(test: &str) -> Option<String> {
    let why = if !Path::new(CHROMIUM).exists() || !Path::new(CHROMEDRIVER).exists() {
        format!("no {CHROMIUM} or {CHROMEDRIVER}: apt-get install chromium chromium-driver")
    } else {
        match Command::new(python())
            .args(["-c", "import selenium"])
            .output()
        {
            Ok(output) if output.status.success() => return None,
            Ok(_) => format!("{} lacks selenium: pip install 'selenium==4.*'", python()),
            Err(error) => format!("no {}: {error}", python()),
        }
    };
    assert!(
        std::env::var_os("SCOUT_REQUIRE_BROWSER").is_none(),
        "{test}: {why}"
    );
    skip(test, &why);
    Some(why)
}

/// Whether the Python lacks `websockets` (said, and skipped; a failure where CI requires the
/// browser checks).
fn websockets_missing(test: &str) -> bool {
    match Command::new(python())
        .args(["-c", "import websockets"])
        .output()
    {
        Ok(output) if output.status.success() => false,
        _ => {
            let why = format!(
                "{} lacks websockets: pip install websockets==17.4",
                python()
            );
            assert!(
                std::env::var_os("SCOUT_REQUIRE_BROWSER").is_none(),
                "{test}: {why}"
            );
            skip(test, &why);
            true
        }
    }
}

/// `scout web --name NAME --listen 127.0.0.1:0 EXTRA`, and the lines it printed up to its link;
/// its log goes to `log`.
fn start_web(name: &str, extra: &[&str], log: &Path) -> (Background, Vec<String>) {
    let mut web = command("scout");
    web.args(["web", "--name", name, "--listen", "127.0.0.1:0"])
        .args(extra)
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(std::fs::File::create(log).expect("scout web's log"));
    let mut child = web.spawn().expect("spawn scout web");
    let lines = line_reader(child.stdout.take().expect("stdout"));
    let background = Background::from_child(child);
    let mut printed = Vec::new();
    loop {
        let line = lines
            .recv_timeout(Duration::from_secs(20))
            .unwrap_or_else(|_| panic!("scout web printed no link: {printed:?}"));
        let link = line
            .split_whitespace()
            .find(|word| word.contains("#token="))
            .map(str::to_owned);
        printed.push(line);
        if let Some(link) = link {
            printed.push(link);
            return (background, printed);
        }
    }
}

/// A gateway on the simulator and `scout web` (with `extra`) in front of it.
struct Served {
    name: String,
    gateway: Gateway,
    web: Background,
    /// What `scout web` printed, its link last.
    printed: Vec<String>,
    /// The link without its token, and the token.
    url: String,
    token: String,
    /// `scout web`'s log, in a directory of its own.
    log: PathBuf,
    _run: scout_system_tests::TempDir,
}

impl Served {
    fn start(prefix: &str, extra: &[&str]) -> Served {
        Served::start_on(prefix, &["--sim"], extra)
    }

    /// As [`Served::start`], the gateway on `chassis` (its chassis arguments).
    fn start_on(prefix: &str, chassis: &[&str], extra: &[&str]) -> Served {
        let name = robot_name(prefix);
        let gateway = Gateway::start(&[chassis, &["--name", &name]].concat());
        connect_within(&name, Duration::from_secs(20));
        let run = scout_system_tests::TempDir::new(&format!("{name}-web"));
        let log = run.path().join("scout-web.log");
        let (web, printed) = start_web(&name, extra, &log);
        let link = printed.last().expect("the link");
        let (url, token) = link.split_once("#token=").expect("a link with a token");
        let (url, token) = (url.to_owned(), token.to_owned());
        Served {
            name,
            gateway,
            web,
            printed,
            url,
            token,
            log,
            _run: run,
        }
    }

    /// `HOST:PORT` of the link.
    fn host(&self) -> &str {
        let url = self.url.trim_end_matches('/');
        url.split_once("://").map_or(url, |(_, host)| host)
    }
}

#[test]
fn the_page_in_a_real_browser_drives_stops_and_refuses_as_the_rules_say() {
    let test = "the_page_in_a_real_browser_drives_stops_and_refuses_as_the_rules_say";
    if browser_missing(test).is_some() {
        return;
    }
    // The chassis apart, tracing what it reads off the wire (for the E-STOP to zero on the wire).
    let run = scout_system_tests::TempDir::new(test);
    let trace = run.path().join("sim-trace");
    let trace = trace.to_string_lossy();
    let sim = Sim::start(&["--serial", "--trace", &trace]);
    let served = Served::start_on("web", &["--serial", sim.port()], &[]);
    let shots: PathBuf = built_bin_dir()
        .parent()
        .expect("target/")
        .join("web-screenshots");
    std::fs::create_dir_all(&shots).expect("the screenshot folder");
    let mut browser = Command::new(python());
    browser
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/web_browser.py"))
        .args([&served.url, &served.token])
        .arg(scout_system_tests::bin("scout"))
        .arg(&served.name)
        .arg(&shots)
        .arg(&*trace)
        .arg(served.web.pid().to_string())
        // Selenium's manager would look for a browser on the internet otherwise.
        .env("SE_OFFLINE", "true");
    let output = run_with_input(browser, b"", Duration::from_secs(240));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "the browser checks failed:\n{}\n{stdout}\nscout web's log:\n{}",
        String::from_utf8_lossy(&output.stderr),
        std::fs::read_to_string(&served.log).unwrap_or_default()
    );
    // The figures (time to the state, drives in a 1 s hold, time to zero, E-STOP tap to its
    // answer and to zero on the wire): printed, never asserted beyond the script's bounds.
    eprintln!("scout web in Chromium: {}", stdout.trim());
    // Fifty wrong tokens at once (and the pages' own): counted in a line or two, not one each.
    let log = std::fs::read_to_string(&served.log).expect("scout web's log");
    let reports = log
        .lines()
        .filter(|line| line.contains("refused for a wrong token"))
        .count();
    assert!(
        (1..=3).contains(&reports),
        "{reports} lines about wrong tokens:\n{log}"
    );
}

/// On a chassis that moves sideways (a SCOUT MINI OMNI on its simulator), the page in a real
/// browser shows its sideways controls, and holding one drives it to the left; on the SCOUT of
/// the test above they are hidden (`web_browser.py`).
#[test]
fn the_page_drives_sideways_where_the_chassis_moves_sideways() {
    let test = "the_page_drives_sideways_where_the_chassis_moves_sideways";
    if browser_missing(test).is_some() {
        return;
    }
    let served = Served::start_on(
        "web-omni",
        &["--sim", "--protocol", "v2", "--model", "scout-mini-omni"],
        &[],
    );
    let mut browser = Command::new(python());
    browser
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/web_sideways.py"))
        .args([&served.url, &served.token])
        .env("SE_OFFLINE", "true");
    let output = run_with_input(browser, b"", Duration::from_secs(120));
    assert!(
        output.status.success(),
        "the browser checks failed:\n{}{}\nscout web's log:\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr),
        std::fs::read_to_string(&served.log).unwrap_or_default()
    );
}

#[test]
fn scout_web_listens_on_loopback_only_and_needs_a_gateway() {
    let (code, _, stderr) =
        scout_system_tests::scout(&["web", "--name", "nobody-here", "--listen", "0.0.0.0:0"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("without TLS"), "{stderr}");
    let (code, _, stderr) = scout_system_tests::scout(&[
        "web",
        "--name",
        &robot_name("web-none"),
        "--listen",
        "127.0.0.1:0",
    ]);
    assert_eq!(code, Some(3), "{stderr}");
}

#[test]
fn a_bad_users_file_is_a_usage_error_naming_the_fault() {
    let dir = scout_system_tests::TempDir::new("web-users");
    let file = dir.path().join("users.toml");
    std::fs::write(
        &file,
        "[[users]]\nname = \"ann\"\nrole = \"drive\"\ntoken = \"short\"\n",
    )
    .expect("write");
    let file = file.to_string_lossy().into_owned();
    let (code, _, stderr) = scout_system_tests::scout(&["web", "--users", &file]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("at least 16"), "{stderr}");
}

#[test]
fn over_tls_the_page_and_its_websocket_go_encrypted_with_the_printed_certificate() {
    let test = "over_tls_the_page_and_its_websocket_go_encrypted_with_the_printed_certificate";
    if websockets_missing(test) {
        return;
    }
    let dir = scout_system_tests::TempDir::new(&robot_name("web-tls-certs"));
    let certs = dir.path().join("tls").to_string_lossy().into_owned();
    let mut served = Served::start("web-tls", &["--tls-self-signed", &certs]);
    let printed = &served.printed;
    // `TLS certificate (made just now) SHA-256 AB:...:EF: the browser shows it; ...`
    let fingerprint = printed
        .iter()
        .find_map(|line| line.split("SHA-256 ").nth(1)?.split_whitespace().next())
        .map(|word| word.trim_end_matches(':').to_owned())
        .unwrap_or_else(|| panic!("no fingerprint printed: {printed:?}"));
    assert!(
        printed.iter().any(|line| line.contains("made just now")),
        "{printed:?}"
    );
    assert!(
        served.url.starts_with("https://127.0.0.1:"),
        "{}",
        served.url
    );
    let mut check = Command::new(python());
    check
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/web_tls.py"))
        .args([served.host(), &served.token, &fingerprint]);
    let output = run_with_input(check, b"", Duration::from_secs(60));
    assert!(
        output.status.success(),
        "web_tls.py failed:\n{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    // A restart keeps the certificate.
    served.web.signal(nix::sys::signal::Signal::SIGTERM);
    assert_eq!(served.web.wait_exit(Duration::from_secs(10)), Some(0));
    let (_again, printed) = start_web(
        &served.name,
        &["--tls-self-signed", &certs],
        &served.log.with_extension("again.log"),
    );
    assert!(
        printed
            .iter()
            .any(|line| line.contains(&fingerprint) && !line.contains("made just now")),
        "{printed:?}"
    );
}

#[test]
fn a_gateway_gone_silent_shows_at_once_and_one_restarted_is_read_again() {
    let test = "a_gateway_gone_silent_shows_at_once_and_one_restarted_is_read_again";
    if websockets_missing(test) {
        return;
    }
    let mut served = Served::start("web-silent", &[]);
    let mut watch = Command::new(python());
    watch
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/web_watch.py"))
        .args([served.host(), &served.token])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    let mut child = watch.spawn().expect("spawn web_watch.py");
    let lines = line_reader(child.stdout.take().expect("stdout"));
    let _watch = Background::from_child(child);
    let wait_for = |kind: &str| {
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        loop {
            let left = deadline.saturating_duration_since(std::time::Instant::now());
            match lines.recv_timeout(left) {
                Ok(line) if line == kind => return,
                Ok(_) => {}
                Err(_) => panic!("no {kind} message within 20 s"),
            }
        }
    };
    wait_for("state");
    served.gateway.signal(nix::sys::signal::Signal::SIGKILL);
    let _ = served.gateway.wait_exit(Duration::from_secs(10));
    wait_for("silent");
    let _gateway = Gateway::start(&["--sim", "--name", &served.name]);
    wait_for("state");
}

#[test]
fn on_a_terminal_the_link_is_a_qr_code_too_in_a_pipe_it_is_not() {
    let test = "on_a_terminal_the_link_is_a_qr_code_too_in_a_pipe_it_is_not";
    // util-linux's `script` gives scout web a terminal (a pty) and copies it to a pipe.
    if Command::new("script").arg("--version").output().is_err() {
        skip(
            test,
            "no `script` (util-linux) to run scout web on a terminal",
        );
        return;
    }
    let served = Served::start("web-qr", &[]);
    // `Served` reads scout web's output through a pipe: the link only.
    assert!(
        !served.printed.iter().any(|line| line.contains("scan")),
        "{:?}",
        served.printed
    );
    let shell = format!(
        "exec {} web --name {} --listen 127.0.0.1:0",
        scout_system_tests::bin("scout").display(),
        served.name
    );
    let mut child = Command::new("script")
        .args(["--quiet", "--flush", "--command", &shell, "/dev/null"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("spawn script");
    let lines = line_reader(child.stdout.take().expect("stdout"));
    let _web = Background::from_child(child);
    // The link, the invitation to scan, then the code: lines in black on white, until a line
    // of anything else (a log line) or a pause.
    let mut shown = Vec::new();
    let mut code: Vec<String> = Vec::new();
    let colours = "\x1b[30;107m";
    while let Ok(line) =
        lines.recv_timeout(Duration::from_secs(if code.is_empty() { 20 } else { 2 }))
    {
        match line.trim_end_matches('\r').strip_prefix(colours) {
            Some(row) => code.push(row.trim_end_matches("\x1b[0m").to_owned()),
            None if code.is_empty() => shown.push(line),
            None => break,
        }
    }
    assert!(
        shown.iter().any(|line| line.contains("#token="))
            && shown
                .iter()
                .any(|line| line.contains("scan it with the phone")),
        "{shown:?}"
    );
    // A version 1 code (21 modules) and its quiet zone at least: 29 wide, 15 lines.
    let width = code.first().map_or(0, |row| row.chars().count());
    assert!(code.len() >= 15 && width >= 29, "{shown:?} {code:?}");
    assert!(
        code.iter().all(|row| row.chars().count() == width
            && row.chars().all(|c| matches!(c, ' ' | '▀' | '▄' | '█'))),
        "{code:?}"
    );
}
