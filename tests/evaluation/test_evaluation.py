"""Metrics on hand-made cases, and the accuracy claims on held-out seeds."""
from __future__ import annotations

import numpy as np
import pytest

from eskin_industrial.detect import GraspState, UpdateTable
from eskin_industrial.evaluation.metrics import score_scene
from eskin_industrial.evaluation.suite import (
    DEFAULT_SETTINGS,
    EVALUATION_SEEDS,
    HOLD_EVALUATION_SEEDS,
    HOLD_SCENES,
    HOLD_TUNING_SEEDS,
    SUITE,
    TUNING_SEEDS,
    by_name,
    evaluate,
)

S = GraspState


def table(times, states) -> UpdateTable:
    n = len(times)
    z = np.zeros(n)
    return UpdateTable(np.asarray(times, float), z, z, np.asarray(states), np.ones(n, bool), z + 5, z, z, np.zeros(n, np.int64), z, z)


def truth():
    t = np.arange(0, 20, 0.01)
    labels = np.full(t.size, "stable", dtype=object)
    labels[t < 1] = "no_contact"
    labels[(t >= 1) & (t < 1.5)] = "transition"
    labels[(t >= 5) & (t < 6)] = "slip"
    labels[(t >= 10) & (t < 12)] = "variable_force"
    labels[(t >= 15) & (t < 15.5)] = "slip"
    return t, labels


def test_found_late_missed_false_alarm_and_transition():
    t, labels = truth()
    times = np.arange(0.1, 20, 0.1)
    states = np.full(times.size, int(S.STABLE))
    states[(times > 1.1) & (times < 1.3)] = S.SLIP  # at the grab: don't care
    states[(times > 5.05) & (times < 5.3)] = S.SLIP  # found, 0.1 s late
    states[(times > 10.5) & (times < 10.8)] = S.SLIP  # varying force read as slip
    states[(times > 17.0) & (times < 17.3)] = S.SLIP  # plain false alarm
    s = score_scene(table(times, states), t, labels)
    assert (s.events, s.found, s.false_alarms, s.vf_as_slip) == (2, 1, 2, 1)
    assert s.delays_s == [pytest.approx(0.1)]
    assert s.precision == pytest.approx(1 / 3) and s.recall == 0.5
    assert s.holding_s == pytest.approx(20 - 1 - 0.5 - 1.0 - 0.5, abs=0.02)


def test_tolerance_after_the_end():
    t, labels = truth()
    times = np.arange(0.1, 20, 0.1)
    states = np.where((times > 15.8) & (times < 16.1), int(S.SLIP), int(S.STABLE))
    assert score_scene(table(times, states), t, labels, tolerance_s=0.5).found == 1
    assert score_scene(table(times, states), t, labels, tolerance_s=0.1).found == 0


def test_tuning_and_evaluation_seeds_are_disjoint():
    tuning = set(TUNING_SEEDS) | set(HOLD_TUNING_SEEDS)
    assert not tuning & (set(EVALUATION_SEEDS) | set(HOLD_EVALUATION_SEEDS))


@pytest.mark.slow
def test_our_method_meets_its_targets_on_held_out_seeds():
    """The default method on held-out seeds of the whole built-in suite (3 of the 10
    evaluation seeds, to keep the test short; docs/evaluation.md reports all 10)."""
    ours = evaluate(by_name("cof-track"), scenes=SUITE, seeds=EVALUATION_SEEDS[:3])["cof-track"]
    assert ours.score.events == 36
    assert ours.score.f1 >= 0.95
    assert ours.score.vf_as_slip == 0
    assert ours.score.false_alarms == 0
    # (the cost against the paper's is a benchmark's, not a test's: a wall-clock ratio
    # taken beside three other workers on two cores moved past 3x; benchmarks/bench_detector.py)
    assert ours.per_scene["case1"].false_alarms == 0  # varying force alone never reads slip


