"""Headless Chromium for the live view's tests and benchmark (Debian's chromium and
chromium-driver, driven by selenium). :func:`missing` says in one line why there is none."""
from __future__ import annotations

import os
import shutil
import tempfile

CHROMIUM = os.environ.get("FOVEATED_MI_CHROMIUM", "/usr/bin/chromium")
CHROMEDRIVER = os.environ.get("FOVEATED_MI_CHROMEDRIVER", "/usr/bin/chromedriver")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--mute-audio")


def missing() -> str | None:
    """None when a browser can be started, else the one-line reason."""
    import importlib.util
    if importlib.util.find_spec("selenium") is None:
        return "selenium is not installed (pip install -e '.[test]')"
    for path, pkg in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not (os.path.isfile(path) and os.access(path, os.X_OK)):
            return (f"{path} not found: install Debian's {pkg} (scripts/setup.sh does as root: "
                    "apt-get install chromium chromium-driver)")
    return None


class Browser:
    """A headless Chromium with a fresh profile, removed on :meth:`quit`."""

    def __init__(self, width: int = 1200, height: int = 760):
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
        self.profile = tempfile.mkdtemp(prefix="foveated-mi-chromium-")
        opts = webdriver.ChromeOptions()
        opts.binary_location = CHROMIUM
        for flag in FLAGS:
            opts.add_argument(flag)
        opts.add_argument(f"--user-data-dir={self.profile}")
        opts.add_argument(f"--window-size={width},{height}")
        self.driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)

    def quit(self) -> None:
        try:
            self.driver.quit()
        finally:
            shutil.rmtree(self.profile, ignore_errors=True)
