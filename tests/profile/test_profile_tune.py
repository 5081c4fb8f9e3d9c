"""Teach-in (`eskin-bus profile tune`): thresholds set from holds of a noisy, jittery
sensor meet the target on held-out holds of the same sensor, and the slides are
still found."""
from __future__ import annotations

import dataclasses
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from eskin_industrial.detect.settings import DetectorSettings
from eskin_industrial.errors import OutputFileError
from eskin_industrial.evaluation import teach as tt
from eskin_industrial.evaluation.corpus import coordinates
from eskin_industrial.methods import all_methods, ready_method
from eskin_industrial.recording import read_updates, write_recording
from eskin_industrial.scenes import load_scene, render
from tests.helpers.paths import PROFILES

PAPER = PROFILES / "paper-5x5.toml"
RATE = 100.0


def cli(*args: str, cwd: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], capture_output=True, text=True,
                          timeout=170, cwd=cwd)


def holds(seeds: tuple[int, ...]) -> list[tt.Hold]:
    spec = tt.jittery(load_scene("hold"))
    out = []
    for seed in seeds:
        r = render(spec, RATE, seed)
        out.append(tt.Hold(f"hold {seed}", r.t, r.forces))
    return out


def xy() -> tuple[np.ndarray, np.ndarray]:
    return coordinates(render(load_scene("hold"), RATE, 0))


@pytest.fixture(scope="module")
def taught() -> tuple[tt.Taught, list[tt.Hold]]:
    # nine of the hold scene's 72 s: 10.8 min, just over the 10 the rule asks for 1 an hour
    tuning = holds(tt.JITTERY_TUNING_SEEDS[:9])
    assert sum(h.seconds for h in tuning) / 3600.0 >= tt.min_hold_hours(1.0)
    x, y = xy()
    return tt.teach("cof-track", DetectorSettings(), x, y, RATE, tuning, per_hour=1.0), tuning


@pytest.mark.slow
def test_taught_thresholds_meet_the_target_on_held_out_holds(taught):
    result, _ = taught
    # untuned, the jittery sensor alarms often: well above 1 an hour on the tuning holds
    assert result.before / result.hours > 100
    assert result.after <= result.allowed == 0
    assert all(c.new > c.old for c in result.changes)
    # held out: seeds no teaching saw, 18 min of holding (the default's rate on them too)
    x, y = xy()
    held = holds(tt.JITTERY_HELD_OUT_SEEDS[:15])
    hours = sum(h.seconds for h in held) / 3600.0
    method = ready_method("cof-track", result.settings)
    tuned = sum(tt.slip_entries(tt.run(method, result.settings, x, y, RATE, h)) for h in held)
    assert tuned / hours <= 1.0
    default = ready_method("cof-track", DetectorSettings())
    untuned = sum(tt.slip_entries(tt.run(default, DetectorSettings(), x, y, RATE, h)) for h in held[:2])
    assert untuned / (2 * 72 / 3600) > 100


@pytest.mark.slow
def test_slides_are_still_found_after_teaching(taught):
    result, tuning = taught
    x, y = xy()
    seen = tt.sensor_noise(tuning, x, y)
    # what the holds show: four times the default noise, and up to 1 mm of jitter
    assert 0.035 < seen.noise_n < 0.045 and 0.8 < seen.jitter_mm < 1.25
    s = tt.slide_score("cof-track", result.settings, tt.slide_scenes(5, 5), RATE, seen)
    assert s.events == 16 and s.found >= s.events // 2
    assert np.isfinite(s.delay_percentile(50)) and np.isfinite(s.delay_percentile(90))


def test_the_jittery_scene_wanders_by_up_to_its_bound():
    spec = tt.jittery(load_scene("hold"), noise_n=0.0)
    r = render(spec, RATE, tt.JITTERY_TUNING_SEEDS[0])
    x, y = coordinates(r)
    held = r.labels == "stable"
    total = r.forces[held].sum(axis=1)
    xc, yc = r.forces[held] @ x / total, r.forces[held] @ y / total
    excursion = max(np.abs(xc - xc.mean()).max(), np.abs(yc - yc.mean()).max())
    assert 0.7 < excursion <= tt.JITTERY_JITTER_MM + 0.05


