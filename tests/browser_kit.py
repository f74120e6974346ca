"""A real browser for the web view's tests: Debian's chromium, headless, driven by Selenium through
Debian's chromedriver (``.ci/run`` installs both before ``make test``).  Where either is missing the
tests that need it are skipped, and say what to install."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time

import pytest

from daemon_kit import HANG_GUARD_S

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1600,900", "--force-device-scale-factor=1"]


def missing() -> str | None:
    """Why no browser test can run here, or None."""
    for path, package in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not os.access(path, os.X_OK):
            return f"no {path}: the browser tests need Debian's {package} (apt-get install chromium chromium-driver)"
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "no selenium: pip install -e '.[test]'"
    return None


needs_browser = pytest.mark.skipif(missing() is not None, reason=missing() or "")


class Browser:
    """One headless chromium with a profile of its own (removed on close)."""

    def __init__(self):
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service

        self.profile = tempfile.mkdtemp(prefix="hilgate-chromium-")
        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for flag in FLAGS:
            options.add_argument(flag)
        options.add_argument(f"--user-data-dir={self.profile}")
        self.driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
        self.driver.set_page_load_timeout(HANG_GUARD_S)

    def open(self, url: str) -> None:
        self.driver.get(url)

    def js(self, script: str, *args):
        return self.driver.execute_script(script, *args)

    def view(self, expression: str):
        """A JSON value computed in the page (``v`` is ``window.hilgateView``)."""
        return json.loads(self.js(f"const v = window.hilgateView; return JSON.stringify(({expression}) ?? null);"))

    def wait(self, expression: str, what: str, timeout: float = HANG_GUARD_S, alive=None):
        """Poll ``expression`` (JSON in the page) until it is truthy; returns it.  The bound is a hang guard."""
        deadline = time.monotonic() + timeout
        while True:
            value = self.view(expression)
            if value:
                return value
            if alive is not None:
                alive()
            if time.monotonic() > deadline:
                raise AssertionError(f"the page did not show {what} within {timeout:.0f} s (a hang guard); "
                                     f"errors: {self.view('v.error')}, console: {self.console()}")
            time.sleep(0.05)

    def console(self) -> list:
        try:
            return [entry["message"] for entry in self.driver.get_log("browser")]
        except Exception:
            return []

    def screenshot(self, path: str) -> None:
        self.driver.save_screenshot(path)

    def viewport(self, width: int, height: int) -> None:
        """The page's own size (the window's, less nothing): what an operator's 1280×800 screen shows."""
        self.driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                                    {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False})

    def keep(self, directory, name: str) -> str:
        """The page as it is now, kept as the test's artefacts: ``NAME.png`` and ``NAME.html`` (its DOM) in
        ``directory`` (a test's tmp_path; ``HILGATE_ARTEFACTS=DIR`` keeps them there instead)."""
        directory = os.environ.get("HILGATE_ARTEFACTS") or str(directory)
        os.makedirs(directory, exist_ok=True)
        shot = os.path.join(directory, name + ".png")
        self.screenshot(shot)
        with open(os.path.join(directory, name + ".html"), "w", encoding="utf-8") as handle:
            handle.write(self.js("return document.documentElement.outerHTML"))
        with open(shot, "rb") as handle:
            assert handle.read(8) == b"\x89PNG\r\n\x1a\n"
        return shot

    def close(self) -> None:
        try:
            self.driver.quit()
        finally:
            shutil.rmtree(self.profile, ignore_errors=True)


@pytest.fixture
def browser():
    reason = missing()
    if reason is not None:
        pytest.skip(reason)
    instance = Browser()
    try:
        yield instance
    finally:
        instance.close()