@pytest.mark.slow
def test_false_alarms_per_hour_of_held_out_holding_within_the_target():
    """False alarms per hour need hours: the still holds over the 100 held-out
    long-hold seeds (3.8 h).  The target is at most one per hour (the default before
    the long-hold check raised 2.4 per hour there, all on the light hand grip; the
    ramp channel's threshold spends some of the budget on delay: docs/evaluation.md)."""
    res = evaluate(by_name("cof-track"), scenes=HOLD_SCENES, seeds=HOLD_EVALUATION_SEEDS)
    score = res["cof-track"].score
    assert score.holding_s > 3 * 3600
    assert score.false_alarms_per_hour <= 1.0


def test_the_ramp_channel_shortens_the_delay_without_false_alarms():
    """cof-track with and without its ramp channel, on held-out seeds: the ramp must
    find every slip sooner than the displacement windows alone (median at least 20 %
    shorter) and add no false alarm; and sooner than the step channel beside the
    windows (the short horizon of the same sum, detect/step.py): on ramps the slope
    is the evidence, a jump is not."""
    from dataclasses import replace

    from eskin_industrial.detect.cof_track import CofTrack

    base = DEFAULT_SETTINGS
    step_only = replace(base, cof_track=replace(base.cof_track, ramp_z=1e9))
    off = replace(base, cof_track=replace(base.cof_track, ramp_z=1e9, step_s=0.0))
    methods = {"with": lambda s, x, y, r: CofTrack(base, x, y, r),
               "step only": lambda s, x, y, r: CofTrack(step_only, x, y, r),
               "without": lambda s, x, y, r: CofTrack(off, x, y, r)}
    res = evaluate(methods, scenes=("case3", "case4", "case6", "hand", "partial"), seeds=EVALUATION_SEEDS[3:6])
    on, step, no = res["with"].score, res["step only"].score, res["without"].score
    assert on.found == on.events == no.found == step.found
    assert on.false_alarms == no.false_alarms == step.false_alarms == 0
    assert np.median(on.delays_s) <= 0.8 * np.median(no.delays_s)
    assert np.median(on.delays_s) < np.median(step.delays_s)


def test_evaluate_takes_the_detector_settings_from_a_profile(tmp_path):
    from click.testing import CliRunner

    from eskin_industrial.cli import main

    loose = tmp_path / "loose.toml"
    loose.write_text('[sensor]\nname = "loose"\n[layout]\nrows = 5\ncols = 5\npitch_mm = 5.0\n'
                     '[calibration]\nraw_unit = "newton"\nzero = 0.0\nper_newton = 1.0\n'
                     '[detector.cof_track]\nz = 1.0\nmin_fast_mm = 0.0\nmin_slow_mm = 0.0\n')
    args = ["evaluate", "-m", "cof-track", "-s", "hold", "--seeds", "100,101"]

    def false_alarms(extra: list[str]) -> int:
        res = CliRunner().invoke(main, args + extra)
        assert res.exit_code == 0, res.output
        row = next(line for line in res.output.splitlines() if line.startswith("| cof-track |"))
        return int(row.split("|")[5].split()[0])

    assert false_alarms([]) == 0
    assert false_alarms(["-p", str(loose)]) > 0  # a threshold at the noise: the still hold flags slip


def test_seed_lists_mix_single_seeds_and_ranges():
    from click.testing import CliRunner

    from eskin_industrial.cli import main
    from eskin_industrial.cli.evaluate_cmd import _seeds

    assert _seeds("0..4,7,10..12") == (0, 1, 2, 3, 4, 7, 10, 11, 12)
    assert _seeds("tuning") == TUNING_SEEDS and _seeds("1000") == (1000,)
    res = CliRunner().invoke(main, ["evaluate", "-m", "cof-track", "--seeds", "0..x"])
    assert res.exit_code == 2 and "0..4,7,10..59" in res.output


