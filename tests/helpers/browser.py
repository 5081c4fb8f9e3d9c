"""A real browser for the web console's tests: Debian's chromium and chromedriver,
driven by Selenium, headless, with a fresh profile each time.  Skips cleanly when
either is missing, unless CI=true (then it fails: scripts/debian-packages.txt lists
them)."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from typing import Any

import pytest

CHROMIUM = ("chromium", "chromium-browser")
ARGS = ("--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--window-size=1400,1000")


def _missing(what: str) -> None:
    if os.environ.get("CI") == "true":
        pytest.fail(f"{what} is missing (scripts/debian-packages.txt lists it)")
    pytest.skip(f"{what} not installed")


def need_chromium() -> tuple[str, str]:
    """The browser and its driver: (chromium, chromedriver)."""
    browser = next((p for p in map(shutil.which, CHROMIUM) if p), None)
    if browser is None:
        _missing("chromium (Debian package chromium)")
    driver = shutil.which("chromedriver")
    if driver is None:
        _missing("chromedriver (Debian package chromium-driver)")
    try:
        import selenium  # noqa: F401
    except ImportError:
        _missing("selenium (the test extra)")
    assert browser is not None and driver is not None
    return browser, driver


@contextlib.contextmanager
def chromium(download_dir: str | None = None) -> Iterator[Any]:
    """A headless Chromium under Selenium, its console log kept (``driver.get_log("browser")``)."""
    browser, driver_path = need_chromium()
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="eskin-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = browser
    for a in ARGS:
        options.add_argument(a)
    options.add_argument(f"--user-data-dir={profile}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    if download_dir is not None:
        options.add_experimental_option("prefs", {"download.default_directory": download_dir,
                                                  "download.prompt_for_download": False})
    driver = webdriver.Chrome(service=Service(driver_path), options=options)
    driver.set_page_load_timeout(20)
    driver.set_script_timeout(20)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def console_errors(driver: Any) -> list[str]:
    """The browser console's errors since the last call (a script's exception, a
    resource that failed to load, a refused connection)."""
    return [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]
