"""The taxel frame as a Sparkplug B ``FloatArray`` metric (``Taxels/Frame``): the loop
hands a sink only the frames due at its interval; on a real broker the DBIRTH
declares the metric with its shape, the DDATA carry the very frames the detector saw
(decoded by the ``protobuf`` package from the tests' own schema, the floats unpacked
here with ``struct``), at most one per ``frame_interval_s``; off by default; not held
while the node cannot publish; a bad interval refused in one line."""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eskin_industrial.bridge.config import BridgeConfig, LogSettings, NodeConfig, load_bridge_config
from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.replay import ReplaySource
from eskin_industrial.calibration import Calibrator
from eskin_industrial.errors import ProfileError
from eskin_industrial.frames import Frame
from eskin_industrial.outputs.base import Sink
from eskin_industrial.outputs.sparkplug import payload as pb
from eskin_industrial.outputs.sparkplug.metrics import FRAME_ALIAS
from eskin_industrial.outputs.sparkplug.options import SparkplugOptions
from eskin_industrial.profile import load_profile
from eskin_industrial.scenes import render
from tests.helpers import sparkplug as spb
from tests.helpers.bridge import PAPER, running_bridge, wait_for
from tests.helpers.modbus import need
from tests.helpers.paths import PROFILES
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)

FLOAT_ARRAY = 30  # Sparkplug 3.0 "FloatArray" (the specification's DataType enum), written out here on purpose
FRAME = "Taxels/Frame"
ALIAS = 1000 + FRAME_ALIAS  # the first device's block


def _floats(data: bytes) -> np.ndarray:
    """A FloatArray's bytes_value as the specification packs it: little-endian float32."""
    assert len(data) % 4 == 0
    return np.array(struct.unpack(f"<{len(data) // 4}f", data), dtype=np.float32)


def _scene_frames(scene: str, rate_hz: float = 100.0) -> np.ndarray:
    """The calibrated frames a ``scene:`` source makes the detector see, as float32:
    the scene's forces to the node's integer raw unit and back through the profile's
    calibration, one scan at a time as the pipeline does."""
    prof = load_profile(PAPER)
    cal = Calibrator.from_section(prof.calibration, prof.taxels)
    raw = np.rint(cal.to_raw(render(scene, rate_hz, 0).forces))
    return np.stack([cal.to_newtons(r)[0] for r in raw]).astype(np.float32)


def _matches(frames: list[np.ndarray], expected: np.ndarray) -> list[int]:
    """For each received frame, the index of the scene frame it is, bit for bit (NaN
    included); in order, each after the one before (the scene loops: from 0 again)."""
    out: list[int] = []
    start = 0
    bits = expected.view(np.uint32)
    for f in frames:
        hit = np.flatnonzero((bits[start:] == f.view(np.uint32)).all(axis=1))
        if not len(hit):
            hit = np.flatnonzero((bits == f.view(np.uint32)).all(axis=1))
            assert len(hit), "a frame that is none of the calibrated frames"
            assert out, "looped before the first frame"
            start = 0
        out.append(start + int(hit[0]))
        start = out[-1] + 1
    return out


# -- the loop: the frames due, nothing for a sink that wants none ------------------------
class _FrameSink(Sink):
    def __init__(self, every_s: float | None) -> None:
        super().__init__()
        self.frame_every_s = every_s
        self.frames: list[tuple[float, Frame]] = []

    clock = staticmethod(time.perf_counter)

    def on_frame(self, frame: Frame) -> None:
        self.frames.append((self.clock(), frame))


