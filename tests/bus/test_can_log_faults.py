"""CAN logs checked, not trusted: a corrupt, truncated or foreign-layout log is one
line and exit 2 in `detect`, and in the bridge a `source_failed` event, BUS_FAULT in
the PLC's image, then BRIDGE_OFFLINE and a non-zero exit.  The logs are written by
python-can's own writers, then damaged."""
from __future__ import annotations

import threading
from pathlib import Path

import can
import numpy as np
import pytest

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, resolve
from eskin_industrial.bridge.logs import EventLog
from eskin_industrial.bridge.runtime import Bridge
from eskin_industrial.bus.can.layout import CanLayout
from eskin_industrial.outputs.plc.image import Status
from eskin_industrial.outputs.plc.options import PlcOptions
from eskin_industrial.outputs.sparkplug.metrics import DEVICE_METRICS
from tests.cli.test_cli_detect import cli
from tests.helpers.bridge import PAPER, LogCapture, TimedPlc, hold_raw
from tests.helpers.can_frames import scans_to_messages
from tests.helpers.modbus import free_port


@pytest.fixture(scope="module")
def paper(request):
    from eskin_industrial import load_profile

    return load_profile(PAPER)


def write_log(path: Path, layout: CanLayout, raw: np.ndarray, t0: float = 1.7e9) -> Path:
    msgs = scans_to_messages(layout, np.arange(len(raw)) % 4096, raw)
    with can.Logger(path) as log:
        for m in msgs:
            m.timestamp += t0
            log.on_message_received(m)
    return path


def good_log(tmp_path: Path, paper, suffix: str, scans: int = 150) -> Path:
    return write_log(tmp_path / f"traffic{suffix}", CanLayout.from_profile(paper), hold_raw(paper, scans))