def test_evaluate_prints_the_share_of_events_found_within_a_delay():
    from click.testing import CliRunner

    from eskin_industrial.cli import main

    res = CliRunner().invoke(main, ["evaluate", "-m", "cof-track", "-s", "case2", "-s", "creep", "--seeds", "1000,1001",
                                    "--within", "50", "--within", "100000"])
    assert res.exit_code == 0, res.output
    line = next(ln for ln in res.output.splitlines() if ln.startswith("# cof-track: of "))
    score = evaluate(by_name("cof-track"), scenes=("case2", "creep"), seeds=(1000, 1001))["cof-track"].score
    quick = sum(d <= 0.050 + 1e-9 for d in score.delays_s)
    assert 0 < quick < score.events  # case2 is faster than 50 ms, creep slower
    assert line == (f"# cof-track: of {score.events} slip events, {100 * quick / score.events:.0f} % within 50 ms, "
                    f"{100 * score.found / score.events:.0f} % within 100000 ms")


def stability_truth():
    """60 s at 100 Hz: a grab, two varying-force episodes (10-12 s, 20-24 s), a slip
    (30-31 s), stable elsewhere."""
    t = np.arange(6000) / 100.0
    labels = np.full(t.size, "stable", dtype=object)
    labels[t < 1] = "no_contact"
    labels[(t >= 1) & (t < 1.5)] = "transition"
    labels[(t >= 10) & (t < 12)] = "variable_force"
    labels[(t >= 20) & (t < 24)] = "variable_force"
    labels[(t >= 30) & (t < 31)] = "slip"
    return t, labels


def test_stability_metrics_on_a_known_sequence():
    t, labels = stability_truth()
    times = np.round(np.arange(1, 600) / 10.0, 6)  # an update every 100 ms
    states = np.full(times.size, int(S.STABLE))
    states[times < 1.0] = S.NO_CONTACT
    states[(times >= 10.3) & (times < 12.4)] = S.VARIABLE_FORCE  # one entry, one exit, 0.3 s late
    flap = (times >= 20.0) & (times < 24.0) & (np.round(times * 10) % 4 < 2)  # 0.2 s on, 0.2 s off
    states[flap] = S.VARIABLE_FORCE
    states[(times >= 30.1) & (times < 30.5)] = S.SLIP
    states[(times >= 45.0) & (times < 45.5)] = S.VARIABLE_FORCE  # a false entry in a still hold
    s = score_scene(table(times, states), t, labels)
    assert s.vf_episodes == 2 and s.vf_found == 2 and s.vf_recall == 1.0
    # episode 1: counted from 10.15 to 12.0, covered from 10.3; episode 2: half of 3.85 s
    first, second = s.vf_coverages
    assert first == pytest.approx(1.7 / 1.85)
    assert second == pytest.approx(0.5, abs=0.03)
    assert s.vf_coverage == pytest.approx((1.7 + 3.85 * second) / (1.85 + 3.85))
    assert s.vf_covered_share(0.9) == 0.5
    # episode 1: entry (10.3) and exit (12.4, within the allowance); episode 2: a change
    # every 0.2 s from 20.0 (the last, at 23.8, back to stable)
    assert s.vf_episode_changes == [2, 20]
    # inside the labels: 10.3 and the 20 changes 20.0 .. 23.8
    assert s.vf_span_s == pytest.approx(6.0)
    assert s.vf_span_changes == 1 + 20
    assert s.vf_changes_per_min == pytest.approx(21 / 0.1)
    # still time: stable at least 1 s after anything else: 2.5-10, 13-20, 25-30, 32-60 s;
    # the false entry and its exit are its only changes (the slip's exit at 30.5 is not)
    assert s.still_s == pytest.approx(7.5 + 7 + 5 + 28)
    assert s.still_changes == 2
    assert s.still_changes_per_min == pytest.approx(2 / (47.5 / 60))
    # while holding: every change but the grab's (1.0, labelled transition) and the
    # slip's two (30.1 and 30.5, labelled slip): episode 1's 2, the flapping 20, the
    # false entry's 2
    assert s.holding_changes == 2 + 20 + 2
    assert s.holding_changes_per_min == pytest.approx(24 / (s.holding_s / 60))
    # entered 0.3 s after onset and left 0.4 s after the end; the flapping one entered
    # at its onset and reads stable at its end
    assert s.vf_entry_s == pytest.approx([0.3, 0.0])
    assert s.vf_exit_s == pytest.approx([0.4, 0.0])
    # the slip, 30.0-31.0 s, found at 30.1 and left at 30.5, before its end: at its end
    assert s.slip_exit_s == pytest.approx([0.0])