def test_the_loop_hands_each_sink_the_newest_frame_at_its_own_interval():
    prof = load_profile(PAPER)
    rec = render("case2", 200.0, 0)
    raw = np.rint(Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.forces))[:300]
    every, never, fast = _FrameSink(0.1), _FrameSink(None), _FrameSink(0.05)
    loop = NodeLoop(prof, ReplaySource(prof, rec.t[:300], raw, 200.0), [every, never, fast], rate_hz=200.0)
    # the loop's own clock, read at each scan's arrival, is what the interval is kept on;
    # a sink's receipt comes after the scan's work, which a loaded machine stretches (a
    # CI run: two receipts 46.9 ms apart for a 50 ms interval)
    hand, clock = loop._hand_frame, [0.0]

    def spy(now: float) -> None:
        clock[0] = now
        hand(now)

    loop._hand_frame = spy  # type: ignore[method-assign]
    for sink in (every, fast):
        sink.clock = lambda: clock[0]
    seen: list[Frame] = []
    start = time.perf_counter()
    for _ in range(300):  # 1.5 s of scans at 200 Hz, played in real time (longer on a loaded machine)
        loop.step(0.05)
        seen.append(loop.pipeline.last_frame)
    elapsed = time.perf_counter() - start
    assert loop.pipeline.counters.scans == 300
    assert never.frames == [] and len(loop._frame_sinks) == 2, "a sink that wants no frame is not asked"
    for sink, interval in ((every, 0.1), (fast, 0.05)):
        times = np.array([t for t, _ in sink.frames])
        assert np.diff(times).min() >= interval - 1e-9, "never two closer than the interval"
        assert 0.5 * elapsed / interval <= len(times) <= elapsed / interval + 1, (len(times), elapsed)
        # the very frame the detector saw (not a copy), handed with the scan that made it
        ids = {id(f) for f in seen}
        assert all(id(f) in ids for _, f in sink.frames)
    assert sink.frames[0][1] is seen[0], "the first scan's frame goes at once"


# -- configuration ------------------------------------------------------------------------
_TOML = ('[sparkplug]\nbroker = "mqtt://127.0.0.1:1883"\ngroup_id = "plant1"\nedge_node_id = "cell7"\n'
         'frame_interval_s = {}\n\n[[node]]\nname = "grip"\nprofile = "{}"\nsource = "scene"\nscene = "case2"\n')


def test_frame_interval_in_the_file_off_by_default_and_bounds_checked(tmp_path):
    assert SparkplugOptions("mqtt://h:1", "g", "e").frame_interval_s == 0
    cfg = tmp_path / "bridge.toml"
    cfg.write_text(_TOML.format(0.5, PAPER))
    assert load_bridge_config(cfg).outputs["sparkplug"].frame_interval_s == 0.5
    for bad in ("-1", "0.01", "4000", '"1"'):
        cfg.write_text(_TOML.format(bad, PAPER))
        with pytest.raises(ProfileError) as err:
            load_bridge_config(cfg)
        line = str(err.value)
        assert "\n" not in line and line.startswith(f"{cfg}: [sparkplug] frame_interval_s: "), line


def _cli(*extra: str) -> list[str]:
    return [sys.executable, "-m", "eskin_industrial", "bridge", "-p", str(PROFILES / "paper-5x5.toml"),
            "--source", "scene:case2", "--sparkplug", "mqtt://127.0.0.1:1883", "--group-id", "plant1",
            "--edge-node-id", "cell7", *extra]


def test_the_command_line_option_and_check(tmp_path):
    env = {**os.environ, "PYTHONPATH": os.getcwd()}
    ok = subprocess.run(_cli("--sparkplug-frame-interval", "0.5", "--check"), capture_output=True, text=True,
                        timeout=60, env=env)
    assert ok.returncode == 0, ok.stderr
    assert "Taxels/Frame every 0.5 s (5 x 5)" in ok.stdout
    off = subprocess.run(_cli("--check"), capture_output=True, text=True, timeout=60, env=env)
    assert off.returncode == 0 and "Taxels/Frame" not in off.stdout
    bad = subprocess.run(_cli("--sparkplug-frame-interval", "0.001", "--check"), capture_output=True, text=True,
                         timeout=60, env=env)
    assert bad.returncode == 2 and "--sparkplug-frame-interval" in bad.stderr and "0.05" in bad.stderr, bad.stderr
    cfg = tmp_path / "bridge.toml"
    cfg.write_text(_TOML.format(-2, PAPER))
    bad = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", "--config", str(cfg), "--check"],
                         capture_output=True, text=True, timeout=60, env=env)
    lines = bad.stderr.strip().splitlines()
    assert bad.returncode == 2 and len(lines) == 1 and "frame_interval_s" in lines[0] and str(cfg) in lines[0], \
        bad.stderr


