"""The web console in a real browser (Debian's chromium under Selenium, headless): a
bridge plays paper case 2 in real time (8 N held from 1.5 s, the slide at 9.4 s, again
every 14 s) with the console and the PLC in server mode beside it, and the pages are
read as an operator reads them: the console's log, the heat map's pixels, the state
lane and the event list against the bridge's decision, the commands, and the
capture's raw scans detected again.

The tests of this file share one bridge and one browser (in order: each takes the
page where the one before left it); they skip when chromium is absent, unless CI=true."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig
from eskin_industrial.cli import main
from eskin_industrial.outputs.plc.image import STATUS_COUNT, Status, decode_registers
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.outputs.web.options import WebOptions
from eskin_industrial.scenes import render
from tests.helpers.bridge import PAPER, Running, running_bridge, wait_for
from tests.helpers.browser import chromium, console_errors, need_chromium
from tests.helpers.modbus import free_port
from tests.helpers.paths import ROOT
from tests.helpers.raw_modbus import connect, read_registers
from tests.outputs.web.test_web import PASSWORDS, users_file

pytestmark = [pytest.mark.slow, pytest.mark.allow_leaks("the module's bridge and browser span its tests")]

RATE_HZ = 100.0
SLIP_T = 9.4  #: case 2's slide, in each 14 s lap
#: The state lane and the event list show a slip this soon after the bridge decided it.
WITHIN_S = 0.2


@dataclass
class Cell:
    run: Running
    base: str
    plc_port: int
    driver: Any
    tabs: dict[str, str]
    started: float


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    need_chromium()
    with chromium() as driver:
        yield driver


@pytest.fixture(scope="module")
def cell(tmp_path_factory, browser) -> Iterator[Cell]:
    tmp = tmp_path_factory.mktemp("web")
    web_port, plc_port = free_port(), free_port()
    node = NodeConfig.of("grip", PAPER, "scene", scene="case2")
    config = BridgeConfig(node=(node,), outputs={
        "plc": PlcOptions(mode="server", host="127.0.0.1", port=plc_port, offline_linger_s=0.0),
        "web": WebOptions(bind=f"127.0.0.1:{web_port}", users_file=users_file(tmp), capture_pre_s=3.0)},
        log=LogSettings(format="json", status_every_s=0))
    with running_bridge(config) as run:
        yield Cell(run, f"http://127.0.0.1:{web_port}", plc_port, browser, {}, time.time())
    for handle in browser.window_handles[1:]:  # one tab left for the next test
        browser.switch_to.window(handle)
        browser.close()
    browser.switch_to.window(browser.window_handles[0])


def seen(driver: Any, key: str) -> Any:
    return driver.execute_script(f"return window.Console && window.Console.seen[{key!r}];")


def text(driver: Any, css: str) -> str:
    """An element's text now (the register block is redrawn at every message: no element kept)."""
    return driver.execute_script(f"const e = document.querySelector({css!r}); return e ? e.textContent : '';")


def js_command(driver: Any, name: str) -> dict:
    """``command`` as the page's button calls it; the answer's status and error."""
    return driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        f"command(0, {name!r}).then((r) => done({{status: r.status, error: r.data.error || null}}));")


def log_in(driver: Any, user: str) -> None:
    driver.find_element("id", "user").send_keys(user)
    driver.find_element("id", "password").send_keys(PASSWORDS[user])
    driver.find_element("id", "login-button").click()
    wait_for(lambda: driver.execute_script("return document.getElementById('whoami') !== null;"), timeout_s=10,
             what=f"{user} logged in")


def slip_latched(port: int) -> bool:
    """STATUS as a Modbus client reads it from the PLC output's served block."""
    s = connect(port)
    try:
        regs = read_registers(s, 0, STATUS_COUNT)
    finally:
        s.close()
    return bool(decode_registers(regs + [0] * 8, "big")["STATUS"] & Status.SLIP_LATCHED)


def test_a_command_without_login_is_refused(cell: Cell) -> None:
    d = cell.driver
    d.get(f"{cell.base}/node/0")
    wait_for(lambda: d.execute_script("return document.getElementById('user') !== null;"), timeout_s=10,
             what="the login form")
    assert d.find_element("id", "message").text == "log in to see the cell"
    assert all(not b.is_enabled() for b in d.find_elements("css selector", "#commands button"))
    assert js_command(d, "ack") == {"status": 401, "error": "login"}
    assert cell.run.counters("grip")["web_commands"] == 0