def test_stability_of_a_steady_detector_and_of_one_that_never_sees_varying_force():
    t, labels = stability_truth()
    times = np.round(np.arange(1, 600) / 10.0, 6)
    quiet = np.where(times < 1.0, int(S.NO_CONTACT), int(S.STABLE))
    s = score_scene(table(times, quiet), t, labels)
    assert (s.vf_found, s.vf_coverage, s.vf_episode_changes, s.still_changes) == (0, 0.0, [0, 0], 0)
    assert s.vf_recall == 0.0
    # an episode's exit that comes after the allowance is a change in the still hold
    late = quiet.copy()
    late[(times >= 10.0) & (times < 13.5)] = S.VARIABLE_FORCE
    s = score_scene(table(times, late), t, labels)
    assert s.vf_episode_changes == [1, 0] and s.vf_coverages[0] == 1.0
    assert s.still_changes == 1


def test_stability_figures_add_over_scenes():
    t, labels = stability_truth()
    times = np.round(np.arange(1, 600) / 10.0, 6)
    states = np.where(times < 1.0, int(S.NO_CONTACT), int(S.STABLE))
    states[(times >= 10.0) & (times < 12.5)] = S.VARIABLE_FORCE
    one = score_scene(table(times, states), t, labels)
    both = score_scene(table(times, states), t, labels)
    both += one
    assert both.vf_episodes == 4 and both.vf_episode_changes == one.vf_episode_changes * 2
    assert both.vf_coverage == pytest.approx(one.vf_coverage)
    assert both.still_changes_per_min == pytest.approx(one.still_changes_per_min)


def test_evaluate_prints_how_steady_the_state_is():
    from click.testing import CliRunner

    from eskin_industrial.cli import main

    res = CliRunner().invoke(main, ["evaluate", "-m", "cof-track", "-s", "case1", "--seeds", "1"])
    assert res.exit_code == 0, res.output
    header = next(ln for ln in res.output.splitlines() if ln.startswith("| method | varying-force episodes"))
    row = [c.strip() for c in res.output.splitlines()[res.output.splitlines().index(header) + 2].split("|")[1:-1]]
    s = evaluate(by_name("cof-track"), scenes=("case1",), seeds=(1,))["cof-track"].score
    assert len(row) == len(header.split("|")) - 2
    assert row[0] == "cof-track" and row[1] == str(s.vf_episodes) == "4"
    assert row[2] == f"{s.vf_found} ({s.vf_recall:.2f})"
    assert row[4] == f"{np.mean(s.vf_episode_changes):.1f} / {max(s.vf_episode_changes)}"
    assert row[7] == f"{np.percentile(s.vf_entry_s, 50) * 1000:.0f} / {np.percentile(s.vf_entry_s, 90) * 1000:.0f}"


