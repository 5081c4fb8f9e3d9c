"""The plant page in a real browser (Debian's chromium under Selenium, headless): a
real edge node publishes into a mosquitto of the test's own, ``eskin-bus plant --web``
serves the page, and the device's row appears, then turns offline at the node's NDEATH,
with nothing in the browser's console.  Skips when chromium is absent, unless CI=true."""

from __future__ import annotations

from pathlib import Path

import pytest

from eskin_industrial.outputs.sparkplug.kind import open_edge
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from eskin_industrial.outputs.sparkplug.properties import score_properties
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import wait_for
from tests.helpers.browser import chromium, console_errors, need_chromium
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)
from tests.outputs.web.test_web_plant import PROFILE, plant_page, snapshot

pytestmark = pytest.mark.slow


def status(driver, row_id: str) -> str | None:
    return driver.execute_script(
        f"const e = document.getElementById({row_id!r}); return e ? e.dataset.status : null;")


def cells(driver, row_id: str) -> list[str]:
    return driver.execute_script(f"const e = document.getElementById({row_id!r});"
                                 " return e ? Array.from(e.children, (c) => c.textContent) : [];") or [""] * 9


def test_the_device_row_appears_and_turns_offline(tmp_path: Path) -> None:
    need_chromium()
    with spb.broker(tmp_path) as port, plant_page(tmp_path, port) as base, chromium() as d:
        d.get(base)
        wait_for(lambda: d.find_element("id", "status").text == "live", timeout_s=10, what="the page live")
        edge = open_edge(SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e"), [("grip", score_properties(PROFILE))])
        edge.start()
        try:
            assert edge.wait_connected(5)
            edge.devices[0].publish(snapshot(1, 0))
            wait_for(lambda: status(d, "row/g/e/grip") == "online", timeout_s=10, what="the device's row online")
            # its DBIRTH may show before the DDATA with the state: the row is redrawn at it
            wait_for(lambda: cells(d, "row/g/e/grip")[2] == "stable", timeout_s=10, what="the device's state")
            row = cells(d, "row/g/e/grip")
            assert row[1] == "online" and row[4] == PROFILE.detector.method
        finally:
            edge.close()  # its NDEATH
        wait_for(lambda: status(d, "row/g/e/grip") == "offline", timeout_s=10, what="the device's row offline")
        assert status(d, "row/g/e/") == "offline"
        assert console_errors(d) == []
