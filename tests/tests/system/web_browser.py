"""The operator's page (`scout web`) in a real browser: headless Chromium driven by Selenium.

Usage: web_browser.py URL TOKEN SCOUT ROBOT SCREENSHOT_DIR SIM_TRACE

SIM_TRACE is the simulated chassis' trace (`scout-sim --trace`: what it read off the wire, in
CLOCK_BOOTTIME), for the E-STOP tap to zero on the wire.

Each check raises AssertionError with what was seen. At the end it prints one JSON line of
figures (what the test measured; nothing here asserts a speed beyond the issue's bounds).
"""

import http.server
import json
import os
import statistics
import subprocess
import sys
import threading
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By

URL, TOKEN, SCOUT, ROBOT, SHOTS, TRACE = sys.argv[1:7]
HOST = URL.split("//", 1)[1].rstrip("/")
CHROMIUM = os.environ.get("SCOUT_CHROMIUM", "/usr/bin/chromium")
DRIVER = os.environ.get("SCOUT_CHROMEDRIVER", "/usr/bin/chromedriver")
figures = {}


class OtherOrigin(http.server.BaseHTTPRequestHandler):
    """A page of another origin that tries the WebSocket with the right token."""

    def do_GET(self):
        body = (f"<title>x</title><script>const ws = new WebSocket('ws://{HOST}/ws?token={TOKEN}');"
                "ws.onopen = () => document.title = 'open';"
                "ws.onclose = () => { if (document.title !== 'open') document.title = 'refused'; };"
                "</script>").encode()
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args):
        pass


def browser(width, height, mobile):
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--no-first-run", "--disable-extensions", f"--window-size={width},{height}"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
        "width": width, "height": height, "deviceScaleFactor": 1, "mobile": mobile})
    driver.set_script_timeout(10)
    return driver


def until(what, check, limit=5.0):
    """Polls `check` until it returns a true value (returned), or fails after `limit` s."""
    deadline = time.monotonic() + limit
    last = None
    while time.monotonic() < deadline:
        last = check()
        if last:
            return last
        time.sleep(0.02)
    raise AssertionError(f"{what}: not within {limit} s (last: {last!r})")


def js(driver, script, *args):
    return driver.execute_script(script, *args)


def commanded(driver):
    return js(driver, "return state && state.command ? state.command.linear : null")


def moving(driver):
    return js(driver, "return state && state.motion ? state.motion.linear : null")


def web_requests(driver):
    sources = js(driver, "return status ? status.sources : []") or []
    return sum(s["requests"] for s in sources if s["client"] == "web:operator")


def stops(driver):
    """The stop list as shown: (owner, text) per stop (read in one go: the list re-renders)."""
    return js(driver, "return [...document.querySelectorAll('#stops li')]"
                      ".map(li => [li.dataset.owner, li.textContent])")


def owners(driver):
    return [owner for owner, _ in stops(driver)]


def hold(driver, button):
    ActionChains(driver).click_and_hold(button).perform()


def let_go(driver):
    ActionChains(driver).release().perform()


def percentiles(name, values):
    """`name`_p50 and `name`_max into the figures (of 20 samples, a 99th percentile would be
    the largest: it is called so)."""
    figures[f"{name}_p50"] = round(statistics.median(values), 1)
    figures[f"{name}_max"] = round(max(values), 1)


