"""One DBC for every CAN node of a bridge: cantools and canmatrix load it and decode a
mixed log of two nodes to the forces our decoder gives; cycle times and send types
are attributes both read."""
from __future__ import annotations

import subprocess
import sys

import can
import canmatrix
import canmatrix.formats
import cantools
import numpy as np
import pytest

from eskin_industrial.bridge.config import load_bridge_config, resolve
from eskin_industrial.bus.can.layout import CanLayout, decode_messages
from eskin_industrial.calibration import Calibrator
from tests.helpers.can_frames import scans_to_messages
from tests.helpers.paths import PROFILES, ROOT

BRIDGE = ROOT / "examples" / "deploy" / "bridge.toml"


def eskin_bus(*args, timeout=60):
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=timeout)


@pytest.fixture(scope="module")
def plant_dbc():
    res = eskin_bus("profile", "dbc", "--config", str(BRIDGE))
    assert res.returncode == 0, res.stderr
    return res.stdout


def test_plant_dbc_names_every_node_and_prefixes_its_messages(plant_dbc):
    db = cantools.database.load_string(plant_dbc, "dbc")
    assert [n.name for n in db.nodes] == ["gripper_left", "gripper_right"]
    nodes = resolve(load_bridge_config(BRIDGE))
    for n, prefix in zip(nodes, ("GRIPPER_LEFT", "GRIPPER_RIGHT")):
        lay = CanLayout.from_profile(n.profile)
        mine = sorted((m for m in db.messages if m.senders == [n.name.replace("-", "_")]), key=lambda m: m.frame_id)
        assert [m.frame_id for m in mine] == [lay.data_id(s) for s in range(lay.segments)] + [lay.status_id]
        assert [m.name for m in mine] == [f"{prefix}_SEG{s}" for s in range(lay.segments)] + [f"{prefix}_STATUS"]
        # the scan period and the heartbeat period, cyclic
        assert [m.cycle_time for m in mine] == [round(1000 / n.rate_hz)] * lay.segments + \
            [round(1000 * n.profile.can.heartbeat_s)]
        assert {m.send_type for m in mine} == {"Cyclic"}
    matrix = canmatrix.formats.loads_flat(plant_dbc, "dbc")
    assert sorted(e.name for e in matrix.ecus) == ["gripper_left", "gripper_right"]
    for m in db.messages:
        frame = matrix.frame_by_id(canmatrix.ArbitrationId(m.frame_id, extended=m.is_extended_frame))
        assert frame.name == m.name and frame.cycle_time == m.cycle_time
        assert frame.attributes["GenMsgSendType"] == "Cyclic"