def test_the_page_loads_with_no_console_error(cell: Cell) -> None:
    d = cell.driver
    console_errors(d)  # (the refused command's 401 above is the browser's own line)
    log_in(d, "olga")
    wait_for(lambda: (seen(d, "frames") or 0) >= 20, timeout_s=10, what="20 frames drawn")
    assert d.find_element("id", "status").text == "live"
    assert all(b.is_enabled() for b in d.find_elements("css selector", "#commands button"))
    cell.tabs["node"] = d.current_window_handle
    d.switch_to.new_window("tab")  # the event list beside it, for the slip
    d.get(f"{cell.base}/events")
    wait_for(lambda: d.find_element("id", "status").text == "live", timeout_s=10, what="the events page live")
    cell.tabs["events"] = d.current_window_handle
    d.switch_to.window(cell.tabs["node"])
    assert console_errors(d) == []


def canvas_cells(d: Any) -> tuple[np.ndarray, float]:
    """Each taxel's colour on the heat map's canvas (read back a few pixels inside its
    cell's corner: the centre of force's trail and the number are drawn over the middle),
    and the sensor time of the frame drawn."""
    out = d.execute_script("""
        const c = document.getElementById('heatmap'), ctx = c.getContext('2d'), n = Console.info.nodes[0];
        const cells = [], img = ctx.getImageData(0, 0, c.width, c.height).data;  // one readback
        for (let r = 0; r < n.rows; r++) for (let k = 0; k < n.cols; k++) {
          const [x, y] = heatCell(r, k), w = c.width / n.cols, h = c.height / n.rows;
          const at = 4 * (Math.floor(y - h / 2 + 5) * c.width + Math.floor(x - w / 2 + 5));
          cells.push(Array.from(img.slice(at, at + 4)));
        }
        return [cells, Console.seen.lastFrameT];""")
    return np.asarray(out[0], dtype=float), float(out[1])


def test_the_heat_map_shows_the_scenes_contact_where_it_is(cell: Cell) -> None:
    d = cell.driver
    rec = render("case2", RATE_HZ, 0)
    lap = rec.t[-1] + 1 / RATE_HZ

    def rank_agreement() -> float:  # of the drawn colours with the scene's forces, taxel by taxel
        pixels, t = canvas_cells(d)
        k = int(np.searchsorted(rec.t, t % lap))
        forces = rec.forces[min(k, len(rec.t) - 1)]
        heat = pixels[:, :3].sum(axis=1)  # black -> red -> yellow -> white: the sum rises with the force
        return float(np.corrcoef(np.argsort(np.argsort(heat)), np.argsort(np.argsort(forces)))[0, 1])

    wait_for(lambda: 2.0 < (seen(d, "lastFrameT") or 0) % lap < SLIP_T - 0.5, timeout_s=20, what="the hold drawn")
    assert rank_agreement() > 0.9
    # the contact's heaviest taxels are the drawn ones
    pixels, t = canvas_cells(d)
    k = int(np.searchsorted(rec.t, t % lap))
    heaviest = int(np.argmax(pixels[:, :3].sum(axis=1)))
    assert rec.forces[k, heaviest] >= 0.9 * rec.forces[k].max()
    corner = 0
    assert pixels[corner, :3].sum() < pixels[heaviest, :3].sum() * 0.8


def test_the_slip_is_in_the_state_lane_and_the_event_list_within_200_ms(cell: Cell) -> None:
    d = cell.driver

    def slips(tab: str, key: str) -> list[dict]:
        d.switch_to.window(cell.tabs[tab])
        return [s for s in seen(d, key) or [] if s["decided"] / 1000 >= cell.started]

    wait_for(lambda: slips("node", "laneSlips") and slips("events", "eventSlips"), timeout_s=30,
             what="the slip on both pages")
    decided = cell.run.log.events("state")
    assert any(e["state"] == "slip" for e in decided)
    lane, event = slips("node", "laneSlips")[0], slips("events", "eventSlips")[0]
    assert lane["t"] == pytest.approx(event["t"])
    assert SLIP_T < lane["t"] % 14.0 < SLIP_T + 0.5
    for shown in (lane, event):
        assert 0 <= shown["page"] - shown["decided"] < WITHIN_S * 1000, shown
    delay = d.find_element("css selector", "#episodes tr.episode.slip td:nth-child(5)").text
    assert 0 < float(delay) < 500  # from the scene's own onset, ms
    d.switch_to.window(cell.tabs["node"])
    assert console_errors(d) == []