# -- on a real broker -----------------------------------------------------------------------
def _frames_of(msgs: list[tuple[str, bytes]]) -> list[tuple[int, np.ndarray, bool]]:
    """(payload timestamp, floats, historical) of every DDATA metric with the frame's alias."""
    out = []
    for t, data in msgs:
        if "/DDATA/" in t:
            p = spb.parse(data)
            for m in p.metrics:
                if m.alias == ALIAS:
                    assert not m.HasField("datatype") and not m.HasField("name") and m.timestamp == p.timestamp
                    out.append((p.timestamp, _floats(m.bytes_value), m.is_historical))
    return out


def _birth_frame(msgs: list[tuple[str, bytes]]):
    births = [spb.parse(p) for t, p in msgs if "/DBIRTH/" in t]
    assert births
    found = [m for m in births[0].metrics if m.name == FRAME]
    return found[0] if found else None


def _properties(m) -> dict:
    out = {}
    for key, v in zip(m.properties.keys, m.properties.values):
        (field,) = [f for f in ("long_value", "double_value", "string_value") if v.HasField(f)]
        out[key] = getattr(v, field)
    return out


def test_dbirth_declares_the_frame_and_ddata_carry_the_calibrated_frames_at_the_interval(tmp_path):
    expected = _scene_frames("case2")
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            node = NodeConfig.of("grip", PAPER, "scene", scene="case2")
            opts = SparkplugOptions(f"mqtt://127.0.0.1:{port}", "plant1", "cell7", frame_interval_s=0.2)
            config = BridgeConfig((node,), {"sparkplug": opts}, LogSettings(format="json", status_every_s=0))
            with running_bridge(config) as run:
                msgs = cap.wait(lambda m: len(_frames_of(m)) >= 12, timeout_s=15)
                counters = run.counters("grip")
            msgs = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m))
        finally:
            cap.close()
    m = _birth_frame(msgs)
    assert m is not None and m.alias == ALIAS and m.datatype == FLOAT_ARRAY
    lay = load_profile(PAPER).layout
    assert _properties(m) == {"engUnit": "N", "rows": lay.rows, "cols": lay.cols, "pitch_mm": lay.pitch_mm,
                              "order": "row-major", "frame_interval_s": 0.2}
    frames = _frames_of(msgs)
    assert all(len(f) == lay.rows * lay.cols and not hist for _, f, hist in frames)
    # each the calibrated frame of a scan, in order, about 20 scans (0.2 s at 100 Hz) apart
    idx = np.array(_matches([f for _, f, _ in frames], expected))
    stamps = np.array([ts for ts, _, _ in frames])
    assert np.diff(stamps).min() >= 190, "never two frames closer than frame_interval_s (ms stamps)"
    assert len(frames) <= (stamps[-1] - stamps[0]) / 200 + 1
    # decimated: about 20 scans apart at 100 Hz (fewer when a loaded machine plays the
    # scene behind time), and never more scans than the time between the two allows
    gaps, waits = np.diff(idx), np.diff(stamps) / 1000
    kept = gaps > 0  # (a loop of the scene restarts the count)
    assert np.median(gaps[kept]) >= 10 and (gaps[kept] <= waits[kept] * 100 + 2).all(), (idx, stamps)
    assert any(f.sum() > 1.0 for _, f, _ in frames), "frames with contact, not only zeros"
    assert counters["sparkplug_frames"] >= len(frames)
    if m.HasField("bytes_value"):  # a frame due before the connection: not sent, the birth's value
        assert counters["sparkplug_frames_not_sent"] >= 1
        _matches([_floats(m.bytes_value)], expected)