def test_cantools_and_canmatrix_decode_a_mixed_log_of_two_nodes(plant_dbc, tmp_path):
    nodes = resolve(load_bridge_config(BRIDGE))
    rng = np.random.default_rng(11)
    per_node, logged = {}, []
    for i, n in enumerate(nodes):
        lay = CanLayout.from_profile(n.profile)
        cal = Calibrator.from_section(n.profile.calibration, n.profile.taxels)
        raw = np.rint(cal.to_raw(rng.uniform(0.0, 7.0, (8, n.profile.taxels))))
        seqs = np.arange(100 * i, 100 * i + 8)
        msgs = scans_to_messages(lay, seqs, raw)
        per_node[n.name] = (lay, cal, msgs)
        logged.append(msgs)
    # interleave the two nodes scan by scan, as on a shared bus, through a candump log
    mixed = []
    for k in range(8):
        for msgs, n in zip(logged, nodes):
            seg = per_node[n.name][0].segments
            mixed += msgs[k * seg: (k + 1) * seg]
    path = tmp_path / "mixed.log"
    with can.Logger(str(path)) as writer:
        for t, m in enumerate(mixed):
            m.timestamp = 1000.0 + t * 1e-4
            m.channel = "can0"
            writer.on_message_received(m)
    replayed = list(can.LogReader(str(path)))
    assert len(replayed) == len(mixed)
    db = cantools.database.load_string(plant_dbc, "dbc")
    matrix = canmatrix.formats.loads_flat(plant_dbc, "dbc")
    for n in nodes:
        lay, cal, _ = per_node[n.name]
        ours, asm = decode_messages(lay, replayed, n.rate_hz)
        assert asm.counters["foreign_frames"] == len(mixed) // 2  # the other node's frames
        forces, flags = cal.to_newtons(np.array([s.raw for s in ours]))
        assert not flags.any() and len(ours) == 8
        theirs = {"cantools": np.full(forces.shape, np.nan), "canmatrix": np.full(forces.shape, np.nan)}
        mine = [m for m in replayed if lay.base_id <= m.arbitration_id < lay.base_id + 16]
        for j, m in enumerate(mine):
            k = j // lay.segments
            message = db.get_message_by_frame_id(m.arbitration_id)
            assert message.senders == [n.name.replace("-", "_")]
            for name, value in message.decode(bytes(m.data)).items():
                if name.startswith("F"):
                    theirs["cantools"][k, int(name[1:])] = value
            frame = matrix.frame_by_id(canmatrix.ArbitrationId(m.arbitration_id, extended=False))
            for name, sig in frame.decode(bytes(m.data)).items():
                if name.startswith("F"):
                    theirs["canmatrix"][k, int(name[1:])] = float(sig.phys_value)
        for tool, values in theirs.items():
            np.testing.assert_allclose(values, forces, rtol=1e-9, atol=1e-9, err_msg=tool)


def test_single_profile_dbc_takes_a_node_name_and_base_id():
    res = eskin_bus("profile", "dbc", str(PROFILES / "hand-4x5.toml"), "--node-name", "left-hand", "--base-id",
                    "0x300")
    assert res.returncode == 0, res.stderr
    db = cantools.database.load_string(res.stdout, "dbc")
    assert [n.name for n in db.nodes] == ["left_hand"]
    assert [(m.frame_id, m.name) for m in sorted(db.messages, key=lambda m: m.frame_id)] == \
        [(0x300 + s, f"LEFT_HAND_SEG{s}") for s in range(5)] + [(0x30F, "LEFT_HAND_STATUS")]


@pytest.mark.parametrize("args,needle", [
    (["--base-id", "0x7F5"], "--base-id"),  # past the last 11-bit node range
    (["--base-id", "twelve"], "--base-id"),
    (["--config", "x.toml"], "--config"),  # FILE and --config
])
def test_single_profile_dbc_refuses_bad_options(args, needle):
    res = eskin_bus("profile", "dbc", str(PROFILES / "hand-4x5.toml"), *args)
    assert res.returncode == 2 and needle in res.stderr, res.stderr


def test_plant_dbc_refuses_two_nodes_on_the_same_ids(tmp_path):
    """Two buses may reuse IDs; one DBC cannot hold both."""
    text = BRIDGE.read_text().replace('channel = "can0"\nbase_id = 0x210', 'channel = "can1"\nbase_id = 0x200')
    assert text != BRIDGE.read_text()
    config = tmp_path / "bridge.toml"
    config.write_text(text.replace("../../profiles/", str(PROFILES) + "/"))
    res = eskin_bus("profile", "dbc", "--config", str(config))
    assert res.returncode == 2
    assert "gripper-left" in res.stderr or "gripper_left" in res.stderr
    assert "0x200" in res.stderr and res.stdout == ""


def test_plant_dbc_refuses_a_configuration_without_can_nodes(tmp_path):
    config = tmp_path / "bridge.toml"
    config.write_text(f'[[node]]\nname = "a"\nprofile = "{PROFILES / "paper-5x5.toml"}"\nsource = "scene"\n'
                      f'scene = "case2"\n')
    res = eskin_bus("profile", "dbc", "--config", str(config))
    assert res.returncode == 2 and "no CAN node" in res.stderr and res.stdout == ""
