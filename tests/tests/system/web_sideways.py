"""The operator's page (`scout web`) on a chassis that moves sideways, in a real browser (headless
Chromium driven by Selenium, a phone's screen): its sideways controls show, holding one drives
the chassis to the left, letting go stops it.

Usage: web_sideways.py URL TOKEN

Each check raises AssertionError with what was seen.
"""

import os
import sys
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By

URL, TOKEN = sys.argv[1:3]
CHROMIUM = os.environ.get("SCOUT_CHROMIUM", "/usr/bin/chromium")
DRIVER = os.environ.get("SCOUT_CHROMEDRIVER", "/usr/bin/chromedriver")


def until(what, check, limit=10.0):
    """Polls `check` until it returns a true value (returned), or fails after `limit` s."""
    deadline = time.monotonic() + limit
    last = None
    while time.monotonic() < deadline:
        last = check()
        if last:
            return last
        time.sleep(0.02)
    raise AssertionError(f"{what}: not within {limit} s (last: {last!r})")


def main():
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--disable-gpu",
                "--no-first-run", "--disable-extensions", "--window-size=390,844"):
        options.add_argument(arg)
    phone = webdriver.Chrome(service=Service(DRIVER), options=options)
    phone.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
        "width": 390, "height": 844, "deviceScaleFactor": 1, "mobile": True})
    try:
        phone.get(f"{URL}#token={TOKEN}")
        state = lambda key: phone.execute_script(f"return state ? state.{key} : null")
        until("the OMNI's state", lambda: (state("chassis.max_lateral") or 0) > 0)
        left = phone.find_element(By.CSS_SELECTOR, "#sidepad button[aria-label='sideways left']")
        until("the sideways controls shown and enabled",
              lambda: left.is_displayed() and left.is_enabled())
        y0 = state("odometry.y")
        ActionChains(phone).click_and_hold(left).perform()
        until("the command sideways to the left", lambda: (state("command.lateral") or 0) > 0.1)
        until("the chassis moved to the left", lambda: state("odometry.y") - y0 > 0.1)
        forward = state("odometry.x")
        assert abs(forward) < 0.05, f"sideways, not forward: x {forward}"
        ActionChains(phone).release().perform()
        until("zero on the wire after letting go", lambda: state("command.lateral") == 0.0)
    finally:
        phone.quit()


main()