def test_every_detecting_method_declares_thresholds_it_has():
    for name, method in all_methods().items():
        if name == "none":
            assert not method.tunable
            continue
        assert method.tunable, name
        own = method.settings_of(DetectorSettings())
        scores = {s.name for s in method.scores}
        for th in method.tunable:
            assert set(th.keys) <= {f.name for f in dataclasses.fields(own)}, name
            assert set(th.scores) <= scores, name


@pytest.mark.slow
def test_a_quiet_sensor_is_taught_near_the_defaults():
    # the scenes' own sensor: cof-track's thresholds move by little, and nothing alarms
    x, y = xy()
    quiet = [tt.Hold(f"hold {s}", r.t, r.forces) for s in (3000, 3001)
             for r in [render(load_scene("hold"), RATE, s)]]
    result = tt.teach("cof-track", DetectorSettings(), x, y, RATE, quiet, per_hour=10.0)
    assert result.before == result.after == 0
    for c in result.changes:
        assert 0.8 * c.old < c.new < 1.6 * c.old, c


def test_set_keys_keeps_the_rest_of_the_file():
    from eskin_industrial.cli.profile_tune import set_keys

    text = ('# cell 7\n[sensor]\nname = "cell7"  # the left finger\n\n[detector.cof_track]\n'
            '# chosen at commissioning\nz = 6.0  # noise\nfast_s = 0.1\n\n[output]\nrefresh_s = 0.05\n')
    out = set_keys(text, "detector.cof_track", {"z": 9.5, "ramp_z": 8.25}, "cell7.toml")
    assert out.startswith('# cell 7\n[sensor]\nname = "cell7"  # the left finger\n')
    assert "# chosen at commissioning\nz = 9.5\nfast_s = 0.1\nramp_z = 8.25\n\n[output]" in out
    assert tomllib.loads(out)["detector"]["cof_track"] == {"z": 9.5, "fast_s": 0.1, "ramp_z": 8.25}
    appended = set_keys('[sensor]\nname = "a"', "detector", {"slip_r_coe": 3.0}, "a.toml")
    assert tomllib.loads(appended) == {"sensor": {"name": "a"}, "detector": {"slip_r_coe": 3.0}}
    with pytest.raises(OutputFileError, match=r"a\.toml: \[detector.cof_track\] z is set outside"):
        set_keys('[detector]\ncof_track.z = 7.0\n', "detector.cof_track", {"z": 9.0}, "a.toml")


@pytest.mark.slow
def test_cli_tunes_a_profile_and_detect_reads_it(tmp_path):
    # at 6 false alarms an hour the rule asks for 100 s of holding: two of the scene's 72 s
    paths = []
    for seed in (3000, 3001, 3100):
        r = render(tt.jittery(load_scene("hold")), RATE, seed)
        paths.append(tmp_path / f"hold{seed}.csv")
        write_recording(paths[-1], r.t, r.forces)
    profile = tmp_path / "cell.toml"
    profile.write_text(PAPER.read_text(encoding="utf-8"), encoding="utf-8")
    res = cli("profile", "tune", str(profile), str(paths[0]), str(paths[1]), "--false-alarms-per-hour", "6",
              cwd=str(tmp_path))
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert "method cof-track, 2 recording(s), 2.4 min of holding" in lines[0]
    assert any(line.split()[:2] == ["[detector.cof_track]", "ramp_z"] for line in lines)
    assert any(line.startswith("false alarms an hour on the holds: ") and line.endswith(" after (0)") for line in lines)
    after = next(line for line in lines if line.startswith("slides after: "))
    assert " found, delay median " in after and not after.startswith("slides after: 0 of")
    tuned = tmp_path / "cell.tuned.toml"  # a copy by default; the profile itself is as it was
    assert profile.read_text(encoding="utf-8") == PAPER.read_text(encoding="utf-8")
    assert tuned.read_text(encoding="utf-8").startswith(PAPER.read_text(encoding="utf-8"))
    section = tomllib.loads(tuned.read_text(encoding="utf-8"))["detector"]["cof_track"]
    assert section["ramp_z"] > 5.5 and section["z"] > 6.0
    # detect reads the tuned profile: a held-out hold of the same sensor raises no slip
    counts = {}
    for name, prof in (("default", profile), ("tuned", tuned)):
        out = tmp_path / f"{name}.csv"
        res = cli("detect", "-p", str(prof), str(paths[2]), "-o", str(out), "-q")
        assert res.returncode == 0, res.stderr
        state = read_updates(out)["state"]
        counts[name] = int(np.sum((state[1:] == "slip") & (state[:-1] != "slip")))
    assert counts["default"] > 3 and counts["tuned"] == 0
    # --write: in place; a recording of moves counts as holding; given slides are run instead of the scenes
    r = render(tt.jittery(load_scene("case2")), RATE, 1000)
    slide = tmp_path / "slide.csv"
    write_recording(slide, r.t, r.forces)
    res = cli("profile", "tune", str(tuned), str(paths[0]), "--moves", str(paths[1]), "--slides", str(slide),
              "--false-alarms-per-hour", "6", "--write")
    assert res.returncode == 0, res.stderr
    assert "2 recording(s), 2.4 min of holding" in res.stdout
    found = next(line for line in res.stdout.splitlines() if line.startswith(f"slides: {slide}: "))
    assert found.endswith(" after") and not found.endswith(" 0 after"), found
    text = tuned.read_text(encoding="utf-8")
    assert text.count("[detector.cof_track]") == 1  # the keys replaced where they were
    # taught again from the same holds, the rule lands where it did (its runs at the new
    # settings learn the noise a little differently)
    assert tomllib.loads(text)["detector"]["cof_track"]["ramp_z"] == pytest.approx(section["ramp_z"], rel=0.05)


