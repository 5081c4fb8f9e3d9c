"""The torsion channel of cof-track (detect/torsion.py): a turn of the part about the
sensor's normal keeps the centre of force and the total force; the distribution's
rotational flow sees it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from eskin_industrial import load_profile
from eskin_industrial.detect.cof_track import CofTrack
from eskin_industrial.detect.torsion import TurnFlow, grid_of, turn_batch, turn_template
from eskin_industrial.evaluation import conditions
from eskin_industrial.evaluation.families import evaluate_families
from eskin_industrial.evaluation.suite import DEFAULT_SETTINGS
from eskin_industrial.profile import find_profile
from eskin_industrial.scenes import load_scene, render
from eskin_industrial.scenes.physics import sampled_forces
from eskin_industrial.scenes.spec import Footprint

XS = YS = np.arange(5) * 5.0  # the paper's 5 x 5 array, 5 mm pitch
X, Y = np.tile(XS, 5), np.repeat(YS, 5)


def _square(angle_deg: np.ndarray, seed: int, noise_n: float = 0.01) -> np.ndarray:
    """A 20 mm square block at 8 N in the middle of the 5 x 5 array, turned by
    ``angle_deg`` (one frame per angle), with taxel noise."""
    spec = load_scene("case2")
    k = len(angle_deg)
    f = sampled_forces(spec.array, Footprint(size_mm=(20.0, 20.0), centre_mm=(10.0, 10.0)),
                       np.tile([10.0, 10.0], (k, 1)), angle_deg, np.zeros((k, 2)), np.full(k, 8.0))
    return f + np.random.default_rng(seed).normal(0.0, noise_n, f.shape)


def test_the_flow_reads_a_small_turn_of_a_smooth_distribution() -> None:
    """On a fine grid, where the gradients are those of the distribution, the flow's
    angle is the turn's, within 5 %, and its sign follows the turn."""
    xs = ys = np.linspace(-10.0, 10.0, 41)
    gx, gy = np.meshgrid(xs, ys)

    def blob(turn: float) -> np.ndarray:  # an elongated Gaussian (a square's moments are isotropic)
        c, s = np.cos(turn), np.sin(turn)
        u, v = c * gx + s * gy, -s * gx + c * gy
        p = np.exp(-(u / 4.0) ** 2 - (v / 2.0) ** 2).ravel()
        return p / p.sum()

    g = turn_template(blob(0.0), xs, ys)
    assert g is not None
    for turn in (np.radians(0.5), -np.radians(0.5)):
        read = -float((blob(turn) - blob(0.0)) @ g)  # dp = -d theta g
        assert read == pytest.approx(turn, rel=0.05)


def test_a_turning_square_moves_the_angle_a_still_one_does_not() -> None:
    """The statistic's numeric core: a square (isotropic second moments) turning at
    30 degrees/s moves ``theta`` by more than 10 of its noise's standard deviations in
    0.2 s; the same square held still stays within 5 over 4 s."""
    block, blocks = 10, 5
    still = turn_batch(_square(np.zeros(600), seed=1), XS, YS, 1, block, blocks)[200:]
    sd = np.std(np.diff(still)) / np.sqrt(2.0)  # the per-frame noise of theta
    assert np.max(np.abs(still - still.mean())) < 5.0 * sd
    angle = np.concatenate([np.zeros(300), 30.0 * np.arange(1, 21) / 100.0])
    turning = turn_batch(_square(angle, seed=1), XS, YS, 1, block, blocks)
    assert abs(turning[-1] - turning[:300].mean()) > 10.0 * sd


def test_renewing_the_template_adds_no_drift() -> None:
    """``theta`` of a still square carries the frames' white noise, not a random walk:
    its spread over 8 s stays within 1.25 times the per-frame noise.  A template from
    one short block (5 frames) renewed as often wandered 1.56 times as far here, and
    three times on the torsion family's case4 at 4 N (each renewal's change of the
    template, times the frame's noise, is a step of the walk)."""
    f = _square(np.zeros(800), seed=2, noise_n=0.02)
    for block, blocks in ((10, 5), (5, 4)):
        theta = turn_batch(f, XS, YS, 1, block, blocks)
        sd = np.std(np.diff(theta)) / np.sqrt(2.0)
        assert np.std(theta) < 1.25 * sd, (block, blocks)


@pytest.mark.parametrize("projected", [False, True])
@pytest.mark.parametrize("hop", [1, 4])
def test_streaming_angle_equals_batch(hop: int, projected: bool) -> None:
    """After every whole hop the streaming angle is the batch one (hop means, the
    template renewed every 7 hops from the last 3 blocks); also when each frame's
    projection on the template comes from the caller's matrix product, whose column
    the channel keeps its template in (cof-track's way)."""
    f = _square(np.concatenate([np.zeros(150), 20.0 * np.arange(1, 101) / 100.0]), seed=3)
    flow = TurnFlow(XS, YS, hop, 7, 3, (5, 10, 20), 20, 5.5, 300)
    mat = np.column_stack([np.ones(f.shape[1]), np.zeros(f.shape[1])])
    if projected:
        flow.project_into(mat[:, 1])
    got = []
    for k, frame in enumerate(f):
        if projected:
            s, fg = (frame @ mat).tolist()
            flow.push(frame, s, False, fg)
        else:
            flow.push(frame, float(frame.sum()))
        if (k + 1) % hop == 0:
            got.append(flow.theta)
    np.testing.assert_allclose(got, turn_batch(f, XS, YS, hop, 7, 3), rtol=0, atol=1e-9)


