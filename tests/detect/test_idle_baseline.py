"""An idle noisy sensor reads no_contact steadily; a real touch is still entered.

The unloaded sensor reads 0.15 +- 0.04 N in total (an offset, noise and a slow drift:
ordinary for a piezoresistive film) against the default 0.2 N contact threshold.  A
plain threshold made the state go no_contact -> stable -> no_contact every few
frames (about 36 state changes a minute, each an urgent PLC write); the learnt
baseline and noise floor (detect/state.py, ContactRule) keep it out of contact."""

from __future__ import annotations

import numpy as np
import pytest

from eskin_industrial.detect.state import ContactRule, GraspState
from eskin_industrial.detect.updates import state_changed
from eskin_industrial.methods import get_method

RATE_HZ = 100.0
#: A touch of 1 N must be in contact within this long of its start.
TOUCH_WITHIN_S = 0.1


def idle_noisy(seconds: float, seed: int, n: int = 25) -> tuple[np.ndarray, np.ndarray]:
    """0.15 N offset over the array, noise 0.04 N RMS in the total, +-0.02 N of drift."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    total = 0.15 + 0.02 * np.sin(2 * np.pi * t / 40.0) + 0.04 * rng.standard_normal(len(t))
    share = rng.dirichlet(np.full(n, 50.0), len(t))
    return t, np.maximum(total, 0.0)[:, None] * share


def changes(states: np.ndarray) -> int:
    return int(np.count_nonzero(np.diff(states)))


@pytest.mark.parametrize("method", ["cof-track", "paper"])
def test_an_idle_noisy_sensor_makes_at_most_one_state_change_a_minute(paper_profile, method):
    x, y = paper_profile.coordinates_mm
    t, f = idle_noisy(120.0, seed=3)
    m = get_method(method)
    batch = m.batch(paper_profile.detector, x, y, RATE_HZ, t, f)
    assert changes(batch.state) <= 2, np.unique(batch.state, return_counts=True)  # 2 minutes
    # the streaming detector gives the same answer
    det = m.stream(paper_profile.detector, x, y, RATE_HZ)
    stream = np.array([int(u.state) for u in det.feed(t, f)])
    assert stream.tolist() == batch.state.tolist()


def test_a_plain_threshold_flaps_on_the_same_sensor():
    """The same input under the rule without a learnt baseline: the finding, kept as
    the reference the test above is measured against."""
    _, f = idle_noisy(60.0, seed=3)
    plain = ContactRule(0.2).mask(f.sum(axis=1))
    assert changes(plain.astype(int)) > 30


def test_a_real_touch_is_entered_in_time_and_no_baseline_hides_it(paper_profile):
    x, y = paper_profile.coordinates_mm
    t, f = idle_noisy(20.0, seed=4)
    touch = (t >= 12.0) & (t < 16.0)
    ramp = np.clip((t - 12.0) / 0.05, 0.0, 1.0)  # 1 N in 50 ms
    f = f + np.where(touch, ramp, 0.0)[:, None] * np.full(25, 1.0 / 25)
    det = get_method("cof-track").stream(paper_profile.detector, x, y, RATE_HZ)
    ups = det.feed(t, f)
    first = next(u.t for u in ups if u.t >= 12.0 and u.state != GraspState.NO_CONTACT)
    hop = paper_profile.detector.hop_s
    assert first - 12.0 <= TOUCH_WITHIN_S + hop, first
    assert sum(state_changed(a, b) for a, b in zip(ups, ups[1:])) <= 4  # in, (variable, stable,) out


def test_the_baseline_is_bounded_and_never_learnt_in_contact():
    rule = ContactRule(0.2, rate_hz=RATE_HZ, baseline_s=2.0, dwell_s=0.03, baseline_max_n=0.25)
    # a load that creeps up from nothing over a minute, never a step: the baseline
    # follows at most 0.25 N of it and the noise floor adds at most as much, so
    # 0.2 + 2 x 0.25 N of load is contact whatever the creep
    creep = np.linspace(0.0, 1.0, 6000)
    got = rule.mask(creep)
    assert got[np.searchsorted(creep, 0.7) + rule.dwell:].all()
    assert abs(rule.mask(creep[:10]).sum()) == 0  # (mask starts from a fresh rule)
    rule.reset()
    for s in [1.0] * 300:  # loaded from the first frame: contact, nothing learnt
        rule.touching(s)
    assert rule.on and rule.baseline == 0.0


@pytest.mark.parametrize(("method", "seed"), [("cof-track", 1000), ("cof-track", 1001), ("paper", 1002)])
def test_the_idle_scene_reads_no_contact_for_a_minute_then_enters_the_grasp(method, seed):
    """The built-in `idle` scene (held-out seeds): a minute of an idle noisy film, then
    a 4 N press at 60 s (0.1 s ramp).  The plain threshold made 70-160 state changes in
    that minute; now none, and the grasp is entered within TOUCH_WITHIN_S of the
    press (plus one update: paper's hop is 0.1 s)."""
    from eskin_industrial.detect.settings import DetectorSettings
    from eskin_industrial.evaluation.corpus import coordinates
    from eskin_industrial.scenes import render

    rec = render("idle", RATE_HZ, seed)
    x, y = coordinates(rec)
    cfg = DetectorSettings()
    table = get_method(method).batch(cfg, x, y, RATE_HZ, rec.t, rec.forces)
    assert changes(table.state[table.t < 60.0]) <= 1
    entered = table.t[(table.t >= 60.0) & (table.state != GraspState.NO_CONTACT)]
    assert entered.size and entered[0] - 60.0 <= TOUCH_WITHIN_S + cfg.hop_s


def phantom(seconds: float, seed: int, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """An idle 5 x 5 film whose unloaded total reads about 0.3 N from its first frame,
    above the 0.2 N threshold: rectified noise (0.03 N RMS a taxel, which a taxel that
    reads no tension clips at zero) or an offset (0.012 N a taxel, 0.005 N of noise)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    if kind == "noise":
        f = np.maximum(0.03 * rng.standard_normal((len(t), 25)), 0.0)
    else:
        f = np.maximum(0.012 + 0.005 * rng.standard_normal((len(t), 25)), 0.0)
    return t, f


@pytest.mark.parametrize("kind", ["noise", "offset"])
@pytest.mark.parametrize("method", ["cof-track", "paper"])
def test_an_idle_film_above_the_threshold_from_its_first_frame_is_no_contact(paper_profile, method, kind):
    """Before: contact was entered at the third frame, before any baseline was learnt,
    and never left: `stable` for the whole minute, nothing gripped.  Now the rule
    settles first (contact_settle_s) and learns the film's own total as its baseline;
    a 4 N press at 60 s is still entered in time."""
    x, y = paper_profile.coordinates_mm
    t, f = phantom(70.0, seed=11, kind=kind)
    assert 0.25 < f[t < 60.0].sum(axis=1).mean() < 0.35  # the finding's level
    press = np.clip((t - 60.0) / 0.1, 0.0, 1.0) * 4.0 / 25
    f = f + press[:, None] * (t >= 60.0)[:, None]
    m = get_method(method)
    batch = m.batch(paper_profile.detector, x, y, RATE_HZ, t, f)
    idle = batch.state[batch.t < 60.0]
    assert (idle == GraspState.NO_CONTACT).all(), np.unique(idle, return_counts=True)
    entered = batch.t[(batch.t >= 60.0) & (batch.state != GraspState.NO_CONTACT)]
    assert entered.size and entered[0] - 60.0 <= TOUCH_WITHIN_S + paper_profile.detector.hop_s
    det = m.stream(paper_profile.detector, x, y, RATE_HZ)  # the streaming answer is the batch's
    assert [int(u.state) for u in det.feed(t, f)] == batch.state.tolist()


def test_a_sensor_loaded_from_its_first_frame_is_in_contact_once_settled():
    """A bridge restarted while a part is held: contact once the rule has settled
    (0.1 s, then the dwell), and nothing of the load learnt as the baseline."""
    rule = ContactRule(0.2, rate_hz=RATE_HZ, baseline_s=2.0, dwell_s=0.03, baseline_max_n=0.25, settle_s=0.1)
    got = [rule.touching(8.0) for _ in range(100)]
    assert all(got) and rule.baseline == 0.0  # a clear load: at once, as after the settling
    rule.reset()
    got = [rule.touching(1.0) for _ in range(100)]  # always contact, not clear: after the dwell
    assert got.index(True) == rule.dwell - 1 and all(got[rule.dwell:]) and rule.baseline == 0.0
    rule.reset()  # a light load that may be the film's own is learnt, never contact
    assert not any(rule.touching(0.4) for _ in range(300)) and rule.baseline == 0.25
