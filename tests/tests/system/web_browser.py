"""The operator's page (`scout web`) in a real browser: headless Chromium driven by Selenium.

Usage: web_browser.py URL TOKEN SCOUT ROBOT SCREENSHOT_DIR SIM_TRACE WEB_PID

SIM_TRACE is the simulated chassis' trace (`scout-sim --trace`: what it read off the wire, in
CLOCK_BOOTTIME), for the E-STOP tap to zero on the wire. WEB_PID is scout web's process: the
last check stops it, and the page must say it cannot stop the robot any more.

Each check raises AssertionError with what was seen. At the end it prints one JSON line of
figures (what the test measured; nothing here asserts a speed beyond the issue's bounds).
"""

import http.server
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By

URL, TOKEN, SCOUT, ROBOT, SHOTS, TRACE, WEB_PID = sys.argv[1:8]
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


class StallingProxy:
    """A TCP proxy in front of scout web whose way back to the browser can stall: it stops
    reading what the server sends (its receive buffer set small), as a phone on bad Wi-Fi does,
    while what the browser sends still goes through."""

    def __init__(self, upstream):
        self.upstream = upstream
        self.flowing = threading.Event()
        self.flowing.set()
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while True:
            client, _ = self.listener.accept()
            server = socket.socket()
            server.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
            server.connect(self.upstream)
            threading.Thread(target=self._pump, args=(client, server, False), daemon=True).start()
            threading.Thread(target=self._pump, args=(server, client, True), daemon=True).start()

    def _pump(self, source, sink, stalls):
        try:
            while True:
                if stalls:
                    self.flowing.wait()
                data = source.recv(4096)
                if not data:
                    break
                sink.sendall(data)
        except OSError:
            pass
        for s in (source, sink):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass


def status_now():
    done = subprocess.run([SCOUT, "status", "--json", "--name", ROBOT],
                          capture_output=True, text=True, timeout=20)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def web_stops():
    return [s for s in status_now()["stops"] if s["owner"] == "web:operator"]


