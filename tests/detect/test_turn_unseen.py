"""TURN_UNSEEN: where cof-track's torsion channel cannot see a turn (a contact on about
one taxel), the updates say so, and the state stays held: the defined degraded
behaviour of a turn the detector cannot see."""

from __future__ import annotations

import json
import re
import time
from dataclasses import replace

import numpy as np
import pytest

from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.replay import ReplaySource
from eskin_industrial.calibration import Calibrator
from eskin_industrial.detect.cof_track import CofTrack
from eskin_industrial.detect.state import GraspState
from eskin_industrial.detect.updates import Update
from eskin_industrial.evaluation import conditions
from eskin_industrial.evaluation.suite import DEFAULT_SETTINGS, by_name, evaluate, run_one
from eskin_industrial.frames import FrameFlag
from eskin_industrial.outputs.plc.export import slip_guard_st
from eskin_industrial.outputs.plc.image import IMAGE_COUNT, REG, Status
from eskin_industrial.outputs.plc.server import PlcServer
from eskin_industrial.recording import read_updates, write_recording
from eskin_industrial.scenes import load_scene, render
from tests.cli.test_cli_detect import PAPER, cli
from tests.helpers.modbus import free_port, mbpoll, mbpoll_values
from tests.helpers.paths import ROOT

X, Y = np.tile(np.arange(5) * 5.0, 5), np.repeat(np.arange(5) * 5.0, 5)  # the 5 x 5 array, 5 mm pitch
UNSEEN = int(FrameFlag.TURN_UNSEEN)
TURN = (9.4, 10.4)  # the twist turns 30 degrees at 30 degrees/s from 9.4 s
#: the channel's first look at a contact: a renewal with learnt noise (its second, 0.6 s
#: after the contact begins at 100 Hz: the template renews every 0.24 s after settling)
FIRST_LOOK_S = 0.7


def _updates(scene: str, seed: int, size_mm: float | None = None, **overrides) -> list[Update]:
    spec = load_scene(scene)
    if size_mm is not None:
        spec = conditions.contact_size(size_mm)(spec)
    r = render(spec, 100.0, seed)
    settings = replace(DEFAULT_SETTINGS, cof_track=replace(DEFAULT_SETTINGS.cof_track, **overrides))
    return CofTrack(settings, X, Y, 100.0).feed(r.t, r.forces)


def _contacts(ups: list[Update]) -> list[list[Update]]:
    """The runs of updates in contact (state not no_contact)."""
    runs: list[list[Update]] = []
    for before, u in zip([None, *ups], ups):
        if u.state != GraspState.NO_CONTACT:
            if before is None or before.state == GraspState.NO_CONTACT:
                runs.append([])
            runs[-1].append(u)
    return runs


def test_a_turn_on_a_5_mm_contact_reads_stable_held_and_flagged_unseen() -> None:
    """The twist on a 5 mm contact (one taxel): the channel cannot see the turn.  The
    state stays `stable` and valid through it, with no state change and no slip
    anywhere, and every update in contact carries TURN_UNSEEN: the PLC can tell this
    "stable" from a seen one."""
    ups = _updates("twist", 1000, 5.0)
    (contact,) = _contacts(ups)
    assert all(u.flags & UNSEEN for u in contact)
    assert FrameFlag.describe(contact[-1].flags) == "TURN_UNSEEN"
    assert not any(u.flags & UNSEEN for u in ups if u.state == GraspState.NO_CONTACT)
    turn = [u for u in ups if TURN[0] <= u.t <= TURN[1] + 0.5]
    assert turn and all(u.state == GraspState.STABLE and u.valid for u in turn)
    states = [u.state for u in ups if u.t >= TURN[0] - 1.0]
    assert len(set(states)) == 1  # no entry of any state from a second before the turn on
    assert not any(u.state == GraspState.SLIP for u in ups)


def test_the_same_turn_on_the_20_mm_block_is_seen_and_not_flagged() -> None:
    """The twist as it is (a 20 x 12 mm block): TURN_UNSEEN only until the channel's
    first look at the contact, then clear to its end, and the turn reads slip."""
    ups = _updates("twist", 1000)
    (contact,) = _contacts(ups)
    start = contact[0].t
    assert contact[0].flags & UNSEEN  # not judged yet: the channel does not look
    assert not any(u.flags & UNSEEN for u in contact if u.t >= start + FIRST_LOOK_S)
    assert any(u.state == GraspState.SLIP for u in ups if TURN[0] <= u.t <= TURN[0] + 0.1)