def test_the_channel_needs_a_grid_of_two_rows_and_columns() -> None:
    assert grid_of(X, Y) is not None
    assert grid_of(np.arange(8) * 4.0, np.zeros(8)) is None  # a strip: no turn to see
    assert grid_of(X[::-1], Y) is None  # not row-major


def _cof_track(**overrides) -> CofTrack:
    settings = replace(DEFAULT_SETTINGS, cof_track=replace(DEFAULT_SETTINGS.cof_track, **overrides))
    return CofTrack(settings, X, Y, 100.0)


def _top_turn_score(det: CofTrack, t: np.ndarray, f: np.ndarray) -> float:
    """The channel's largest score over a recording."""
    top = 0.0
    score = det.score

    def watched(t, f, s, xc, yc):
        nonlocal top
        out = score(t, f, s, xc, yc)
        top = max(top, det.turn_score)
        return out

    det.score = watched  # type: ignore[method-assign]
    det.feed(t, f)
    return top


def _states(det: CofTrack, t: np.ndarray, f: np.ndarray) -> list[tuple[float, int, bool]]:
    return [(u.t, u.state, u.valid) for u in det.feed(t, f)]


def test_the_twist_is_read_as_slip_soon_and_held_through_the_turn() -> None:
    """The twist scene (seed 1000): the block turns 30 degrees at 30 degrees/s from
    9.4 s and its centre of force stays.  cof-track reads slip within 0.1 s, holds it
    through the turn (no flapping: one entry), and reads no slip before it; with the
    channel off, every update of the turn read stable and valid."""
    r = render("twist", 100.0, 1000)
    onset, end = 9.4, 10.4
    on = _states(_cof_track(), r.t, r.forces)
    slip = [t for t, state, valid in on if state == 3]
    assert slip and onset < slip[0] <= onset + 0.1
    during = [state for t, state, _ in on if slip[0] <= t <= end]
    assert all(state == 3 for state in during)
    assert not [t for t in slip if t < onset]
    off = _states(_cof_track(torsion=False), r.t, r.forces)
    turn = [(state, valid) for t, state, valid in off if onset <= t <= end]
    assert turn and all(state == 1 and valid for state, valid in turn)


@pytest.mark.parametrize("scene", ["hold", "case1"])
def test_a_still_hold_and_a_varying_force_do_not_turn(scene: str) -> None:
    """A still 70 s hold and the paper's varying force (6-10 N, no sliding), held-out
    seeds: the channel's score stays below its threshold throughout."""
    spec = load_scene(scene)
    for seed in (1000, 1001):
        r = render(spec, 100.0, seed)
        top = _top_turn_score(_cof_track(), r.t, r.forces)
        assert 0.0 < top < 1.0, (scene, seed)


def test_the_torsion_family_is_found_with_the_channel_and_missed_without() -> None:
    """Tuning seed 0 of the torsion family (cases 2-6 turned, and the twist): every
    turn found with no false alarm; none with the channel off."""
    methods = {"on": lambda s, x, y, r: CofTrack(DEFAULT_SETTINGS, x, y, r),
               "off": lambda s, x, y, r: CofTrack(replace(DEFAULT_SETTINGS, cof_track=replace(
                   DEFAULT_SETTINGS.cof_track, torsion=False)), x, y, r)}
    res = evaluate_families(methods, ("torsion",), (0,))["torsion"]
    on, off = res["on"].score, res["off"].score
    assert on.events == 9 and on.found == 9 and on.false_alarms == 0
    assert off.found == 0


def test_a_profile_turns_the_channel_off(tmp_path) -> None:
    text = find_profile("paper-5x5").read_text()
    path = tmp_path / "p.toml"
    path.write_text(text + "\n[detector.cof_track]\ntorsion = false\n" if "[detector.cof_track]" not in text
                    else text.replace("[detector.cof_track]\n", "[detector.cof_track]\ntorsion = false\n", 1))
    settings = load_profile(path).detector
    assert settings.cof_track.torsion is False
    assert CofTrack(settings, X, Y, 100.0)._turn is None


def test_a_contact_on_one_taxel_shows_no_turn_and_the_channel_stays_silent() -> None:
    """A 5 mm contact centred on one taxel (the failure map's tiny contact, 70 s of
    holding): the rotational derivative is the noise of its own template, which would
    turn at random at every renewal.  Its visibility stays below the threshold and the
    channel stays silent; a real footprint's (the still 20 mm block) is far above."""
    def visibilities(rec) -> list[float]:
        det = _cof_track()
        seen: list[float] = []
        score = det.score

        def watched(t, f, s, xc, yc):
            out = score(t, f, s, xc, yc)
            seen.append(det._turn.visibility)
            return out

        det.score = watched  # type: ignore[method-assign]
        det.feed(rec.t, rec.forces)
        return [v for v in seen if 0.0 < v < np.inf]

    tiny = render(conditions.contact_size(5.0)(load_scene("hold")), 100.0, 1002)
    assert _top_turn_score(_cof_track(), tiny.t, tiny.forces) == 0.0
    limit = DEFAULT_SETTINGS.cof_track.torsion_min_visibility
    assert max(visibilities(tiny)) < limit
    assert np.median(visibilities(render("hold", 100.0, 1002))) > 10 * limit
