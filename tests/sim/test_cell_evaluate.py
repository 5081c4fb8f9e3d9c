"""``eskin-bus evaluate --closed-loop``: one record per control, the same figures in
one process or several, the baselines behaving as they must, and bad input refused
in one line."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

SEEDS = "9000..9004"  # five held-out episodes: one of each object


def evaluate(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", "evaluate", *args], capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.slow
def test_json_has_a_record_per_control_and_the_same_figures_with_two_worker_processes():
    args = ["--closed-loop", "--seeds", SEEDS, "-m", "cof-track", "-m", "fixed", "-m", "none", "--format", "json"]
    one, two = evaluate(*args), evaluate(*args, "--jobs", "2")
    assert one.returncode == 0, one.stderr
    assert two.returncode == 0, two.stderr
    doc, doc2 = json.loads(one.stdout), json.loads(two.stdout)
    rows = {r["control"]: r for r in doc["methods"]}
    assert list(rows) == ["cof-track", "fixed", "none", "oracle"]  # the oracle joins: figures are against it
    strip = lambda d: [{k: v for k, v in r.items()} for r in d["methods"]]  # noqa: E731
    assert strip(doc) == strip(doc2)
    for r in rows.values():
        assert r["episodes"] == 5 and r["held"] + r["dropped"] + r["crushed"] == 5
        assert 0.0 <= r["held_share"] <= 1.0 and r["crushed"] <= r["fragile"] == 3
        assert r["needless_squeezes_per_hour"] >= 0 and r["grip_vs_fixed"] > 0
        assert set(r["per_object"]) == {"glass", "part", "box", "egg", "cup"}
    fixed, none = rows["fixed"], rows["none"]
    assert fixed["grip_vs_fixed"] == pytest.approx(1.0, abs=1e-3)  # it is the reference
    assert fixed["raises"] == none["raises"] == 0 and fixed["slid_p90_mm"] == 0.0
    assert none["grip_vs_fixed"] < 1.0  # the light grip
    assert rows["oracle"]["held_of_oracle_share"] == 1.0
    assert doc["setup"]["rate_hz"] == 100 and doc["setup"]["plc_cycle_ms"] == 10


@pytest.mark.slow
def test_a_sweep_has_every_point_with_every_control_and_a_slower_plc_cycle_answers_later():
    res = evaluate("--closed-loop", "--sweep", "plc-cycle", "--seeds", "9400,9405", "-m", "none", "--format", "json")
    assert res.returncode == 0, res.stderr
    doc = json.loads(res.stdout)
    assert doc["sweep"] == "plc-cycle" and doc["unit"] == "ms"
    points = {p["value"]: {r["control"]: r for r in p["methods"]} for p in doc["points"]}
    assert list(points) == [4.0, 10.0, 20.0]
    for rows in points.values():
        assert list(rows) == ["none", "oracle"] and all(r["episodes"] == 2 for r in rows.values())
        assert rows["none"]["raises"] == 0  # no slip sensing: nothing to react to
    # the oracle hears of a slide at once; what is left is the transport and the PLC's cycle
    assert points[4.0]["oracle"]["reaction_p50_ms"] < points[20.0]["oracle"]["reaction_p50_ms"]


@pytest.mark.parametrize("args, message", [
    (["--closed-loop", "--cell", "nope=1"], "--cell"),
    (["--closed-loop", "--cell", "mass=-1"], "positive"),
    (["--closed-loop", "--cell", "mass"], "--cell"),
    (["--closed-loop", "--cell", "gripper=big"], "gripper= one of"),
    (["--closed-loop", "--cell", "force_drop=1.5"], "share below 1"),
    (["--sweep", "rate"], "--closed-loop"),
    (["--cell", "mass=1.2"], "--closed-loop"),
    (["--closed-loop", "--per-family"], "--per-family"),
    (["--closed-loop", "-s", "case2"], "--scene"),
    (["-m", "oracle"], "--closed-loop"),
    (["--closed-loop", "--seeds", "9000..x"], "seeds such as"),
])
def test_bad_input_is_refused_in_one_line(args, message):
    res = evaluate(*args, timeout=60)
    assert res.returncode == 2, res.stdout
    assert message in res.stderr and res.stderr.strip().count("\n") <= 3, res.stderr