def test_a_still_hold_on_a_real_footprint_clears_the_flag_for_good() -> None:
    """A 70 s still hold of the 20 mm block (held-out seeds): the flag falls once, at
    the channel's first look, and never rises again."""
    for seed in (1000, 1001):
        for contact in _contacts(_updates("hold", seed)):
            bits = [bool(u.flags & UNSEEN) for u in contact]
            assert bits[0] and sum(a != b for a, b in zip(bits, bits[1:])) == 1, seed
            assert not any(u.flags & UNSEEN for u in contact if u.t >= contact[0].t + FIRST_LOOK_S), seed


def test_a_visibility_about_the_limit_leaves_the_flag_set_not_flapping() -> None:
    """A 5.5 mm contact (70 s hold, seed 1002): the channel's visibility lies about its
    limit (most renewals below, a few above, where the channel looks for a moment).
    The flag stays set through the whole contact: it clears only at twice the limit.
    (The footprint's own limit is off here: alone it would keep the flag set.)"""
    spec = conditions.contact_size(5.5)(load_scene("hold"))
    r = render(spec, 100.0, 1002)
    det = CofTrack(replace(DEFAULT_SETTINGS, cof_track=replace(DEFAULT_SETTINGS.cof_track, torsion_min_footprint=0.0)),
                   X, Y, 100.0)
    turn = det._turn
    assert turn is not None
    seen: list[float] = []
    hop = turn._hop

    def watched(frames: int) -> None:
        hop(frames)
        if turn._since == 0 and turn._learnt:  # a renewal that judged
            seen.append(turn.visibility)

    turn._hop = watched  # type: ignore[method-assign]
    ups = det.feed(r.t, r.forces)
    limit = DEFAULT_SETTINGS.cof_track.torsion_min_visibility
    above = sum(v >= limit for v in seen)
    assert 0 < above < 0.2 * len(seen)  # the channel itself looks now and then
    (contact,) = _contacts(ups)
    assert all(u.flags & UNSEEN for u in contact)


def test_a_turn_on_a_12_mm_square_is_missed_and_flagged_a_16_mm_one_found() -> None:
    """The channel finds a 12 mm square's template far out of its noise (visibility in
    the thousands) but mostly not its turn.  Its footprint (1.2 squared pitches from
    its centre) is below ``torsion_min_footprint`` (1.3): flagged throughout, not a
    plain miss; a slip it does report lies within the turn (from 9.4 s, 1 s long:
    seed 1001 since the contact rule learns the unloaded baseline and enters contact
    30 ms later).  A 16 mm square's turn is found (1.76), and the flag is clear."""
    for seed in (1000, 1001):
        small = _updates("twist", seed, 12.0)
        (contact,) = _contacts(small)
        assert all(u.flags & UNSEEN for u in contact), seed
        assert all(9.4 <= u.t <= 11.0 for u in small if u.state == GraspState.SLIP), seed
        big = _updates("twist", seed, 16.0)
        (contact,) = _contacts(big)
        assert not any(u.flags & UNSEEN for u in contact if u.t >= contact[0].t + FIRST_LOOK_S), seed
        assert any(u.state == GraspState.SLIP for u in big if TURN[0] <= u.t <= TURN[1]), seed


def test_without_the_channel_and_in_other_methods_nothing_is_flagged() -> None:
    """`torsion = false` and the other methods see no turn at all (docs/plc.md): the
    bit is never set by them, so it says something only with the channel on."""
    assert not any(u.flags & UNSEEN for u in _updates("twist", 1000, 5.0, torsion=False))

    r = render(conditions.contact_size(5.0)(load_scene("twist")), 100.0, 1000)
    for name, factory in by_name("paper", "cof-velocity", "force-rate", "hf-energy").items():
        table, _ = run_one(factory, DEFAULT_SETTINGS, r)
        assert not (table.flags & UNSEEN).any(), name


# -- on the wire: what a PLC reads --------------------------------------------------