def damaged(path: Path, how: str) -> Path:
    data = bytearray(path.read_bytes())
    if how == "truncated":
        data = data[: len(data) // 2 + 7]  # (mid-record: a cut at a line boundary leaves a shorter, whole log)
    elif how == "bit-flipped":
        data[len(data) // 2] ^= 0x10  # inside the compressed container: its checksum fails
    elif how == "bad-magic":
        data[:4] = b"XXXX"
    elif how == "10-byte":
        data = data[:10]
    out = path.with_name(f"{how}-{path.name}")
    out.write_bytes(bytes(data))
    return out


def one_line_error(res) -> str:
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert "Traceback" not in res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("eskin-bus: error: "), res.stderr
    return lines[0]


@pytest.mark.parametrize("suffix,how,expect", [
    (".blf", "bit-flipped", "zlib.error"),
    (".blf", "bad-magic", "byte 0: not a BLF log"),
    (".blf", "10-byte", "not a BLF log: 10 bytes"),
    (".blf", "truncated", "the log is truncated"),
    (".asc", "truncated", "cut short (no newline at the end of the file): the log is truncated"),
    (".log", "truncated", "cut short (no newline at the end of the file): the log is truncated"),
])
def test_a_damaged_log_is_one_line_and_exit_2_in_detect(paper, tmp_path, suffix, how, expect):
    bad = damaged(good_log(tmp_path, paper, suffix), how)
    line = one_line_error(cli("detect", "-p", PAPER, "--can-log", str(bad), "-o", str(tmp_path / "o.csv")))
    assert str(bad) in line and expect in line


def test_a_truncated_blf_whose_header_was_never_closed_is_found_by_its_objects(paper, tmp_path):
    bad = bytearray(damaged(good_log(tmp_path, paper, ".blf"), "truncated").read_bytes())
    bad[16:24] = bytes(8)  # the file-size field a writer that never stopped leaves at 0
    path = tmp_path / "unclosed.blf"
    path.write_bytes(bytes(bad))
    line = one_line_error(cli("detect", "-p", PAPER, "--can-log", str(path)))
    assert "runs past the end of the file" in line and "the log is truncated" in line


@pytest.mark.parametrize("suffix", [".blf", ".asc", ".log"])
def test_an_intact_log_still_decodes(paper, tmp_path, suffix):
    res = cli("detect", "-p", PAPER, "--can-log", str(good_log(tmp_path, paper, suffix)), "-o", str(tmp_path / "o.csv"),
              "--json")
    assert res.returncode == 0, res.stderr
    assert '"scans": 150' in res.stderr


def foreign_log(tmp_path: Path, paper, suffix: str = ".blf", scans: int = 150) -> Path:
    """The paper node's 25 taxels packed at 12 bits (another firmware's layout) on the
    same IDs: most frames have the lengths the 16-bit layout expects."""
    layout = CanLayout(25, 12, "little", paper.can.base_id)
    raw = np.clip(hold_raw(paper, scans) // 8, 0, 4095)
    return write_log(tmp_path / f"foreign{suffix}", layout, raw)


def test_a_log_of_another_layout_is_refused_not_decoded(paper, tmp_path):
    line = one_line_error(cli("detect", "-p", PAPER, "--can-log", str(foreign_log(tmp_path, paper))))
    assert "do not fit its layout" in line and "IDs 0x200-0x20f" in line


def run_bridge(log_path: Path, port: int, timeout_s: float = 10.0) -> tuple[Bridge, LogCapture]:
    cfg = BridgeConfig(node=(NodeConfig.of("grip", PAPER, "can-log", path=str(log_path)),),
                       outputs={"plc": PlcOptions(mode="client", host="127.0.0.1", port=port)},
                       log=LogSettings(format="json", status_every_s=0))
    capture = LogCapture()
    log = EventLog(capture, "json", "debug")
    bridge = Bridge(cfg, resolve(cfg), log)
    bridge.open()
    try:
        bridge.start()
        waiter = threading.Thread(target=bridge.wait, kwargs={"duration_s": timeout_s, "tick_s": 0.02}, daemon=True)
        waiter.start()
        waiter.join(timeout_s + 5)
    finally:
        bridge.stop()
        log.close()
    return bridge, capture


@pytest.mark.parametrize("how", ["bit-flipped", "foreign"])
def test_in_the_bridge_a_failed_log_is_source_failed_bus_fault_and_a_failure(paper, tmp_path, how):
    path = foreign_log(tmp_path, paper) if how == "foreign" else damaged(good_log(tmp_path, paper, ".blf"), how)
    plc = TimedPlc(free_port()).start()
    try:
        bridge, capture = run_bridge(path, plc.port)
        images = [img for _, img in plc.images()]
    finally:
        plc.stop()
    failed = capture.events("source_failed")
    assert len(failed) == 1 and str(path) in failed[0]["error"], capture.events()
    assert not capture.events("source_ended")
    assert bridge.failure.startswith("source failed: grip: ")
    assert any(img["STATUS"] & Status.BUS_FAULT for img in images), images[-3:]
    assert images[-1]["STATUS"] == Status.BRIDGE_OFFLINE
    if how == "foreign":  # refused before any verdict
        assert not any(img["STATUS"] & Status.DATA_VALID for img in images)


def test_the_bridge_command_exits_non_zero_when_its_only_source_fails(paper, tmp_path):
    bad = damaged(good_log(tmp_path, paper, ".blf"), "truncated")
    res = cli("bridge", "-p", PAPER, "--source", f"log:{bad}", "--plc", f"serve:127.0.0.1:{free_port()}",
              "--duration", "10")
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr
    assert "source_failed" in res.stderr and "the log is truncated" in res.stderr
    assert res.stderr.strip().splitlines()[-1].startswith("eskin-bus: error: bridge stopped: source failed: ")


@pytest.mark.slow
def test_sparkplug_hears_the_bus_fault_then_the_device_death(paper, tmp_path):
    from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
    from tests.helpers import sparkplug as spb

    layout = CanLayout.from_profile(paper)
    path = tmp_path / "traffic.blf"
    msgs = scans_to_messages(layout, np.arange(250) % 4096, hold_raw(paper, 250))
    with can.Logger(path, max_container_size=4096) as log:  # many containers: the damage is in the last
        for m in msgs:
            log.on_message_received(m)
    data = bytearray(path.read_bytes())
    data[-100] ^= 0x10
    path.write_bytes(bytes(data))
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            cfg = BridgeConfig(node=(NodeConfig.of("grip", PAPER, "can-log", path=str(path)),),
                               outputs={"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "plant1", "cell7")},
                               log=LogSettings(format="json", status_every_s=0))
            log_ = EventLog(LogCapture(), "json", "debug")
            bridge = Bridge(cfg, resolve(cfg), log_)
            bridge.open()
            try:
                bridge.start()
                bridge.wait(10.0, tick_s=0.02)
            finally:
                bridge.stop()
                log_.close()
            msgs_ = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m))
        finally:
            cap.close()
    assert bridge.failure.startswith("source failed: grip: ")
    kinds = [t.split("/")[2] for t, _ in msgs_]
    assert kinds[-2:] == ["DDEATH", "NDEATH"]
    faults = [spb.value(m) for t, p in msgs_ if "/DDATA/" in t for m in spb.parse(p).metrics
              if m.alias == 1000 + [d.name for d in DEVICE_METRICS].index("Bus Fault")]
    assert faults and faults[-1] is True, (kinds, faults)
