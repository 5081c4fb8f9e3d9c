from __future__ import annotations

import subprocess
import sys

import pytest

from tests.helpers.paths import PROFILES, ROOT


def test_plot_writes_a_png_of_a_recording(tmp_path):
    out = tmp_path / "case2.png"
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plot", "-p", str(PROFILES / "paper-5x5.toml"),
                          str(ROOT / "examples" / "case2.csv"), "--labels", str(ROOT / "examples" / "case2-labels.csv"),
                          "--method", "cof-track", "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
    assert "slip" in res.stderr and "slip 0" not in res.stderr  # the example's slide is detected


def test_plot_refuses_a_bad_recording_in_one_line(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,f0\n0,1\n")
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plot", "-p", str(PROFILES / "paper-5x5.toml"),
                          str(bad), "-o", str(tmp_path / "x.png")], capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "1 taxel columns" in res.stderr


@pytest.mark.slow
def test_plot_draws_a_can_log_through_the_receivers_decoding(tmp_path):
    import numpy as np

    from eskin_industrial import Calibrator, load_profile
    from eskin_industrial.bus.can.layout import CanLayout
    from eskin_industrial.recording import read_recording

    prof = load_profile(PROFILES / "paper-5x5.toml")
    rec = read_recording(ROOT / "examples" / "case2.csv", prof.taxels)
    raw = np.rint(Calibrator.from_section(prof.calibration, prof.taxels).to_raw(rec.values))
    layout = CanLayout.from_profile(prof, fd=False)
    lines = [f"({100 + k / 100 + s * 1e-4:.6f}) can0 {can_id:03X}#{data.hex().upper()}"
             for k, scan in enumerate(layout.encode(np.arange(len(raw)), raw)) for s, (can_id, data) in enumerate(scan)]
    log = tmp_path / "case2.log"
    log.write_text("\n".join(lines) + "\n")
    out = tmp_path / "case2-log.png"
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plot", "-p", str(PROFILES / "paper-5x5.toml"),
                          "--can-log", str(log), "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"{len(raw)} updates" in res.stderr and "slip 0" not in res.stderr
    empty = tmp_path / "other.log"
    empty.write_text("(1.000000) can0 7FF#00\n")
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plot", "-p", str(PROFILES / "paper-5x5.toml"),
                          "--can-log", str(empty), "-o", str(tmp_path / "x.png")], capture_output=True, text=True,
                         timeout=60)
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and "no complete scan" in res.stderr


def test_the_plot_has_a_lane_for_the_states_and_one_for_the_truth_with_legends_and_units():
    """The figure's parts, as matplotlib holds them: labelled axes with units, the
    detected states and the truth each a lane of bands with its own legend, every
    legend right of the data, and a colour per state that no line shares."""
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import to_hex

    from eskin_industrial import load_profile
    from eskin_industrial.cli.plot_cmd import plot_data
    from eskin_industrial.cli.plot_figure import SCORE_COLOURS, STATE_COLOURS, state_figure
    from eskin_industrial.offline import detect_recording

    prof = load_profile(PROFILES / "paper-5x5.toml")
    found = detect_recording(prof, ROOT / "examples" / "case2.csv", method="cof-track")
    fig = state_figure(plt, plot_data(prof, found, str(ROOT / "examples" / "case2-labels.csv")))
    try:
        force, centre, scores, detected, truth = fig.axes
        assert force.get_ylabel() == "total force (N)" and truth.get_xlabel() == "time (s)"
        assert centre.get_ylabel() == "centre of\nforce (mm)"
        assert [t.get_text() for t in centre.get_legend().get_texts()] == ["x of the centre", "y of the centre"]
        # the example's slide moves the centre: millimetres, not a flat line (and none without contact)
        x = centre.get_lines()[0].get_ydata()
        assert np.isnan(x[0]) and 1.0 < np.nanmax(x) - np.nanmin(x) < 50.0
        assert "dimensionless" in scores.get_ylabel()
        assert [t.get_text() for t in scores.get_legend().get_texts()] == ["onset_score", "slow_score", "threshold"]
        lanes = {}
        for ax, name in ((detected, "detected"), (truth, "truth")):
            assert ax.get_ylabel() == name and ax.get_legend().get_title().get_text() == name
            lanes[name] = {t.get_text() for t in ax.get_legend().get_texts()}
            # bands, not lines: one collection per state drawn, in that state's colour
            colours = {to_hex(c.get_facecolor()[0]) for c in ax.collections}
            assert colours <= {to_hex(c) for c in STATE_COLOURS.values()} and len(colours) == len(lanes[name])
        assert {"stable", "slip"} <= lanes["detected"] and {"stable", "slip", "transition"} <= lanes["truth"]
        fig.canvas.draw()
        for ax in (centre, scores, detected, truth):  # each legend clear of its lane's data: right of the axes
            assert ax.get_legend().get_window_extent().x0 >= ax.get_window_extent().x1
        assert len({to_hex(c) for c in (*STATE_COLOURS.values(), *SCORE_COLOURS)}) == len(STATE_COLOURS) + 2
    finally:
        plt.close(fig)


def test_plot_refuses_labels_without_their_columns_in_one_line(tmp_path):
    labels = tmp_path / "labels.csv"
    labels.write_text("time,state\n0,stable\n")
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "plot", "-p", "paper-5x5",
                          str(ROOT / "examples" / "case2.csv"), "--labels", str(labels), "-o", str(tmp_path / "x.png")],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "expected the columns t,label" in res.stderr and not (tmp_path / "x.png").exists()