@pytest.mark.parametrize(("size_mm", "unseen"), [(5.0, True), (None, False)])
def test_mbpoll_reads_the_bit_in_flags_through_a_turn(paper_profile, size_mm, unseen) -> None:
    """The bridge in server mode replays the twist (on a 5 mm contact, and as it is);
    mbpoll reads the image 0.3 s into the turn: DATA_VALID, no slip and TURN_UNSEEN in
    FLAGS on the small contact; slip and the bit clear on the block."""
    prof = paper_profile
    assert prof.detector.method == "cof-track"
    spec = load_scene("twist")
    if size_mm is not None:
        spec = conditions.contact_size(size_mm)(spec)
    scene = render(spec, prof.sensor.rate_hz, 1000)
    raw = np.rint(Calibrator.from_section(prof.calibration, prof.taxels).to_raw(scene.forces))
    port = free_port()
    server = PlcServer(prof.modbus.plc, tcp=("127.0.0.1", port)).start()
    try:
        bridge = NodeLoop(prof, ReplaySource(prof, scene.t, raw, 4000.0), [server.block(0)])
        deadline = time.monotonic() + 15.0
        while (u := bridge.pipeline.last_update) is None or u.t < TURN[0] + 0.3:
            assert time.monotonic() < deadline, "the scene did not reach the turn"
            bridge.step()
        bridge.publish_if_due(True)
        out = mbpoll("-m", "tcp", "-p", str(port), "-a", "1", "-r", "1", "-c", str(IMAGE_COUNT), "-1", "127.0.0.1")
        assert out.returncode == 0, out.stderr
        got = mbpoll_values(out.stdout)
        reg = {name: got[r.offset + 1] for name, r in REG.items()}
    finally:
        server.stop()
    assert reg["STATUS"] & int(Status.DATA_VALID)
    assert bool(reg["FLAGS"] & UNSEEN) is unseen
    # (from the sensor's raw counts, the one-taxel footprint's total wavers as the
    # square turns over it: this profile reads variable_force there, one entry)
    assert (reg["STATE"] == GraspState.SLIP) is not unseen


def test_detect_counts_the_unseen_updates_apart_from_flagged_frames(tmp_path) -> None:
    """`eskin-bus detect`: the CSV's flags carry the bit, and the summary counts those
    updates as turn unseen, not as updates with flagged frames (no frame was wrong)."""
    r = render(conditions.contact_size(5.0)(load_scene("twist")), 100.0, 1000)
    rec = tmp_path / "tw5.csv"
    write_recording(rec, r.t, r.forces)
    out = tmp_path / "out.csv"
    res = cli("detect", "-p", PAPER, str(rec), "-o", str(out), "--json")
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stderr.strip().splitlines()[-1])
    cols = read_updates(out)
    unseen = (cols["flags"].astype(int) & UNSEEN) != 0
    assert summary["turn_unseen"] == int(unseen.sum()) > 0.8 * len(unseen)
    assert summary["flagged"] == 0


def test_the_flags_bit_table_in_the_docs_names_every_bit() -> None:
    """docs/plc.md's FLAGS table: one row per FrameFlag, bit number and value right,
    and every bit within the 16 of the register."""
    docs = (ROOT / "docs" / "plc.md").read_text(encoding="utf-8")
    section = docs.split("## FLAGS bits", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| (\d+) \| (\d+) \| ([A-Z_]+) \|", section, re.M)
    assert [(int(b), int(v), n) for b, v, n in rows] == [
        (int(f).bit_length() - 1, int(f), f.name) for f in FrameFlag]
    assert max(int(f) for f in FrameFlag) < 1 << 16


# -- the failure map: a turn unseen and said so, against a plain miss ---------------

def test_evaluate_tells_a_flagged_miss_from_a_plain_one() -> None:
    """The twist on a 5 mm contact: its turn missed, flagged unseen, the flag in effect
    all the holding time; as it is: found, the flag never in effect while holding;
    with the channel off: missed, and nothing said (a plain miss)."""
    def score(size_mm: float | None, **overrides):
        settings = replace(DEFAULT_SETTINGS, cof_track=replace(DEFAULT_SETTINGS.cof_track, **overrides))
        hook = None if size_mm is None else conditions.contact_size(size_mm)
        return evaluate(by_name("cof-track"), scenes=("twist",), seeds=(1000,), settings=settings,
                        spec_hook=hook)["cof-track"].score

    small = score(5.0)
    assert small.events == 1 and small.found == 0 and small.missed_unseen == 1
    assert small.unseen_share == 1.0
    seen = score(None)
    assert seen.found == 1 and seen.missed_unseen == 0 and seen.unseen_share == 0.0
    blind = score(None, torsion=False)
    assert blind.found == 0 and blind.missed_unseen == 0 and blind.unseen_share == 0.0


def test_slip_guard_reads_turn_unseen_from_the_flags_word() -> None:
    """FB_SlipGuard's FLAGS input and the bit it reads come from the tables."""
    text = slip_guard_st()
    assert re.search(rf"\bwFlags\s*: WORD;\s*\(\* %MW{REG['FLAGS'].offset}\b", text)
    assert re.search(rf"\bbTurnUnseen\s*:= wFlags\.{UNSEEN.bit_length() - 1};", text)