def boottime_from_epoch_ns():
    """What to subtract from a wall-clock time (ns since the epoch) to get CLOCK_BOOTTIME, the
    simulator's trace clock: the closest of a few readings of both."""
    pairs = []
    for _ in range(5):
        before = time.clock_gettime_ns(time.CLOCK_BOOTTIME)
        wall = time.time_ns()
        after = time.clock_gettime_ns(time.CLOCK_BOOTTIME)
        pairs.append((after - before, wall - (before + after) // 2))
    return min(pairs)[1]


def wire_commands():
    """The motion commands the chassis read: (CLOCK_BOOTTIME ns, linear, angular)."""
    with open(TRACE) as trace:
        return [(int(f[1]), float(f[2]), float(f[3]))
                for f in (line.split() for line in trace) if len(f) == 4 and f[0] == "C"]


def comes_to_zero(driver, why):
    """How long until `driver`'s page (another than the one that drove: a page that lost its
    connection sees no state) shows the gateway commanding zero."""
    started = time.monotonic()
    until(f"the command back to zero after {why}", lambda: commanded(driver) == 0.0, 2.0)
    return round((time.monotonic() - started) * 1000)


phone = browser(390, 844, True)
desktop = browser(1280, 800, False)
try:
    # Loads and shows the state.
    started = time.monotonic()
    phone.get(f"{URL}#token={TOKEN}")
    until("the battery shown, its charge with its voltage",
          lambda: "V" in phone.find_element(By.ID, "battery").text
          and "%" in phone.find_element(By.ID, "battery").text)
    until("the speed shown", lambda: phone.find_element(By.ID, "actual").text not in ("", "–"))
    figures["load_to_state_ms"] = round((time.monotonic() - started) * 1000)
    assert figures["load_to_state_ms"] < 3000, figures
    until("the user shown", lambda: "operator" in phone.find_element(By.ID, "me").text)
    # A second page watches (what the gateway commands, while the first one's connection drops).
    desktop.get(f"{URL}#token={TOKEN}")
    until("the second page's state", lambda: commanded(desktop) is not None)

    # The E-STOP is on screen without scrolling on a phone held upright.
    rect = js(phone, "const r = document.getElementById('estop').getBoundingClientRect();"
                     "return [r.top, r.bottom, innerHeight, innerWidth]")
    assert rect[0] >= 0 and rect[1] <= rect[2] and rect[3] == 390, rect
    phone.save_screenshot(os.path.join(SHOTS, "phone-ready.png"))

    # Holding the forward control for 1 s drives; letting go stops.
    forward = phone.find_element(By.CSS_SELECTOR, "#pad button[aria-label=forward]")
    before = web_requests(phone)
    hold(phone, forward)
    time.sleep(1.0)
    speed = until("the chassis moving", lambda: (moving(phone) or 0) > 0.1 and moving(phone))
    let_go(phone)
    figures["zero_after_let_go_ms"] = comes_to_zero(desktop, "letting go")
    time.sleep(0.3)
    sent = web_requests(phone) - before
    # The take-control and the relinquish are requests too.
    figures["drives_in_1s_hold"] = sent - 2
    assert 15 <= sent - 2 <= 25, f"{sent - 2} drives accepted in a 1 s hold (moving at {speed})"

    # Losing focus, being hidden and losing the connection each stop the driving.
    for why, script in (
        ("the page losing focus", "window.dispatchEvent(new Event('blur'))"),
        ("the page hidden", "Object.defineProperty(document, 'hidden', {value: true, configurable: true});"
                            "document.dispatchEvent(new Event('visibilitychange'));"
                            "delete document.hidden;"),
        ("the connection dropped", "ws.close()"),
    ):
        until("connected", lambda: js(phone, "return ws.readyState === WebSocket.OPEN"))
        hold(phone, forward)
        until(f"driving before {why}", lambda: (commanded(phone) or 0) > 0.05)
        js(phone, script)
        figures[f"zero_after_{why.split()[-1]}_ms"] = comes_to_zero(desktop, why)
        let_go(phone)
    until("connected again", lambda: js(phone, "return ws.readyState === WebSocket.OPEN"))

    # The E-STOP latches a stop owned by web:operator, while the other page drives: the tap to
    # the page's answer, and to the first zero command the chassis reads off the wire, 20
    # times. The tap's time is the pointer event's own stamp (its timeStamp, before any handler
    # ran) on the page's clock (performance.timeOrigin: the system's wall clock, through
    # Chromium's own base), the wire's the simulator's (CLOCK_BOOTTIME).
    js(phone, """
        window.__taps = [];
        document.getElementById('estop').addEventListener('pointerdown',
            (e) => window.__taps.push([performance.timeOrigin + e.timeStamp, null]), true);
        new MutationObserver(() => {
            const t = window.__taps[window.__taps.length - 1];
            if (t && t[1] === null && /latched/.test(document.getElementById('log').textContent))
                t[1] = performance.timeOrigin + performance.now();
        }).observe(document.getElementById('log'), {childList: true, characterData: true, subtree: true});
    """)
    estop = phone.find_element(By.ID, "estop")
    desktop_forward = desktop.find_element(By.CSS_SELECTOR, "#pad button[aria-label=forward]")
    taps = 20
    for tap in range(taps):
        # Pressed once the page shows the last stop gone (its arrows are off while one holds).
        until(f"the other page free to drive (tap {tap})",
              lambda: "web:operator" not in owners(desktop) and desktop_forward.is_enabled())
        hold(desktop, desktop_forward)
        until(f"the other page driving (tap {tap})", lambda: (commanded(desktop) or 0) > 0.05)
        js(phone, "document.getElementById('log').textContent = ''")
        ActionChains(phone).click(estop).perform()
        until("the E-STOP answered", lambda: js(phone, "const t = window.__taps; return t.length && t[t.length-1][1] !== null"))
        until(f"the stop shown on the other page (tap {tap})", lambda: "web:operator" in owners(desktop))
        let_go(desktop)
        if tap < taps - 1:
            release = phone.find_element(By.ID, "release")
            until("the stop shown, to release", release.is_displayed)
            release.click()
            until("own stops released", lambda: "web:operator" not in owners(phone))
    tapped = js(phone, "return window.__taps")
    percentiles("estop_tap_to_latched_ms", [b - a for a, b in tapped])
    # The page's clock against the system's: Date.now() is the wall clock itself, floored to
    # the millisecond, so the least of many differences is the page clock's lead.
    lead_ms = js(phone, """
        let least = Infinity;
        for (let i = 0; i < 20000; i++)
            least = Math.min(least, performance.timeOrigin + performance.now() - Date.now());
        return least;""")
    figures["page_clock_lead_ms"] = round(lead_ms, 2)
    to_boottime = boottime_from_epoch_ns() + int(lead_ms * 1e6)
    time.sleep(0.2)  # the trace is flushed every 20 ms feedback period
    wire = wire_commands()
    # Each E-STOP shows on the wire as a jump from driving to zero (the gateway sends zero at
    # once; letting go ramps down at 0.02 m/s a command, and came after the stop anyway).
    jumps = [now[0] for then, now in zip(wire, wire[1:])
             if then[1] >= 0.1 and now[1] == 0.0 and now[2] == 0.0]
    to_wire = []
    for tapped_at, answered_at in tapped:
        at = int(tapped_at * 1e6) - to_boottime
        nearest = min(jumps, key=lambda jump: abs(jump - at), default=None)
        # Within the page's own answer (and 50 ms of the clocks' tie): what the figure is of.
        answered = int(answered_at * 1e6) - to_boottime
        assert nearest is not None and at - 50_000_000 <= nearest <= answered + 50_000_000, \
            f"no jump to zero on the wire between the tap at {at} and its answer at {answered}: {jumps[-5:]}"
        to_wire.append((nearest - at) / 1e6)
    percentiles("estop_tap_to_zero_on_wire_ms", to_wire)
    figures["estop_taps"] = len(to_wire)
    until("the stop in the list", lambda: "web:operator" in owners(phone))

    # A second browser sees it.
    until("the stop in a second browser", lambda: "web:operator" in owners(desktop))

    # A stop from the terminal shows with its owner and cannot be released from the page.
    done = subprocess.run([SCOUT, "estop", "--name", ROBOT, "--reason", "from the terminal"],
                          capture_output=True, text=True, timeout=20)
    assert done.returncode == 0, done.stderr
    other = until("the terminal's stop shown", lambda: [
        (who, text) for who, text in stops(phone) if who != "web:operator"])
    owner, text = other[0]
    assert "only " + owner in text, text
    phone.save_screenshot(os.path.join(SHOTS, "phone-stopped.png"))
    desktop.save_screenshot(os.path.join(SHOTS, "desktop-stopped.png"))

    # Release frees the page's own stops only, and restarts nothing.
    phone.find_element(By.ID, "release").click()
    until("own stops released", lambda: "web:operator" not in owners(phone))
    assert owners(phone) == [owner], stops(phone)
    # Even asked directly, the page cannot release the terminal's stop.
    js(phone, "send({op: 'release', through: newestShown})")
    time.sleep(0.5)
    assert owners(phone) == [owner], stops(phone)
    for _ in range(10):
        assert commanded(phone) == 0.0 and abs(moving(phone) or 0) < 0.01, (commanded(phone), moving(phone))
        time.sleep(0.05)
    assert "Stopped by " + owner in phone.find_element(By.ID, "why").text, phone.find_element(By.ID, "why").text

    # Without the token, with a wrong one, or from another origin: refused, nothing can be done.
    for fragment, shown in (("", "No token"), ("#token=wrong-token-0123456789", "No connection")):
        desktop.get("about:blank")
        desktop.get(URL + fragment)
        until("the page", lambda: js(desktop, "return !!document.getElementById('why')"))
        until(f"refused ({fragment or 'no token'})", lambda: shown in desktop.find_element(By.ID, "why").text)
        assert desktop.find_element(By.ID, "me").text == "–"
        assert js(desktop, "return ws.readyState") != 1
    # A page of another origin (another port) with the right token.
    other_origin = http.server.ThreadingHTTPServer(("127.0.0.1", 0), OtherOrigin)
    threading.Thread(target=other_origin.serve_forever, daemon=True).start()
    desktop.get(f"http://127.0.0.1:{other_origin.server_address[1]}/")
    until("another origin refused", lambda: desktop.title in ("open", "refused"))
    other_origin.shutdown()
    assert desktop.title == "refused", desktop.title

    print(json.dumps(figures))
finally:
    phone.quit()
    desktop.quit()