def test_acknowledge_clears_the_latch_a_modbus_client_reads(cell: Cell) -> None:
    d = cell.driver
    d.switch_to.window(cell.tabs["node"])
    wait_for(lambda: slip_latched(cell.plc_port), timeout_s=10, what="SLIP_LATCHED read over Modbus")
    wait_for(lambda: text(d, "#state") != "SLIP", timeout_s=10, what="the slip over")
    assert slip_latched(cell.plc_port)  # the latch outlasts the slip
    d.find_element("css selector", "#commands button[data-command=ack]").click()
    wait_for(lambda: (seen(d, "lastCommand") or {}).get("status") == 202, timeout_s=5, what="the ack queued")
    wait_for(lambda: not slip_latched(cell.plc_port), timeout_s=5, what="SLIP_LATCHED cleared over Modbus")
    latched = "return document.querySelector(\"#flags .flag[data-flag='slip latched']\").classList.contains('on');"
    wait_for(lambda: not d.execute_script(latched), timeout_s=5, what="the page's latch off")


def test_a_reader_cannot_command(cell: Cell) -> None:
    d = cell.driver
    d.switch_to.window(cell.tabs["node"])
    d.find_element("id", "logout").click()
    wait_for(lambda: d.execute_script("return document.getElementById('user') !== null;"), timeout_s=10,
             what="logged out")
    log_in(d, "rita")
    assert all(not b.is_enabled() for b in d.find_elements("css selector", "#commands button"))
    before = cell.run.counters("grip")["web_commands"]
    assert js_command(d, "ack") == {"status": 403, "error": "role"}
    assert cell.run.counters("grip")["web_commands"] == before


def test_a_downloaded_capture_is_detected_again(cell: Cell, tmp_path: Path) -> None:
    d = cell.driver
    d.switch_to.window(cell.tabs["events"])
    wait_for(lambda: d.find_elements("css selector", "#episodes tr.episode.slip a.capture"), timeout_s=10,
             what="the slip's capture")
    link = d.find_elements("css selector", "#episodes tr.episode.slip a.capture")[-1]
    text = d.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "fetch(arguments[0], {credentials: 'same-origin'}).then((r) => r.text()).then(done);",
        link.get_attribute("href"))
    assert text.startswith("t,f0,f1,")
    path = tmp_path / "capture.csv"
    path.write_text(text)
    res = CliRunner().invoke(main, ["detect", "-p", PAPER, str(path), "--changes"])
    assert res.exit_code == 0, res.output
    states = [line.split(",")[3] for line in res.output.splitlines()[1:] if line]
    assert "slip" in states, res.output


def test_the_demo_shows_the_hands_glass_slip_and_the_register_block_flipping(browser) -> None:
    port = free_port()
    demo = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "demo", "--scene", "hand", "--plain",
                             "--web", f"127.0.0.1:{port}"], env=dict(os.environ, PYTHONPATH=str(ROOT)),
                            stdout=subprocess.PIPE, text=True)
    d = browser
    try:
        assert demo.stdout is not None
        assert f"the web console at http://127.0.0.1:{port}/node/0" in demo.stdout.readline() + demo.stdout.readline()
        console_errors(d)  # (what the tests before left in the log)
        d.get(f"http://127.0.0.1:{port}/node/0")
        wait_for(lambda: d.find_elements("id", "status-bits"), timeout_s=15, what="the register block")
        assert d.find_element("id", "title").text == "node demo"
        assert "SLIP" not in text(d, "#status-bits").split()
        wait_for(lambda: (seen(d, "frames") or 0) >= 20, timeout_s=10, what="the glass drawn")
        wait_for(lambda: seen(d, "laneSlips"), timeout_s=40, what="the glass's slip in the state lane")
        wait_for(lambda: "SLIP_LATCHED" in text(d, "#status-bits").split(), timeout_s=5,
                 what="SLIP_LATCHED in the register block")
        assert int(text(d, "[data-register=SLIP_EVENTS]")) >= 1
        assert console_errors(d) == []
    finally:
        demo.terminate()
        demo.wait(timeout=10)
        if demo.stdout is not None:
            demo.stdout.close()
