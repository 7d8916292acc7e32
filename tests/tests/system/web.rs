//! `scout web` against a real gateway on the simulated chassis: its refusals without a browser,
//! and the page in a real browser (`web_browser.py`: headless Chromium driven by Selenium):
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
    Background, Gateway, built_bin_dir, command, connect_within, line_reader, robot_name,
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

/// `scout web --name NAME --listen 127.0.0.1:0`, and the link it printed.
fn start_web(name: &str) -> (Background, String) {
    let mut web = command("scout");
    web.args(["web", "--name", name, "--listen", "127.0.0.1:0"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit());
    let mut child = web.spawn().expect("spawn scout web");
    let lines = line_reader(child.stdout.take().expect("stdout"));
    let background = Background::from_child(child);
    let line = lines
        .recv_timeout(Duration::from_secs(20))
        .expect("scout web prints its link");
    let link = line
        .split_whitespace()
        .find(|word| word.contains("#token="))
        .unwrap_or_else(|| panic!("no link with a token in {line:?}"))
        .to_owned();
    (background, link)
}

#[test]
fn the_page_in_a_real_browser_drives_stops_and_refuses_as_the_rules_say() {
    let test = "the_page_in_a_real_browser_drives_stops_and_refuses_as_the_rules_say";
    if browser_missing(test).is_some() {
        return;
    }
    let name = robot_name("web");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect_within(&name, Duration::from_secs(20));
    let (_web, link) = start_web(&name);
    let (url, token) = link.split_once("#token=").expect("a link with a token");
    let shots: PathBuf = built_bin_dir()
        .parent()
        .expect("target/")
        .join("web-screenshots");
    std::fs::create_dir_all(&shots).expect("the screenshot folder");
    let mut browser = Command::new(python());
    browser
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/web_browser.py"))
        .args([url, token])
        .arg(scout_system_tests::bin("scout"))
        .arg(&name)
        .arg(&shots)
        // Selenium's manager would look for a browser on the internet otherwise.
        .env("SE_OFFLINE", "true");
    let output = run_with_input(browser, b"", Duration::from_secs(240));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "the browser checks failed:\n{}\n{stdout}",
        String::from_utf8_lossy(&output.stderr)
    );
    // The figures (time to the state, drives in a 1 s hold, time to zero, E-STOP tap to its
    // answer): printed, never asserted beyond the script's bounds.
    eprintln!("scout web in Chromium: {}", stdout.trim());
}

#[test]
fn scout_web_listens_on_loopback_only_and_needs_a_gateway() {
    let (code, _, stderr) =
        scout_system_tests::scout(&["web", "--name", "nobody-here", "--listen", "0.0.0.0:0"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("loopback only"), "{stderr}");
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