def alert_on_screen_in_red(driver, words, limit=15.0):
    """The alert says `words`, is within the viewport, and is white on red."""
    text = until(f"the alert saying {words!r}", lambda: words in driver.find_element(By.ID, "alert").text
                 and driver.find_element(By.ID, "alert").text, limit)
    rect = js(driver, "const r = document.getElementById('alert').getBoundingClientRect();"
                      "return [r.top, r.bottom, innerHeight]")
    assert rect[0] >= 0 and rect[1] <= rect[2], f"the alert off screen: {rect}"
    color = js(driver, "return getComputedStyle(document.getElementById('alert')).backgroundColor")
    red, green, blue = (int(c) for c in color[color.index("(") + 1:color.index(")")].split(",")[:3])
    assert red >= 180 and green <= 80 and blue <= 80, f"the alert not red: {color}"
    size = js(driver, "return parseFloat(getComputedStyle(document.getElementById('alert')).fontSize)")
    assert size >= 18, f"the alert's words are small: {size}px"
    return text


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
    # A SCOUT does not move sideways: the page offers no sideways controls.
    assert not phone.find_element(By.ID, "sidepad").is_displayed(), "sideways on a SCOUT"

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
        # Driving past 0.1 m/s (the ramp adds 0.02 a command), so that the stop shows on the
        # wire as the jump to zero looked for below: tapped at 0.06 on a loaded machine, it
        # was no jump.
        until(f"the other page driving (tap {tap})", lambda: (commanded(desktop) or 0) > 0.15)
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

    # A congested page (the way back stalls, as a phone's on bad Wi-Fi): its E-STOP still
    # latches at once, the page shows it unconfirmed until the answer gets through, then
    # confirmed. (Before, the server read a page only between its writes: a write that could
    # not drain held the E-STOP back, then closed the page and lost it.)
    # (The page's origin and its Host header are both the proxy's: the origin check passes.)
    proxy = StallingProxy(("127.0.0.1", int(HOST.rsplit(":", 1)[1])))
    phone.get(f"http://127.0.0.1:{proxy.port}/#token={TOKEN}")
    until("the page through the proxy", lambda: commanded(phone) is not None)
    proxy.flowing.clear()
    until("the page sees the link congested", lambda: js(phone, "return stale"), 10.0)
    phone.save_screenshot(os.path.join(SHOTS, "phone-congested.png"))
    tapped = time.monotonic()
    ActionChains(phone).click(phone.find_element(By.ID, "estop")).perform()
    latched = until("the E-STOP latched behind the congested link", lambda: web_stops(), 5.0)
    # When it latched: the status read after it, less the stop's age in that status (an upper
    # bound: the status was read a little before `scout status` returned).
    figures["congested_estop_latched_ms"] = round(
        (time.monotonic() - tapped) * 1000 - latched[0]["age_ms"])
    assert js(phone, "return estop && !estop.stop"), "shown confirmed before any answer came"
    alert_on_screen_in_red(phone, "NOT CONFIRMED")
    phone.save_screenshot(os.path.join(SHOTS, "phone-estop-not-confirmed.png"))
    proxy.flowing.set()
    until("the E-STOP shown confirmed once the link drains",
          lambda: js(phone, "return !!(estop && estop.stop)"), 30.0)
    assert "STOPPED" in phone.find_element(By.ID, "estop").text
    phone.find_element(By.ID, "release").click()
    until("own stops released", lambda: not web_stops())

    # Idle connections (another user's, renewed as they close) cannot keep a page out: the page
    # reconnects and its E-STOP latches.
    flooding = threading.Event()
    flooding.set()
    address = ("127.0.0.1", int(HOST.rsplit(":", 1)[1]))

    def idle_connections():
        held = []
        while flooding.is_set():
            while len(held) < 63:
                try:
                    held.append(socket.create_connection(address, timeout=2))
                except OSError:
                    time.sleep(0.01)
            for s in list(held):
                s.setblocking(False)
                try:
                    if s.recv(1) == b"":
                        held.remove(s)
                        s.close()
                except BlockingIOError:
                    pass
                except OSError:
                    held.remove(s)
            time.sleep(0.005)
        for s in held:
            s.close()

    flooder = threading.Thread(target=idle_connections, daemon=True)
    flooder.start()
    time.sleep(1.0)
    started = time.monotonic()
    phone.get(f"{URL}#token={TOKEN}")
    until("the page connected through the idle flood",
          lambda: js(phone, "return !!me && ws.readyState === WebSocket.OPEN"), 20.0)
    figures["reconnect_through_idle_flood_ms"] = round((time.monotonic() - started) * 1000)
    ActionChains(phone).click(phone.find_element(By.ID, "estop")).perform()
    until("the E-STOP latched through the idle flood", lambda: web_stops(), 5.0)
    until("and confirmed", lambda: js(phone, "return !!(estop && estop.stop)"), 5.0)
    flooding.clear()
    flooder.join()
    phone.find_element(By.ID, "release").click()
    until("own stops released", lambda: not web_stops())

    # Without the token, with a wrong one, or from another origin: refused, nothing can be done.
    for fragment, shown in (("", "No token"), ("#token=wrong-token-0123456789", "token is wrong")):
        desktop.get("about:blank")
        desktop.get(URL + fragment)
        until("the page", lambda: js(desktop, "return !!document.getElementById('why')"))
        alert_on_screen_in_red(desktop, shown)
        assert desktop.find_element(By.ID, "me").text == "–"
        assert js(desktop, "return ws ? ws.readyState : -1") != 1
        assert js(desktop, "return document.getElementById('estop').disabled")

    # Token guessing is slowed per address, and logged by count (checked in scout web's log by
    # the test): fifty wrong tokens at once.
    def guess(n):
        with socket.create_connection(address, timeout=30) as s:
            s.sendall((f"GET /ws?token=guess-{n:020d} HTTP/1.1\r\nHost: {HOST}\r\n"
                       f"Origin: {URL.rstrip('/')}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                       "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
            s.settimeout(30)
            while s.recv(4096):
                pass

    guessers = [threading.Thread(target=guess, args=(n,)) for n in range(50)]
    for g in guessers:
        g.start()
    for g in guessers:
        g.join()
    # A page of another origin (another port) with the right token.
    other_origin = http.server.ThreadingHTTPServer(("127.0.0.1", 0), OtherOrigin)
    threading.Thread(target=other_origin.serve_forever, daemon=True).start()
    desktop.get(f"http://127.0.0.1:{other_origin.server_address[1]}/")
    until("another origin refused", lambda: desktop.title in ("open", "refused"))
    other_origin.shutdown()
    assert desktop.title == "refused", desktop.title

    # On a small phone (390x640): a wrong token says so, in red, on screen, with the E-STOP
    # shown unavailable.
    small = browser(390, 640, True)
    try:
        small.get(f"{URL}#token=an-old-token-of-a-former-start")
        alert_on_screen_in_red(small, "token is wrong")
        assert "UNAVAILABLE" in small.find_element(By.ID, "estop").text
        small.save_screenshot(os.path.join(SHOTS, "phone-wrong-token.png"))
        # scout web stopped: a page that was live says it cannot stop the robot any more.
        small.get("about:blank")  # a new fragment alone would not load the page again
        small.get(f"{URL}#token={TOKEN}")
        until("the small page connected", lambda: js(small, "return !!me"))
        os.kill(int(WEB_PID), signal.SIGTERM)
        alert_on_screen_in_red(small, "No connection to scout web")
        assert "UNAVAILABLE" in small.find_element(By.ID, "estop").text
        assert js(small, "return document.getElementById('estop').disabled")
        small.save_screenshot(os.path.join(SHOTS, "phone-no-scout-web.png"))
    finally:
        small.quit()

    print(json.dumps(figures))
finally:
    phone.quit()
    desktop.quit()
