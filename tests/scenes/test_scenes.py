"""The scene simulator: each effect alone, then whole scenes, files and the CLI."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from eskin_industrial import ProfileError
from eskin_industrial.recording import read_recording
from eskin_industrial.scenes import list_scenes, load_scene, render, sensor
from eskin_industrial.scenes.physics import footprint_forces, force_profile, slide_offset, stick_slip
from eskin_industrial.scenes.spec import ArraySpec, Event, Footprint, parse_scene

A5 = ArraySpec(5, 5, 5.0)


def test_footprint_on_the_array_measures_the_applied_force():
    f = footprint_forces(A5, Footprint((10.0, 10.0), (10.0, 10.0)), np.array([[10.0, 10.0]]), np.array([8.0]))
    assert f.sum() == pytest.approx(8.0)
    assert np.count_nonzero(f) == 9  # covers the middle 3 x 3 cells, partly the outer ones
    x = np.tile(np.arange(5) * 5.0, 5)
    assert (f[0] @ x) / f.sum() == pytest.approx(10.0)


def test_footprint_off_the_array_loses_force_and_tilt_moves_the_centre():
    off = footprint_forces(A5, Footprint((10.0, 10.0)), np.array([[22.5, 10.0]]), np.array([8.0]))
    assert off.sum() == pytest.approx(4.0)  # half of it hangs over the edge
    tilted = footprint_forces(A5, Footprint((20.0, 20.0), gradient_per_mm=(0.03, 0.0)), np.array([[10.0, 10.0]]), np.array([8.0]))
    x = np.tile(np.arange(5) * 5.0, 5)
    assert (tilted[0] @ x) / tilted.sum() > 10.5


def test_force_profile_and_slide():
    t = np.arange(0, 10, 0.01)
    events = (Event("press", 1.0, 0.5, force_n=6.0), Event("force", 4.0, 1.0, force_n=10.0),
              Event("slide", 6.0, distance_mm=(6.0, 0.0), speed_mm_s=3.0), Event("release", 9.0, 0.2))
    f = force_profile(t, events)
    assert f[50] == 0 and f[200] == pytest.approx(6.0) and f[550] == pytest.approx(10.0) and f[-1] == 0
    off = slide_offset(t, events)
    assert off[599, 0] == 0 and off[700, 0] == pytest.approx(3.0) and off[850, 0] == pytest.approx(6.0)


def test_stick_slip_only_while_sliding():
    t = np.arange(0, 5, 0.001)
    jitter, factor = stick_slip(t, (Event("slide", 2.0, distance_mm=(5.0, 0.0), speed_mm_s=5.0),), np.random.default_rng(0))
    assert np.all(jitter[t < 2.0] == 0) and np.all(factor[t >= 3.0] == 1.0)
    assert jitter[(t > 2.0) & (t < 3.0), 0].std() > 0.05 and np.all(jitter[:, 1] == 0)


@pytest.mark.parametrize("effect", ["gain", "vibration", "noise", "quantize", "saturate", "dead", "drops"])
def test_each_sensor_effect_alone(effect):
    rng = np.random.default_rng(1)
    f = np.full((2000, 25), 0.4)
    t = np.arange(2000) / 1000.0
    if effect == "gain":
        out = sensor.gain_mismatch(f, 0.05, rng)
        assert out.std(axis=0).max() < 1e-12 and 0.01 < out[0].std() / 0.4 < 0.1
    elif effect == "vibration":
        out = sensor.machine_vibration(f, t, 0.5, 50.0)
        assert out.sum(axis=1).max() == pytest.approx(10.5, abs=1e-3) and out.mean() == pytest.approx(0.4, abs=1e-3)
        late = sensor.machine_vibration(f, t, 0.5, 50.0, start_s=1.0)  # the machine starts at 1 s
        np.testing.assert_array_equal(late[t < 1.0], f[t < 1.0])
        np.testing.assert_allclose(late[t >= 1.0], out[: int((t >= 1.0).sum())])
    elif effect == "noise":
        assert sensor.noise(f, 0.02, rng).std() == pytest.approx(0.02, rel=0.05)
    elif effect == "quantize":
        out = sensor.quantize(f + 0.013, 0.01)
        assert set(np.round(out[0] / 0.01, 6)) == {41.0}
    elif effect == "saturate":
        assert sensor.saturate(f * 40, 10.0).max() == 10.0
    elif effect == "dead":
        out = sensor.dead_and_stuck(f, (3,), (4,), 2.0)
        assert out[:, 3].max() == 0 and out[:, 4].min() == 2.0 and out[:, 5].min() == 0.4
    else:
        kept = sensor.drop_frames(2000, 0.1, rng)
        assert 150 < 2000 - kept.size < 250 and np.all(np.diff(kept) > 0)


def test_labels_of_the_paper_case2():
    rec = render("case2", 100.0, 3)
    def at(t):
        return rec.labels[np.searchsorted(rec.t, t)]
    assert (at(0.5), at(1.2), at(5.0), at(9.6), at(12.0)) == ("no_contact", "transition", "stable", "slip", "stable")


def test_render_is_seeded_and_rate_free():
    a, b, c = render("case4", 100.0, 1), render("case4", 100.0, 1), render("case4", 100.0, 2)
    np.testing.assert_array_equal(a.forces, b.forces)
    assert not np.array_equal(a.forces, c.forces)
    fast = render("case4", 1000.0, 1)
    assert fast.forces.shape == (14000, 25) and abs(fast.forces.sum(1).max() - a.forces.sum(1).max()) < 0.3


def test_builtin_suite_and_user_scene_files(tmp_path):
    names = list_scenes()
    assert {"case1", "case6", "hand", "hold", "creep", "partial", "vibration"} <= set(names)
    assert render("hand", 100.0, 0).forces.shape[1] == 20
    path = tmp_path / "mine.toml"
    path.write_text('[scene]\nname = "mine"\nduration_s = 3.0\n[[events]]\nkind = "press"\nt_s = 0.5\nforce_n = 2.0\n')
    assert render(str(path), 50.0, 0).forces.shape == (150, 25)
    with pytest.raises(ProfileError, match=r"\[events\[0\]\] force_n: expected a force"):
        parse_scene('[scene]\nname = "x"\n[[events]]\nkind = "press"\nt_s = 0.5\n', "x.toml")
    with pytest.raises(ProfileError, match="did you mean 'duration_s'"):
        parse_scene('[scene]\nname = "x"\nduraton_s = 2.0\n', "x.toml")
    with pytest.raises(ProfileError, match="unknown scene"):
        load_scene("case9")


def test_simulate_cli(tmp_path):
    listing = subprocess.run([sys.executable, "-m", "eskin_industrial", "simulate", "--list"], capture_output=True, text=True, timeout=60)
    assert listing.returncode == 0 and "case2" in listing.stdout and "hand" in listing.stdout
    rec, lab = tmp_path / "rec.csv", tmp_path / "lab.csv"
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "simulate", "case2", "-o", str(rec), "--labels", str(lab),
                          "--rate", "250", "--seed", "4"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    r = read_recording(rec, 25)
    assert r.rate_hz(0) == pytest.approx(250.0) and len(r.t) == 3500
    labels = lab.read_text().splitlines()
    assert labels[0] == "t,label" and len(labels) == 3501 and "slip" in lab.read_text()
