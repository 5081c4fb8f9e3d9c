from __future__ import annotations

import re
import subprocess
import sys
import tomllib

import pytest

from eskin_industrial import ProfileError, load_profile, parse_profile
from eskin_industrial.cli.toml_out import dumps
from eskin_industrial.profile import Profile
from eskin_industrial.schema import build
from tests.helpers.paths import PROFILES

BASE = """
[sensor]
name = "t"
[layout]
rows = 4
cols = 5
pitch_mm = 5.0
[calibration]
raw_unit = "ohm"
zero = 1400.0
per_newton = -181.0
"""


def refused(text: str) -> str:
    with pytest.raises(ProfileError) as info:
        parse_profile(text, "x.toml")
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith("x.toml: ")
    return msg


def test_shipped_profiles_load(paper_profile, hand_profile):
    assert paper_profile.taxels == 25 and hand_profile.taxels == 20
    assert hand_profile.layout.row_names == ("index", "middle", "ring", "little")
    assert paper_profile.detector.window_s == 0.4 and paper_profile.detector.wavelet == "db2"
    x, y = hand_profile.coordinates_mm
    assert x[:5].tolist() == [0, 5, 10, 15, 20] and y[5] == 20.0  # row-major, finger pitch


def test_every_profile_in_the_repo_is_valid():
    files = sorted(PROFILES.glob("*.toml"))
    assert {f.name for f in files} >= {"paper-5x5.toml", "hand-4x5.toml"}
    for f in files:
        load_profile(f)


def test_unknown_key_names_the_nearest_valid_one():
    msg = refused(BASE + "[detector]\nwindw_s = 0.4\n")
    assert "[detector] windw_s" in msg and "window_s" in msg


def test_wrong_type_is_not_converted():
    assert "expected a number, got '0.4'" in refused(BASE + '[detector]\nwindow_s = "0.4"\n')
    assert "expected an integer" in refused(BASE.replace("rows = 4", "rows = 4.0"))


def test_missing_section():
    text = BASE.replace("[layout]\nrows = 4\ncols = 5\npitch_mm = 5.0\n", "")
    assert "[layout]: missing section" in refused(text)


def test_calibration_entries_must_match_the_layout():
    text = BASE.replace("per_newton = -181.0", "per_newton = [" + ", ".join(["-181.0"] * 19) + "]")
    msg = refused(text)
    assert "[calibration] per_newton" in msg and "20" in msg and "19" in msg


def test_negative_window():
    assert "[detector] window_s: expected a value in [0.0001, 600], got -0.4" in refused(BASE + "[detector]\nwindow_s = -0.4\n")


def test_window_must_be_whole_hops_and_hold_the_filter():
    assert "whole multiple of hop_s" in refused(BASE + "[detector]\nwindow_s = 0.45\n")
    msg = refused(BASE + '[detector]\nwindow_s = 0.02\nhop_s = 0.01\nwavelet = "db4"\n')
    assert "filter length" in msg


def test_bad_choices_and_overrides():
    assert "did you mean 'ohm'" in refused(BASE.replace('"ohm"', '"ohms"'))
    assert "expected a discrete PyWavelets wavelet" in refused(BASE + '[detector]\nwavelet = "db99"\n')
    assert "[detector] method" in refused(BASE + '[detector]\nmethod = "magic"\n')
    assert "below 20" in refused(BASE + '[calibration.overrides]\n"25" = { zero = 1.0 }\n')
    assert "per_newton" in refused(BASE.replace("per_newton = -181.0", "per_newton = 0.0"))


def test_not_toml_and_missing_file(tmp_path):
    assert "not valid TOML" in refused("[sensor\nname=")
    with pytest.raises(ProfileError, match="cannot read profile"):
        load_profile(tmp_path / "absent.toml")


def test_show_output_reloads_to_the_same_profile(paper_profile):
    table = paper_profile.to_table()
    again = build(Profile, tomllib.loads(dumps(table)))
    assert again == paper_profile


def run_cli(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eskin_industrial", *args], input=stdin,
                          capture_output=True, text=True, timeout=60)


def test_cli_check_and_show(tmp_path):
    ok = run_cli("profile", "check", str(PROFILES / "paper-5x5.toml"))
    assert ok.returncode == 0 and "ok (paper-5x5, 5x5 taxels" in ok.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text(BASE + "[detector]\nhop_s = -1.0\n")
    res = run_cli("profile", "check", str(bad))
    assert res.returncode == 2
    assert re.fullmatch(r"eskin-bus: error: .*bad\.toml: \[detector\] hop_s: expected a value in \[0\.0001, 600\], got -1\.0\n", res.stderr)
    shown = run_cli("profile", "show", str(PROFILES / "hand-4x5.toml"))
    assert shown.returncode == 0
    table = tomllib.loads(shown.stdout)
    assert table["derived"]["window_samples"] == 40 and table["layout"]["rows"] == 4


def test_check_warns_when_raw_values_do_not_fit_the_can_bits(tmp_path):
    path = tmp_path / "wide.toml"
    path.write_text(BASE.replace("per_newton = -181.0", "per_newton = -181.0\nvalid_max = 20000.0"))
    res = run_cli("profile", "check", str(path))
    assert res.returncode == 0 and "ok" in res.stdout
    assert "warning" in res.stderr and "[can] taxel_bits" in res.stderr and res.stderr.count("\n") == 1


@pytest.mark.parametrize("section,key,near", [
    ("force_rate", "threshold", "threshold_per_s"),
    ("cof_velocity", "threshold_mm", "threshold_mm_s"),
    ("hf_energy", "baseline", "baseline_s"),
    ("learned", "slip_prob", "slip_p"),
])
def test_an_unknown_key_in_a_method_section_is_refused(section, key, near):
    msg = refused(BASE + f"[detector.{section}]\n{key} = 2.0\n")
    assert f"[detector] {section}.{key}: unknown key" in msg and repr(near) in msg


def test_method_sections_are_typed_and_checked():
    assert "expected true or false" in refused(BASE + "[detector.hf_energy]\ntotal = 1\n")
    assert "[detector] force_rate.lag_s: expected a value in [0.0001, 600], got 0.0" in refused(BASE + "[detector.force_rate]\nlag_s = 0.0\n")
    prof = parse_profile(BASE + "[detector.force_rate]\nthreshold_per_s = 2.5\n[detector.learned]\nconfirm_hops = 2\n")
    assert prof.detector.force_rate.threshold_per_s == 2.5 and prof.detector.force_rate.lag_s == 0.1
    assert prof.detector.learned.confirm_hops == 2
