"""Where methods fail, the product degrades into a defined state: finite indicators,
no exception, no storm of false slip flags, and the not-valid bit when it cannot know."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from eskin_industrial import FrameFlag
from eskin_industrial.detect import GraspState
from eskin_industrial.detect.methods import get_method
from eskin_industrial.detect.settings import DetectorSettings
from eskin_industrial.evaluation import conditions
from eskin_industrial.evaluation.metrics import score_scene
from eskin_industrial.evaluation.suite import run_one
from eskin_industrial.scenes import load_scene, render

SEED = 1002  # an evaluation seed
METHODS = ("cof-track", "paper")


def run(method, hook, scene="hold", rate=100.0):
    spec = hook(load_scene(scene)) if hook else load_scene(scene)
    rec = render(spec, rate, SEED)
    table, _ = run_one(get_method(method).stream, DetectorSettings(), rec)
    for col in ("r_coe", "r_dw", "f_sum", "xc", "yc"):
        assert np.isfinite(getattr(table, col)).all(), col
    return rec, table


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name,hook", [
    ("extreme noise", conditions.noise(0.1)),
    ("light touch", conditions.force_scale(0.05)),
    ("dead taxels", conditions.dead_taxels(8)),
    ("machine vibration", conditions.vibration(2.0)),
    ("machine starting to shake mid-hold", conditions.vibration_onset(1.0)),
    ("dropped frames", conditions.drop_rate(0.2)),
    ("tiny contact", conditions.contact_size(5.0)),
])
def test_still_hold_under_a_failure_condition_raises_no_storm(method, name, hook):
    # 70 s of holding: at most one false slip episode (the grab is a don't-care span)
    rec, table = run(method, hook)
    assert score_scene(table, rec.t, rec.labels).false_alarms <= 1, name


@pytest.mark.parametrize("method", METHODS)
def test_dropped_frames_are_flagged(method):
    _, table = run(method, conditions.drop_rate(0.1))
    assert (table.flags & FrameFlag.GAP_BEFORE).any()


@pytest.mark.parametrize("method", METHODS)
def test_a_silent_sensor_reads_not_valid_until_it_has_history_again(method):
    rec = render("hold", 100.0, SEED)
    keep = (rec.t < 20.0) | (rec.t > 25.0)  # five seconds of silence
    det = get_method(method).stream(DetectorSettings(), *(np.tile(np.arange(5) * 5.0, 5), np.repeat(np.arange(5) * 5.0, 5)), 100.0)
    updates = det.feed(rec.t[keep], rec.forces[keep])
    after = [u for u in updates if u.t > 25.0]
    assert after[0].flags & FrameFlag.RESET or not after[0].valid
    assert not after[0].valid and after[-1].valid
    assert all(u.state != GraspState.SLIP for u in after)


def test_low_sample_rate_degrades_without_nan():
    # 50 Hz: the one-level detail band is 12.5-25 Hz; still defined output
    for method in METHODS:
        rec, table = run(method, None, scene="case2", rate=50.0)
        assert table.valid.any()


@pytest.mark.parametrize("drop", [0.1, 0.2, 0.4])
def test_many_dropped_frames_still_detect_and_never_divide_by_zero(drop):
    # held copies across gaps carry no CoF step: they must not teach a zero noise
    rec, table = run("cof-track", conditions.drop_rate(drop), scene="case2")
    s = score_scene(table, rec.t, rec.labels)
    assert s.found == 1 and s.false_alarms == 0


def test_with_the_onward_gate_on_dropped_frames_raise_no_false_slip():
    """The gate never opens on a held copy nor on the real frame after one: that frame
    moves the centre by the gap's motion at once (0.16 mm here), which opened the gate
    and let the step test read the held copy's step as a jump (a second slip 40 ms
    after the slide's first ended, before the held-copy rule)."""
    spec = conditions.drop_rate(0.2)(load_scene("case2"))
    rec = render(spec, 100.0, SEED)
    base = DetectorSettings()
    settings = replace(base, cof_track=replace(base.cof_track, onward_open=0.25, force_covariate=4.0))
    table, _ = run_one(get_method("cof-track").stream, settings, rec)
    s = score_scene(table, rec.t, rec.labels)
    assert s.found == 1 and s.false_alarms == 0


@pytest.mark.parametrize("scene", ["case1", "case2", "hand"])
def test_the_grab_itself_reads_no_slip_with_the_default_method(scene):
    rec, table = run("cof-track", None, scene=scene)
    first_slide = min([e.t_s for e in load_scene(scene).events if e.kind == "slide"], default=np.inf)
    before = table.t < first_slide
    assert not (table.state[before] == GraspState.SLIP).any()
    # (in contact: the state, since contact is judged on the total minus the learnt
    # unloaded baseline, not on the total against 0.2 N)
    touching = table.state != GraspState.NO_CONTACT
    assert not table.valid[touching][0]  # the first updates in contact say "not yet"


def test_a_touch_at_the_contact_threshold_does_not_toggle_the_state():
    # the total force wobbles around contact_threshold_n (0.2 N) for two seconds
    rng = np.random.default_rng(0)
    t = np.arange(300) / 100.0
    total = np.where(t < 0.5, 0.0, 0.2 + 0.03 * rng.standard_normal(300))
    forces = np.tile(total[:, None] / 25.0, (1, 25)) * (1 + 0.1 * rng.standard_normal((300, 25)))
    x, y = np.tile(np.arange(5) * 5.0, 5), np.repeat(np.arange(5) * 5.0, 5)
    det = get_method("cof-track").stream(DetectorSettings(), x, y, 100.0)
    states = np.array([u.state for u in det.feed(t, forces)])
    touched = np.flatnonzero(states != GraspState.NO_CONTACT)[0]
    assert not (states[touched:] == GraspState.NO_CONTACT).any()  # once touching, no flicker back


@pytest.mark.parametrize("covariate", [True, False])
def test_a_swaying_glass_on_a_hand_with_eight_dead_taxels_stays_bounded(covariate: bool):
    """The failure the map found for cof-track: 8 of the hand's 20 taxels dead, and the
    glass swayed.  With the defaults (the force covariate off) some sways read as slip
    (half the force is on dead taxels); pinned here: every such episode is short and
    few, the indicators stay finite, and the real slip is still found.  With the
    covariate on, it explains this seed's sway away: no false slip."""
    spec = conditions.dead_taxels(8)(load_scene("hand"))
    rec = render(spec, 100.0, 1)  # a tuning seed where the sway reads as slip three times
    settings = DetectorSettings()
    if covariate:
        settings = replace(settings, cof_track=replace(settings.cof_track, force_covariate=4.0))
    table, _ = run_one(get_method("cof-track").stream, settings, rec)
    assert np.isfinite(table.r_coe).all() and np.isfinite(table.r_dw).all()
    s = score_scene(table, rec.t, rec.labels)
    assert s.found == s.events == 1
    assert (s.false_alarms == 0) if covariate else (1 <= s.false_alarms <= 4)
    slip = np.asarray(table.state) == int(GraspState.SLIP)
    t = np.asarray(table.t)
    starts = np.flatnonzero(slip & ~np.r_[False, slip[:-1]])
    ends = np.flatnonzero(slip & ~np.r_[slip[1:], False])
    false_lengths = [t[b] - t[a] for a, b in zip(starts, ends) if t[a] < 15.5]
    # (each lasts its evidence, kept down to 0.8 of the thresholds, and then hold_s,
    # 0.2 s, without any)
    assert len(false_lengths) == s.false_alarms and max(false_lengths, default=0.0) <= 0.5
