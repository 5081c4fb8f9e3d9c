"""One documented precedence for every setting: command line, then the bridge
configuration, then the node's profile, then the defaults; ``bridge --check
--explain`` prints each resolved value with where it came from."""

from __future__ import annotations

import os
import subprocess
import sys

from tests.helpers.paths import PROFILES

PAPER = str(PROFILES / "paper-5x5.toml")


def explain(*args: str) -> dict[str, tuple[str, str]]:
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "bridge", *args, "--check", "--explain"],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    out = {}
    for line in res.stdout.splitlines()[1:]:
        key, _, rest = line.strip().partition(" = ")
        value, _, origin = rest.rpartition("  (")
        out[key] = (value, origin.rstrip(")"))
    return out


def test_command_line_over_profile_over_default():
    controller, device = os.openpty()  # --check looks for the serial device: give it one
    try:
        got = explain("-p", PAPER, "--source", f"rtu:{os.ttyname(device)}@57600", "--rate", "50",
                      "--plc", "tcp:10.0.0.5:5020")
    finally:
        os.close(controller)
        os.close(device)
    assert got["rate_hz"] == ("50.0", "command line")
    assert got["baudrate"] == ("57600", "command line")
    assert got["unit_id"][1] == f"profile {PAPER}"  # not given: the profile's [modbus.node]
    assert got["plc.host"] == ("'10.0.0.5'", "command line") and got["plc.port"] == ("5020", "command line")
    assert got["plc.offline_linger_s"] == ("0.5", "default")


def test_bridge_configuration_over_profile(tmp_path):
    cfg = tmp_path / "b.toml"
    cfg.write_text(f'[plc]\nmode = "client"\nhost = "10.1.1.1"\n\n'
                   f'[[node]]\nname = "a"\nprofile = "{PAPER}"\ninterface = "virtual"\nchannel = "x"\nnode_id = 7\n')
    got = explain("--config", str(cfg))
    assert got["node_id"] == ("7", str(cfg)) and got["base_id"] == ("512", f"profile {PAPER}")
    assert got["plc.mode"] == ("'client'", str(cfg))
    assert got["plc.port"][1] == f"profile {PAPER}"  # [plc] left it to the profile's [modbus.plc]


def test_with_no_output_given_the_plc_is_the_default_output():
    got = explain("-p", PAPER, "--source", "scene:case2")
    assert got["plc.mode"] == ("'server'", f"profile {PAPER}")
    assert not any(k.startswith("recorder.") for k in got)


def test_profile_show_marks_what_the_file_leaves_to_the_default(tmp_path):
    """``profile show``: every key as resolved, the defaults marked, and still TOML
    that loads back to the same profile."""
    import tomllib

    from eskin_industrial import load_profile

    src = (PROFILES / "paper-5x5.toml").read_text()
    path = tmp_path / "p.toml"
    path.write_text(src.replace("[detector]\n", "[detector]\nslip_confirm_updates = 2\n", 1))
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "profile", "show", str(path)],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert "slip_confirm_updates = 2" in lines  # given by the file: no mark
    assert "z = 6.0  # default" in lines  # [detector.cof_track] z is not in the file
    assert "rate_hz = 100.0" in lines and not any(ln.startswith("window_samples") and "default" in ln
                                                   for ln in lines)  # derived values are not defaults
    table = tomllib.loads(res.stdout)
    del table["derived"]
    again = tmp_path / "again.toml"
    again.write_text(res.stdout.split("\n[derived]")[0] + "\n")
    assert table["detector"]["slip_confirm_updates"] == 2
    assert load_profile(again) == load_profile(path)