def test_the_timing_diagrams_of_the_state_policy_are_drawn_by_one_command(tmp_path):
    from click.testing import CliRunner

    from eskin_industrial.cli import main

    res = CliRunner().invoke(main, ["evaluate", "--charts", str(tmp_path), "--only", "timing"])
    assert res.exit_code == 0, res.output
    for name in ("state-timing.png", "state-timing-detail.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (tmp_path / "failure-map.png").exists()  # only what was asked for
    res = CliRunner().invoke(main, ["evaluate", "--only", "timing"])
    assert res.exit_code == 2 and "--charts" in res.output


def test_evaluate_pushes_a_failure_map_condition_on_every_scene():
    from click.testing import CliRunner

    from eskin_industrial.cli import main
    from eskin_industrial.evaluation.conditions import noise

    args = ["evaluate", "-m", "cof-track", "-s", "case1", "--seeds", "10"]
    res = CliRunner().invoke(main, args + ["--condition", "noise=0.1"])
    assert res.exit_code == 0, res.output
    assert res.output.startswith("# eskin-bus evaluate --seeds 10 --rate 100 --condition noise=0.1 ")
    row = next(ln for ln in res.output.splitlines() if ln.startswith("| cof-track | 4 |"))
    s = evaluate(by_name("cof-track"), scenes=("case1",), seeds=(10,), spec_hook=noise(0.1))["cof-track"].score
    plain = evaluate(by_name("cof-track"), scenes=("case1",), seeds=(10,))["cof-track"].score
    assert s.vf_coverages != plain.vf_coverages  # the noise changed what the detector saw
    assert f"{100 * s.vf_coverage:.0f} %" in row.split("|")[4]
    for bad in ("rate=3", "noise=x", "loud=1"):
        res = CliRunner().invoke(main, args + ["--condition", bad])
        assert res.exit_code == 2 and "--condition" in res.output


def test_the_delay_against_changes_chart_marks_the_front_of_lower_delay_and_fewer_changes(tmp_path):
    from eskin_industrial.evaluation.charts import _delay_vs_changes, pareto

    rows = [{"family": "cof-track", "delay_ms": 50.0, "still_min": 0.1, "vf_min": 38.0},
            {"family": "paper", "delay_ms": float("nan"), "still_min": 0.0, "vf_min": 38.0},
            {"family": "cof-velocity", "delay_ms": 90.0, "still_min": 12.0, "vf_min": 40.0}]
    own = [{"family": "cof-track", "delay_ms": 50.0, "still_min": 0.0, "vf_min": 216.0}]
    _delay_vs_changes(tmp_path, rows, own, (1000, 1002))
    assert (tmp_path / "delay-vs-changes.png").read_bytes()[:4] == b"\x89PNG"
    # lower delay and fewer changes are better: cof-velocity is dominated by cof-track
    pts = [(50.0, -0.1), (3000.0, -0.0), (90.0, -12.0)]
    assert sorted(pareto(pts)) == [0, 1]


@pytest.mark.slow
def test_the_family_map_marks_the_families_that_miss_a_target_and_every_unseen_turn(tmp_path):
    """families.png: each family's delay against the targets, red where missed, and a
    turn against the contact's size: found, or missed and flagged TURN_UNSEEN; a turn
    missed with no flag would be a plain miss, and there is none."""
    from eskin_industrial.evaluation.family_map import TARGET_P50_S, TARGET_P90_S, family_map

    lines: list[str] = []
    shown = family_map(tmp_path, (1000,), lines.append)
    assert (tmp_path / "families.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    by = {r["family"]: r for r in shown["families"]}
    assert by["line-contact"]["misses"] and by["torsion"]["misses"] and not by["hand"]["misses"]
    assert all(r["misses"] == (r["p50"] > TARGET_P50_S or r["p90"] > TARGET_P90_S) for r in by.values())
    turns = {t["size_mm"]: t for t in shown["turns"]}
    assert turns[5.0]["unseen"] == turns[5.0]["events"] == 1 and turns[20.0]["found"] == 1
    assert all(t["unflagged"] == 0 for t in turns.values())
    assert any("line-contact" in line for line in lines)


def test_the_slides_force_ripple_is_a_condition_of_the_command_not_of_the_map():
    from click.testing import CliRunner

    from eskin_industrial.cli import main
    from eskin_industrial.evaluation.conditions import CONDITIONS, MORE_CONDITIONS
    from eskin_industrial.scenes import load_scene

    spec = MORE_CONDITIONS["ripple"][2](0.12)(load_scene("case6"))
    assert [e.stick_slip_force for e in spec.events if e.kind == "slide"] == [0.12] * 4
    assert spec.events[0] == load_scene("case6").events[0] and "ripple" not in CONDITIONS  # the map's nine stay
    res = CliRunner().invoke(main, ["evaluate", "-m", "cof-step", "-s", "case2", "--seeds", "0",
                                    "--condition", "ripple=0.12"])
    assert res.exit_code == 0, res.output
    assert res.output.startswith("# eskin-bus evaluate --seeds 0 --rate 100 --condition ripple=0.12 ")