def test_off_by_default_no_frame_metric_and_no_frames(tmp_path):
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            node = NodeConfig.of("grip", PAPER, "scene", scene="case2")
            config = BridgeConfig((node,), {"sparkplug": SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e")},
                                  LogSettings(format="json", status_every_s=0))
            with running_bridge(config) as run:
                cap.wait(lambda m: any("/DBIRTH/" in t for t, _ in m))
                time.sleep(1.0)
                loops = [r.loop for r in run.bridge.runs]
                counters = run.counters("grip")
            msgs = cap.wait(lambda m: any("/NDEATH/" in t for t, _ in m))
        finally:
            cap.close()
    assert _birth_frame(msgs) is None
    assert all(m.alias != ALIAS for t, p in msgs if "/DDATA/" in t for m in spb.parse(p).metrics)
    assert "sparkplug_frames" not in counters
    assert loops and all(not loop._frame_sinks for loop in loops), "no sink asks the loop for frames"


@pytest.mark.slow
def test_frames_are_not_held_while_the_node_cannot_publish_and_the_birth_has_the_newest(tmp_path):
    """With a primary host that is not online yet the node holds its data (the store);
    frames are counted, not held: the DBIRTH when the host comes carries the newest,
    and what the store forwards (historical) has no frame."""
    expected = _scene_frames("case2")
    with spb.broker(tmp_path) as port:
        cap = spb.Capture(port, tmp_path / "sub.txt")
        try:
            node = NodeConfig.of("grip", PAPER, "scene", scene="case2")
            opts = SparkplugOptions(f"mqtt://127.0.0.1:{port}", "g", "e", primary_host_id="scada1",
                                    frame_interval_s=0.1, min_interval_s=0.1)
            config = BridgeConfig((node,), {"sparkplug": opts}, LogSettings(format="json", status_every_s=0))
            with running_bridge(config) as run:
                c = lambda: run.counters("grip")  # noqa: E731
                wait_for(lambda: c()["sparkplug_frames_not_sent"] >= 5 and c()["sparkplug_store_held"] >= 1,
                         what="frames not sent, data held")
                held = c()["sparkplug_store_held"]
                subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-q", "1", "-r",
                                "-t", "spBv1.0/STATE/scada1", "-s"], check=True, timeout=10,
                               input=json.dumps({"online": True, "timestamp": int(time.time() * 1000)}).encode())
                msgs = cap.wait(lambda m: any("/NDATA/" in t for t, _ in m) and len(_frames_of(m)) >= 3)
                counters = c()
        finally:
            cap.close()
    m = _birth_frame(msgs)
    assert m is not None and not m.is_null and m.HasField("bytes_value")
    _matches([_floats(m.bytes_value)], expected)  # a calibrated frame of the scene
    frames = _frames_of(msgs)
    assert frames and not any(hist for _, _, hist in frames), "no frame forwarded from the store"
    historical = [spb.parse(p) for t, p in msgs if "/DDATA/" in t and
                  all(x.is_historical for x in spb.parse(p).metrics)]
    assert historical, "the store forwarded the states it held"
    assert counters["sparkplug_store_forwarded"] >= held >= 1
    assert counters["sparkplug_store_overflow"] == 0


