"""Effect families and leave-one-family-out: each family switches on its one effect,
the choice never sees the held-out family, and the CLI lists, scores and holds out."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from eskin_industrial.evaluation import holdout
from eskin_industrial.evaluation.families import (
    FAMILIES,
    FORCE_DROP,
    SHAKE_AMPLITUDE,
    SHAKE_HZ,
    STEP_HZ,
    STEP_REST,
    get_family,
)
from eskin_industrial.evaluation.holdout import CANDIDATES, choose, hold_out
from eskin_industrial.evaluation.metrics import SceneScore
from eskin_industrial.evaluation.suite import SUITE
from eskin_industrial.scenes import load_scene, render


def test_the_suite_families_cover_the_suite_once():
    scenes = [s for f in FAMILIES.values() if f.in_suite for s in f.scenes]
    assert sorted(scenes) == sorted(SUITE) and all(f.hook is None for f in FAMILIES.values() if f.in_suite)


@pytest.mark.parametrize("name", [f for f, fam in FAMILIES.items() if not fam.in_suite])
def test_each_new_family_switches_on_its_effect(name):
    fam = get_family(name)
    base = load_scene("case3" if "case3" in fam.scenes else fam.scenes[0])  # (the shake: the hand)
    spec = fam.hook(base) if fam.hook else base
    assert spec != base and spec.array == base.array
    slides = [e for e in spec.events if e.kind == "slide"]
    checks = {
        "film-creep": lambda: spec.sensor.creep_fraction == 0.1,
        "temperature-drift": lambda: spec.sensor.drift_n_per_s > 0,
        "crosstalk": lambda: spec.sensor.crosstalk == 0.08,
        "smooth-slide": lambda: all(e.stick_slip_mm == e.stick_slip_force == 0 for e in slides),
        "torsion": lambda: not slides and [e.kind for e in spec.events] == ["press", "rotate"],
        "soft": lambda: spec.footprint.size_exponent > 0 and spec.footprint.reference_force_n == 8.0,
        "lift-off": lambda: all(e.lift_off_per_mm > 0 for e in slides),
        "line-contact": lambda: spec.footprint.shape == "cylinder",
        "point-contact": lambda: spec.footprint.shape == "sphere",
        "step-slip": lambda: all(e.step_hz == STEP_HZ and e.step_rest == STEP_REST for e in slides),
        "force-drop": lambda: all(e.force_drop == FORCE_DROP for e in slides),
        "shake": lambda: [(e.amplitude, e.freq_hz) for e in spec.events if e.kind == "oscillate"] == [(SHAKE_AMPLITUDE, SHAKE_HZ)],
    }
    assert checks[name]()
    rec = render(spec, 100.0, 0)
    assert np.isfinite(rec.forces).all() and (rec.labels == "slip").any()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_force_drop_slide_loses_its_drawn_share_of_the_force_at_onset_and_stays_down(seed):
    """The force-drop family: the normal force falls by 10-30 % (drawn per seed and
    slide) within force_drop_s of the slide's start, and stays there, against the
    plain scene (whose footprint leaves the array as it slides: the sensed total falls
    there too)."""
    spec = get_family("force-drop").hook(load_scene("case2"))
    (slide,) = [e for e in spec.events if e.kind == "slide"]
    rec = render(spec, 1000.0, seed)
    plain = render(load_scene("case2"), 1000.0, seed)
    before = (rec.t > slide.t_s - 0.5) & (rec.t < slide.t_s)
    after = (rec.t > slide.t_s + slide.force_drop_s + 0.02) & (rec.t < slide.end_s)

    def kept(forces: np.ndarray) -> float:
        total = forces.sum(axis=1)
        return float(total[after].mean() / total[before].mean())

    ratio = kept(rec.forces) / kept(plain.forces)
    assert 1.0 - FORCE_DROP[1] - 0.03 < ratio < 1.0 - FORCE_DROP[0] + 0.03, ratio


def test_torsion_turns_as_far_as_the_slide_moved():
    spec = get_family("torsion").hook(load_scene("case6"))
    turns = [e for e in spec.events if e.kind == "rotate"]
    assert [round(e.angle_deg, 1) for e in turns] == [28.6, -28.6, 28.6, -28.6]
    assert all(e.end_s - e.t_s == pytest.approx(1.0) for e in turns)  # 5 mm at 5 mm/s: as long as the slide


def _score(events, found, fa, hours, delays_ms):
    return SceneScore(events=events, found=found, false_alarms=fa, holding_s=hours * 3600,
                      delays_s=[d / 1000 for d in delays_ms])


def test_choose_false_alarms_first_then_f1_then_delay_then_the_default():
    a = _score(10, 10, 2, 1.0, [50] * 10)  # 2 per hour: beyond the target
    b = _score(10, 9, 0, 1.0, [40] * 9)
    c = _score(10, 9, 0, 1.0, [30] * 9)
    assert choose({"a": a, "b": b, "c": c}) == "c"
    assert choose({"b": b, "b2": _score(10, 9, 0, 1.0, [40.0000001] * 9)}) == "b"  # whole ms: a tie, the first
    assert choose({"a": a, "a2": _score(10, 10, 3, 1.0, [10] * 10)}) == "a"  # none within: the fewest


def test_hold_out_never_chooses_on_the_held_out_family(monkeypatch):
    labels = [c.label for c in CANDIDATES["cof-track"]]
    good, fair = _score(10, 10, 0, 1.0, [50] * 10), _score(10, 9, 0, 1.0, [50] * 9)
    # everywhere the first candidate is a little better; on "torsion" the second, by far
    tuning = {fam: {lab: (good if lab == labels[0] else fair) for lab in labels} for fam in FAMILIES}
    tuning["torsion"] = {lab: _score(100, 100 if lab == labels[1] else 0, 0, 1.0, [10] * (100 if lab == labels[1] else 0))
                         for lab in labels}
    seen = []
    monkeypatch.setattr(holdout, "evaluate_families", lambda methods, fams, seeds, *a, **k: seen.append((fams, seeds))
                        or {fams[0]: {lab: type("R", (), {"score": good})() for lab in methods}})
    h = hold_out("cof-track", "torsion", tuning)
    assert h.chosen == labels[0] and seen == [(("torsion",), holdout.EVALUATION_SEEDS)]
    assert hold_out("cof-track", "hold", tuning).chosen == labels[1]  # with torsion among the choosers


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "eskin_industrial", "evaluate", *args], capture_output=True,
                          text=True, timeout=120)


def test_cli_lists_families_and_scores_per_family():
    listing = _cli("--families")
    assert listing.returncode == 0 and all(f"| {f} |" in listing.stdout for f in FAMILIES)
    res = _cli("--per-family", "--family", "torsion", "--family", "lift-off", "-m", "cof-track", "--seeds", "0",
               "--format", "json")
    assert res.returncode == 0, res.stderr
    doc = json.loads(res.stdout)
    assert set(doc["families"]) == {"torsion", "lift-off"} and doc["families"]["lift-off"]["cof-track"]["events"] == 8  # cases 2-5 one each, case6 four
    md = _cli("--per-family", "--family", "lift-off", "-m", "cof-track", "--seeds", "0", "--per-scene", "--within", "100")
    assert md.returncode == 0, md.stderr
    assert "|   | case6 | 4 | 4 |" in md.stdout and "# lift-off, cof-track: 100 % within 100 ms" in md.stdout
    row = next(line for line in md.stdout.splitlines() if line.startswith("| lift-off | cof-track |"))
    mean, top = row.split("|")[-2].split(" / ")  # slip episodes per found slide
    assert 1.0 <= float(mean) <= int(top) and doc["families"]["lift-off"]["cof-track"]["slip_episodes_per_event_max"] >= 1
    bad = _cli("--per-family", "--family", "torsoin", "--seeds", "0")
    assert bad.returncode == 2 and "unknown family 'torsoin'" in bad.stderr
    two = _cli("--hold-out-family", "torsion", "-m", "cof-track", "-m", "paper")
    assert two.returncode == 2 and "at most one -m" in two.stderr
    seeds = _cli("--hold-out-family", "torsion", "--seeds", "0")  # the seeds are the discipline's, not a choice
    assert seeds.returncode == 2 and "leave out --seeds" in seeds.stderr


def test_new_families_draw_their_own_noise_at_the_same_seed():
    base = load_scene("case2")
    fam = get_family("crosstalk")
    ours, again = render(fam.hook(base), 100.0, 4, fam.stream), render(fam.hook(base), 100.0, 4, fam.stream)
    same_draws = render(fam.hook(base), 100.0, 4)
    np.testing.assert_array_equal(ours.forces, again.forces)  # reproducible
    assert not np.allclose(ours.forces, same_draws.forces)
    assert get_family("stick-slip").stream is None  # the suite's own draw as the suite does
    assert len({f.stream for f in FAMILIES.values() if not f.in_suite}) == sum(not f.in_suite for f in FAMILIES.values())


def test_where_a_family_defeats_the_delay_target_the_state_is_late_but_steady():
    """Most families miss the delay target (median 40 ms; line contact and torsion by
    far: docs/evaluation.md). The defined degraded behaviour there is a late slip that
    is one slip: no flicker off and on within a slide, and no state changes in still
    holds, on every family at a tuning seed (0).  (With ``hold_from = "entry"``, the
    rule before, 7 families flicker, up to 5 entries for one slide.)"""
    from eskin_industrial.evaluation.families import evaluate_families
    from eskin_industrial.evaluation.suite import by_name

    res = evaluate_families(by_name("cof-track"), tuple(FAMILIES), (0,))
    late = {f for f, by in res.items() if by["cof-track"].score.delays_s
            and by["cof-track"].score.delay_percentile(50) > 0.040}
    assert {"line-contact", "torsion", "creep"} <= late  # the families where the target is out of reach
    for fam, by in res.items():
        s = by["cof-track"].score
        assert s.found == s.events, fam
        assert not s.slip_episodes or max(s.slip_episodes) <= 2, (fam, s.slip_episodes)
        assert sum(e > 1 for e in s.slip_episodes) <= max(1, len(s.slip_episodes) // 10), (fam, s.slip_episodes)
        assert s.still_changes == 0, fam
