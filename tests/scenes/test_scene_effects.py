"""The scene effects added for the effect families, each alone: creep and hysteresis
of the film, temperature drift, crosstalk, smooth slides, torsional slip, soft
contacts, lift-off at slip onset, line and point contacts."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from eskin_industrial import ProfileError
from eskin_industrial.scenes import load_scene, render, sensor
from eskin_industrial.scenes.physics import (
    footprint_forces,
    lift_off_gradient,
    rotation_deg,
    sampled_forces,
    slide_offset,
    stepped_slide,
)
from eskin_industrial.scenes.spec import ArraySpec, Event, Footprint, SensorEffects, parse_scene

A5 = ArraySpec(5, 5, 5.0)
X, Y = np.tile(np.arange(5) * 5.0, 5), np.repeat(np.arange(5) * 5.0, 5)


def cof(f: np.ndarray) -> np.ndarray:
    s = f.sum(axis=1)
    return np.column_stack([(f @ X) / s, (f @ Y) / s])


def quiet(spec):
    """The same scene with no sensor noise: what the effect alone does."""
    return replace(spec, sensor=replace(spec.sensor, noise_n=0.0))


def test_film_creep_rises_with_its_time_constant_and_lags_on_unloading():
    t = np.arange(0, 60, 0.01)
    load = np.where((t >= 1) & (t < 31), 2.0, 0.0)[:, None] * np.ones((1, 3))
    out = sensor.film_creep(load, t, 0.1, 5.0, 15.0)
    def at(s):
        return out[np.searchsorted(t, s), 0]
    assert at(1.0) == pytest.approx(2.0, rel=1e-2)  # no creep at the step itself
    assert at(6.0) == pytest.approx(2.0 * (1 + 0.1 * (1 - np.exp(-1))), rel=2e-3)  # one time constant
    assert at(30.99) == pytest.approx(2.2, rel=2e-3)  # settled: + 10 %
    # unloaded, the excess decays with the recovery time constant (15 s), not 5 s
    assert at(46.0) == pytest.approx(0.2 * np.exp(-1), rel=5e-3)
    # hysteresis: at the same load the unloading branch reads more than the loading one
    ramp = np.concatenate([np.linspace(0, 4, 1000), np.linspace(4, 0, 1000)])[:, None]
    tr = np.arange(2000) * 0.01
    r = sensor.film_creep(ramp, tr, 0.1, 5.0, 15.0)[:, 0]
    assert r[1500] - ramp[1500, 0] > 2 * (r[499] - ramp[499, 0]) > 0  # both at 2 N


def test_crosstalk_neighbours_read_the_set_fraction():
    f = np.zeros((1, 25))
    f[0, 12] = 3.0
    out = sensor.crosstalk(f, 5, 5, 0.05)
    assert out[0, 12] == 3.0
    for n in (7, 11, 13, 17):
        assert out[0, n] == pytest.approx(0.15)
    assert out[0, [6, 8, 16, 18, 0]].max() == 0.0  # not diagonally, not further


def test_temperature_drift_moves_every_taxel_with_its_own_gain():
    t = np.arange(0, 100, 0.1)
    out = sensor.baseline_drift(np.zeros((t.size, 400)), t, 0.001, 0.3, np.random.default_rng(0))
    slope = out[-1] / t[-1]
    np.testing.assert_allclose(out, t[:, None] * slope[None, :], atol=1e-12)  # linear, from 0
    assert slope.mean() == pytest.approx(0.001, rel=0.05) and slope.std() / 0.001 == pytest.approx(0.3, rel=0.15)


def _hf_energy(total: np.ndarray) -> float:
    return float(np.mean(np.diff(total, 2) ** 2))


def test_smooth_slide_has_no_force_ripple_above_the_noise():
    stick = load_scene("case3")
    smooth = replace(stick, events=tuple(replace(e, stick_slip_mm=0.0, stick_slip_force=0.0) for e in stick.events))
    for spec, low, high in ((smooth, 0.7, 1.5), (stick, 10.0, np.inf)):
        rec = render(spec, 100.0, 1)
        total = rec.forces.sum(axis=1)
        hold = total[(rec.t > 4) & (rec.t < 9)]
        slide = total[(rec.t > 9.6) & (rec.t < 11.2)]
        assert low < _hf_energy(slide) / _hf_energy(hold) < high


def test_torsional_slip_turns_the_footprint_and_leaves_the_centre():
    t = np.arange(0, 3, 0.01)
    events = (Event("rotate", 1.0, angle_deg=30.0, angular_speed_deg_s=30.0),)
    angle = rotation_deg(t, events)
    assert angle[50] == 0 and angle[150] == pytest.approx(15.0) and angle[-1] == pytest.approx(30.0)
    foot = Footprint((20.0, 8.0), (10.0, 10.0))
    f = sampled_forces(A5, foot, np.tile([10.0, 10.0], (t.size, 1)), angle, np.zeros((t.size, 2)), np.full(t.size, 8.0))
    assert np.abs(cof(f) - 10.0).max() < 0.02  # the centre of force stays within 0.02 mm ...
    d = f / f.sum(axis=1, keepdims=True)  # ... while the distribution's long axis turns with the object
    axis = 0.5 * np.degrees(np.arctan2(2 * d @ ((X - 10) * (Y - 10)), d @ ((X - 10) ** 2 - (Y - 10) ** 2)))
    assert axis[50] == pytest.approx(0.0, abs=1e-6) and abs(axis[-1] - 30.0) < 3.0 and np.all(np.diff(axis) > -1e-9)
    spec = parse_scene('[scene]\nname = "t"\nduration_s = 4.0\n[[events]]\nkind = "press"\nt_s = 0.5\nforce_n = 6.0\n'
                       '[[events]]\nkind = "rotate"\nt_s = 2.0\nangle_deg = -20.0\nangular_speed_deg_s = 40.0\n', "t.toml")
    rec = render(spec, 100.0, 0)
    def at(s):
        return rec.labels[np.searchsorted(rec.t, s)]
    assert (at(1.5), at(2.2), at(2.6)) == ("stable", "slip", "stable")


def test_soft_contact_grows_with_force():
    foot = Footprint((8.0, 8.0), (10.0, 10.0), size_exponent=0.33, reference_force_n=2.0)
    f = footprint_forces(A5, foot, np.tile([10.0, 10.0], (2, 1)), np.array([2.0, 16.0]))
    spread = [(row / row.sum()) @ ((X - 10) ** 2 + (Y - 10) ** 2) for row in f]
    assert spread[1] > 1.5 * spread[0] and np.count_nonzero(f[1]) > np.count_nonzero(f[0])
    hard = footprint_forces(A5, replace(foot, size_exponent=0.0), np.tile([10.0, 10.0], (2, 1)), np.array([2.0, 16.0]))
    np.testing.assert_allclose(hard[1] / hard[1].sum(), hard[0] / hard[0].sum())  # a rigid block does not


def test_lift_off_unloads_the_trailing_part_as_the_slide_starts():
    t = np.arange(0, 3, 0.01)
    slide = Event("slide", 1.0, distance_mm=(2.0, 0.0), speed_mm_s=2.0, lift_off_per_mm=0.15, lift_off_s=0.1)
    g = lift_off_gradient(t, (slide,))
    assert g[99, 0] == 0 and g[115, 0] == pytest.approx(0.15) and g[-1, 0] == 0 and np.all(g[:, 1] == 0)
    foot = Footprint((20.0, 20.0), (10.0, 10.0))
    f = sampled_forces(A5, foot, np.tile([10.0, 10.0], (t.size, 1)), np.zeros(t.size), g, np.full(t.size, 8.0))
    trailing = f[:, X == 0.0].sum(axis=1)
    assert trailing[50] > 0.9 and trailing[115] < 0.01  # the first column unloads ...
    np.testing.assert_allclose(f.sum(axis=1), 8.0)  # ... the normal force does not change
    assert cof(f)[115, 0] > 12.0  # the centre of force jumps forward


def test_sampled_footprint_matches_the_exact_rectangle():
    K = 200
    c = np.column_stack([np.linspace(5, 16, K), np.full(K, 10.3)])
    exact = footprint_forces(A5, Footprint((20.0, 14.0)), c, np.full(K, 8.0))
    sampled = sampled_forces(A5, Footprint((20.0, 14.0)), c, np.zeros(K), np.zeros((K, 2)), np.full(K, 8.0))
    np.testing.assert_allclose(sampled, exact, atol=1e-9)


def test_line_and_point_contacts():
    def one(foot):
        return sampled_forces(A5, foot, np.array([[10.0, 10.0]]), np.zeros(1), np.zeros((1, 2)), np.array([6.0]))[0]
    line = one(Footprint((3.0, 20.0), shape="cylinder"))
    assert line.sum() == pytest.approx(6.0) and line[X != 10.0].max() == 0.0  # one column carries it all
    np.testing.assert_allclose(line[(X == 10.0) & (Y > 0) & (Y < 20)], 1.5)  # uniform along the line
    point, flat = one(Footprint((6.0, 6.0), shape="sphere")), one(Footprint((6.0, 6.0)))
    assert point.sum() == pytest.approx(6.0) and point[12] > flat[12]  # Hertzian: peaked at its centre
    assert np.count_nonzero(point > 1e-9) == 5  # the disc (radius 3 mm) misses the diagonal cells


def test_new_keys_are_validated_like_the_others():
    with pytest.raises(ProfileError, match="did you mean 'creep_fraction'"):
        parse_scene('[scene]\nname = "x"\n[sensor]\ncreep_fractoin = 0.1\n', "x.toml")
    with pytest.raises(ProfileError, match="shape"):
        parse_scene('[scene]\nname = "x"\n[footprint]\nshape = "cube"\n', "x.toml")
    spec = parse_scene('[scene]\nname = "x"\n[sensor]\ncrosstalk = 0.05\ncreep_fraction = 0.1\n', "x.toml")
    assert spec.sensor == SensorEffects(crosstalk=0.05, creep_fraction=0.1)


def _stepped(hz=(10.0,), rest=(0.7,), speed=2.0, distance=2.0):
    return Event("slide", 1.0, distance_mm=(distance, 0.0), speed_mm_s=speed, step_hz=hz, step_rest=rest)


def _path(event, seed=0, rate=1000.0):
    t = np.arange(0, 1.0 + event.end_s, 1.0 / rate)
    offset, ripple = stepped_slide(t, event, np.random.default_rng(seed))
    return t, slide_offset(t, (event,))[:, 0] + offset[:, 0], ripple


def test_a_stepped_slide_jumps_then_rests_and_keeps_its_length_and_speed():
    e = _stepped()
    t, x, ripple = _path(e)
    during = (t >= e.t_s) & (t < e.end_s)
    assert x[t < e.t_s].max() == 0.0 and x[-1] == pytest.approx(2.0)  # the whole distance, no more
    v = np.diff(x)
    assert v.min() >= -1e-12  # it sticks and jumps forward, never back
    moving = v[during[1:]] > 1e-9
    assert 0.2 < moving.mean() < 0.4  # at rest for 70 % of each period
    # one jump per period: 10 in the 1 s slide at 10 Hz, each the period's share of the
    # slide: 0.2 mm (the speed over the rate), the periods wandering by 20 %
    starts = np.flatnonzero(np.diff(np.concatenate(([0], moving.astype(int)))) == 1)
    assert 8 <= starts.size <= 12
    jumps = np.add.reduceat(v[during[1:]], starts)
    assert 0.1 < jumps.min() and jumps.max() < 0.3 and jumps.mean() == pytest.approx(0.2, rel=0.2)
    # the first jump starts at the onset, so the slide's label is when it first moves
    assert x[np.searchsorted(t, e.t_s + 0.01)] > 0.0
    # the normal force ripples with the jumps: it drops as each one starts
    drop = np.flatnonzero(np.diff(ripple[during]) < -0.05)
    assert drop.size == starts.size - 1 and np.abs(drop - starts[1:]).max() <= 2
    assert np.abs(ripple - 1.0).max() < 0.04 * 2.5


def test_a_stepped_slides_rate_and_rest_are_drawn_per_seed_within_their_ranges():
    e = _stepped(hz=(6.0, 18.0), rest=(0.5, 0.8), distance=4.0)
    seen = []
    for seed in range(6):
        t, x, _ = _path(e, seed)
        moving = np.diff(x) > 1e-9
        jumps = int(np.sum(np.diff(np.concatenate(([0], moving.astype(int)))) == 1))
        rest = 1.0 - moving[(t[1:] >= e.t_s) & (t[1:] < e.end_s)].mean()
        assert 6.0 * 2.0 * 0.8 <= jumps <= 18.0 * 2.0 * 1.2 and 0.45 <= rest <= 0.85
        seen.append((jumps, round(rest, 2)))
    assert len(set(seen)) == 6  # each seed its own
    np.testing.assert_array_equal(_path(e, 3)[1], _path(e, 3)[1])  # reproducible


def test_a_stepped_scene_renders_with_the_slides_labels_and_other_scenes_draw_as_before():
    base = load_scene("case5")
    steps = replace(base, events=tuple(replace(e, step_hz=(6.0, 18.0), step_rest=(0.5, 0.8)) if e.kind == "slide"
                                       else e for e in base.events))
    a, b = render(base, 100.0, 3), render(steps, 100.0, 3)
    np.testing.assert_array_equal(a.labels, b.labels)
    during = a.labels == "slip"
    qa, qb = render(quiet(base), 100.0, 3).forces, render(quiet(steps), 100.0, 3).forces
    np.testing.assert_allclose(qa[~during], qb[~during], atol=1e-12)  # the same before, and where it ends
    xb = cof(qb[during])[:, 0]
    assert np.mean(np.abs(np.diff(xb)) < 1e-9) > 0.4  # it rests
    # the keys draw only where step_hz is set: a rest share alone changes nothing
    rest_only = replace(base, events=tuple(replace(e, step_rest=(0.6,)) for e in base.events))
    np.testing.assert_array_equal(render(rest_only, 100.0, 3).forces, a.forces)


def test_step_keys_are_one_value_or_a_range():
    slide = '[scene]\nname = "x"\n[[events]]\nkind = "slide"\nt_s = 1.0\ndistance_mm = [2.0, 0.0]\n'
    assert parse_scene(slide + "step_hz = [6.0, 18.0]\nstep_rest = [0.5]\n", "x.toml").events[0].step_hz == (6.0, 18.0)
    for bad, match in (("step_hz = [18.0, 6.0]", "step_hz: expected one value or a range"),
                       ("step_hz = [6.0, 9.0, 12.0]", "step_hz: expected one value or a range"),
                       ("step_rest = []", "step_rest: expected one value or a range"),
                       ("step_rest = [0.99]", r"step_rest.*expected a value in \[0, 0.95\]"),
                       ("step_hz = [0.1]", r"step_hz.*expected a value in \[0.5, 100\]")):
        with pytest.raises(ProfileError, match=match):
            parse_scene(slide + bad + "\n", "x.toml")