def test_the_codec_packs_float_arrays_as_protobuf_and_tahu_read_them():
    """Our encoder's FloatArray against protobuf's reading and the specification's packing."""
    values = [1.23, 89.341, -0.0, float("nan"), 3.4e38]
    data = pb.encode(pb.Payload(7, (pb.Metric("a", 3, None, pb.FLOAT_ARRAY, pb.pack_floats(values)),)))
    (m,) = spb.parse(data).metrics
    assert m.datatype == FLOAT_ARRAY == pb.FLOAT_ARRAY
    assert m.bytes_value == struct.pack("<5f", *values)
    assert m.bytes_value[:4] == bytes.fromhex("a4709d3f"), "1.23 as a little-endian float32"
    back = pb.decode(spb.parse(data).SerializeToString()).metrics[0]
    assert back.value == m.bytes_value and pb.unpack_floats(back.value)[1] == pytest.approx(89.341, rel=1e-6)
    bad = spb.Payload(timestamp=1)
    bad.metrics.add(alias=3, datatype=FLOAT_ARRAY, bytes_value=b"\x00" * 7)
    with pytest.raises(pb.PayloadError, match="7 bytes"):
        pb.decode(bad.SerializeToString())


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(width=32), max_size=64))
def test_float_arrays_round_trip_through_protobuf(values):
    data = pb.encode(pb.Payload(1, (pb.Metric(None, 9, None, pb.FLOAT_ARRAY, pb.pack_floats(values)),)))
    (m,) = spb.parse(data).metrics
    assert _floats(m.bytes_value).view(np.uint32).tolist() == np.array(values, dtype=np.float32).view(np.uint32).tolist()
    assert pb.decode(spb.parse(data).SerializeToString()).metrics[0].value == m.bytes_value


# -- eskin-bus plant ----------------------------------------------------------------------
def test_the_plant_view_shows_the_newest_frames_peak_and_total_and_survives_a_bad_one():
    from eskin_industrial.outputs.sparkplug.watch import PlantModel
    from eskin_industrial.view.plant_table import plant_lines

    def payload(seq: int, **metric) -> bytes:
        p = spb.Payload(timestamp=1000, seq=seq)
        p.metrics.add(**metric)
        return p.SerializeToString()

    forces = np.array([0.5, float("nan"), 2.25, 0.0], dtype="<f4")
    m = PlantModel()
    m.take("spBv1.0/g/NBIRTH/e", payload(0, name="bdSeq", datatype=4, long_value=0), 0.0)
    m.take("spBv1.0/g/DBIRTH/e/grip", payload(1, name=FRAME, alias=ALIAS, datatype=FLOAT_ARRAY, is_null=True), 0.0)
    assert m.take("spBv1.0/g/DDATA/e/grip", payload(2, alias=ALIAS, datatype=FLOAT_ARRAY,
                                                     bytes_value=forces.tobytes()), 1.0) == []
    (dev,) = [r for r in m.rows(1.0) if "device" in r]
    assert (dev["frame_max"], dev["frame_sum"]) == (2.25, 2.75), "the NaN of a refused reading left out"
    assert "2.25 / 2.8" in "\n".join(plant_lines(m.rows(1.0), "t", 200, 10))
    # another publisher's: no datatype and not whole floats: the last values stay, nothing breaks
    assert m.take("spBv1.0/g/DDATA/e/grip", payload(3, alias=ALIAS, bytes_value=b"\x00" * 5), 2.0) == []
    # declared FloatArray but not whole floats: a malformed message, counted
    assert m.take("spBv1.0/g/DDATA/e/grip", payload(4, alias=ALIAS, datatype=FLOAT_ARRAY, bytes_value=b"\x00" * 6),
                  2.0)[0]["event"] == "malformed"
    (dev,) = [r for r in m.rows(2.0) if "device" in r]
    assert (dev["frame_max"], dev["frame_sum"]) == (2.25, 2.75) and m.malformed == 1


def test_the_frame_alias_is_its_own_in_the_device_block():
    from eskin_industrial.outputs.sparkplug.commands import COMMAND_ALIAS, COMMANDS
    from eskin_industrial.outputs.sparkplug.metrics import DEVICE_METRICS

    aliases = [*range(len(DEVICE_METRICS)), FRAME_ALIAS, *range(COMMAND_ALIAS, COMMAND_ALIAS + len(COMMANDS))]
    assert len(set(aliases)) == len(aliases) and max(aliases) < 1000, "a device's block is 1000 aliases"