@pytest.mark.slow
def test_cli_refuses_bad_input_in_one_line(tmp_path):
    r = render(load_scene("hold"), RATE, 3000)
    hold = tmp_path / "hold.csv"
    write_recording(hold, r.t, r.forces)
    hand = tmp_path / "hand.csv"
    h = render(load_scene("hand-hold"), RATE, 3000)
    write_recording(hand, h.t[:500], h.forces[:500])
    cases = [
        (("profile", "tune", str(PAPER)), "give at least one RECORDING of stable holds"),
        (("profile", "tune", str(PAPER), str(hand)), "20 taxel columns, but the profile has 25 taxels"),
        (("profile", "tune", str(PAPER), str(hold), "-o", str(tmp_path / "t.toml")),
         "1 recording(s) hold 1.2 min in all: too short to say 1 false alarm(s) an hour; record 10.0 min"),
        (("profile", "tune", "paper-5x5", str(hold), "--write"), "is a built-in profile, which --write cannot change"),
        (("profile", "tune", str(PAPER), str(hold), "-m", "none"), "method none declares no threshold to teach"),
    ]
    for args, message in cases:
        res = cli(*args, cwd=str(tmp_path))
        assert res.returncode == 2, (args, res.stderr)
        assert message in res.stderr and res.stderr.count("\n") <= 2, (args, res.stderr)
    assert not (tmp_path / "t.toml").exists()


def test_a_grab_and_a_release_are_no_hold():
    from eskin_industrial.detect.updates import UpdateTable

    t = np.arange(0.0, 10.0, 0.1)
    state = np.where((t >= 1.0) & (t < 9.0), 1, 0)  # contact from 1 s to 9 s
    state[(t >= 1.1) & (t < 1.3)] = 3  # a slip in the grab's half second: no false alarm
    state[(t >= 5.0) & (t < 5.2)] = 3  # one in the hold: a false alarm
    state[(t >= 8.7) & (t < 8.9)] = 3  # one in the release's half second: none
    score = np.where(state == 3, 9.0, 0.5)
    n = len(t)
    table = UpdateTable(t=t, r_coe=score, r_dw=score, state=state, valid=np.ones(n, bool), f_sum=np.ones(n),
                        xc=np.zeros(n), yc=np.zeros(n), flags=np.zeros(n, np.int64), score_a=score, score_b=score)
    assert tt.slip_entries(table) == 1
    held = tt.holding(table)
    # (the last update in contact is at 8.9 s)
    assert held[(t > 1.55) & (t < 8.35)].all() and not held[(t < 1.45) | (t > 8.45)].any()
    # the grab's scores set nothing: the peaks are the hold's (its slip's second, then calm ones)
    peaks = tt.block_peaks([table], ("score_a",))
    assert peaks[0] == 9.0 and peaks[1] == 0.5
