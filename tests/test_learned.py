"""The learned ceiling: trained on the tuning seeds only, scored on held-out seeds,
defined output on the edge cases, and a clear error without its optional extra."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("sklearn")

from eskin_industrial.detect import GraspState, get_method
from eskin_industrial.detect.learned import CLASSES, FEATURES, Learned
from eskin_industrial.evaluation.suite import EVALUATION_SEEDS, SUITE, TUNING_SEEDS, evaluate
from eskin_industrial.evaluation.train import TrainConfig, default_model
from tests.helpers.paths import PROFILES
from tests.helpers.scenes import grasp

RATE = 100.0


@pytest.fixture(scope="module")
def model():
    return default_model()


def run(profile, model, f, t=None):
    x, y = profile.coordinates_mm
    det = Learned(profile.detector, x, y, RATE, model=model)
    t = np.arange(len(f)) / RATE if t is None else t
    ups = det.feed(np.asarray(t, float), f)
    for u in ups:
        assert all(np.isfinite(v) for v in (u.r_coe, u.r_dw, u.f_sum, u.xc, u.yc))
        assert u.state in {0, 1, 2, 3}
    return ups


def test_trains_on_tuning_seeds_only():
    cfg = TrainConfig()
    assert cfg.seeds == TUNING_SEEDS and not set(cfg.seeds) & set(EVALUATION_SEEDS)
    with pytest.raises(ValueError, match="held out"):
        TrainConfig(seeds=(0, EVALUATION_SEEDS[0]))


def test_tabulated_trees_equal_sklearn():
    from sklearn.ensemble import HistGradientBoostingClassifier

    from eskin_industrial.evaluation.train import trees_from_sklearn

    rng = np.random.default_rng(0)
    x = rng.normal(size=(3000, len(FEATURES)))
    y = (x[:, 0] > 0.3).astype(int) + (x[:, 1] + x[:, 2] > 1.0).astype(int)
    clf = HistGradientBoostingClassifier(max_iter=10, max_depth=3, early_stopping=False, random_state=0).fit(x, y)
    m = trees_from_sklearn(clf)
    assert np.allclose(np.array([m(v) for v in x[:500]]), clf.predict_proba(x[:500]), atol=1e-12)


@pytest.mark.slow
def test_held_out_accuracy(model):
    """Two held-out seeds of the whole suite.  Measured at 10 seeds: F1 1.0, no false
    alarm (docs/evaluation.md); the bar leaves margin for one seed's chance."""
    res = evaluate({"learned": get_method("learned").stream}, scenes=SUITE, seeds=EVALUATION_SEEDS[:2])["learned"]
    s = res.score
    assert s.events == 24
    assert s.f1 >= 0.9
    assert s.false_alarms <= 1 and s.vf_as_slip == 0
    assert s.delay_percentile(50) <= 0.12
    assert res.per_scene["case1"].false_alarms == 0  # varying force alone never reads slip


@pytest.mark.slow
def test_edges_give_defined_output(paper_profile, model):
    assert run(paper_profile, model, np.zeros((0, 25))) == []
    ups = run(paper_profile, model, np.zeros((300, 25)))
    assert all(u.state == GraspState.NO_CONTACT for u in ups)
    f = grasp(600, seed=2)
    f[100] = np.nan
    f[200, 3] = np.inf
    f[300:320] = 0.0  # contact lost and found again
    ups = run(paper_profile, model, f)
    assert not any(u.state == GraspState.SLIP for u in ups)
    # every value NaN: replaced by 0, so no contact, never slip
    assert all(u.state == GraspState.NO_CONTACT for u in run(paper_profile, model, np.full((200, 25), np.nan)))


@pytest.mark.slow
def test_still_grasp_and_warmup(paper_profile, model):
    ups = run(paper_profile, model, grasp(2000, seed=4))
    assert not ups[0].valid  # warm-up: "I don't know", never slip
    assert all(u.valid for u in ups[50:])
    assert not any(u.state == GraspState.SLIP for u in ups)


def test_classes_and_features_are_named():
    assert CLASSES == ("stable", "variable_force", "slip")
    assert len(FEATURES) == len(set(FEATURES))


def test_without_scikit_learn_the_cli_names_the_extra(tmp_path):
    # a site directory whose sklearn cannot be imported stands in for a missing extra
    (tmp_path / "sklearn.py").write_text("raise ImportError('no scikit-learn here')\n")
    code = (f"import sys; sys.path.insert(0, {str(tmp_path)!r}); from eskin_industrial.cli import main; "
            "main(['evaluate', '-m', 'learned', '-s', 'case2', '--seeds', '1000'])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 4  # every missing extra: one format, one exit code (tests/test_cli_conventions.py)
    assert out.stderr.strip().splitlines() == [
        "eskin-bus: error: the learned method needs scikit-learn: pip install 'eskin-industrial[learn]'"]


def test_nothing_imports_sklearn_at_import_time():
    code = "import sys, eskin_industrial.cli, eskin_industrial.evaluation.charts; print('sklearn' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_every_path_that_builds_by_name_hands_the_default_model(paper_profile, model, tmp_path):
    from eskin_industrial.calibration import Calibrator
    from eskin_industrial.frames import RawScan
    from eskin_industrial.pipeline import Pipeline
    from eskin_industrial.recording import read_updates, write_recording

    f = grasp(600, seed=3)
    f[:100] = 0.0
    direct = run(paper_profile, model, f)
    # the bridge's path
    cal = Calibrator.from_section(paper_profile.calibration, 25)
    pipe = Pipeline(paper_profile, method="learned")
    raw = cal.to_raw(f)
    live = [u for k in range(600) for u in pipe.push(RawScan(seq=k, t=k / RATE, raw=raw[k]))]
    assert [u.state for u in live] == [u.state for u in direct]
    np.testing.assert_allclose([u.score_a for u in live], [u.score_a for u in direct], atol=1e-6)
    # the CLI's detect command
    path, out = tmp_path / "rec.csv", tmp_path / "out.csv"
    write_recording(path, np.arange(600) / RATE, f)
    res = subprocess.run([sys.executable, "-m", "eskin_industrial", "detect", "-p", str(PROFILES / "paper-5x5.toml"),
                          "--method", "learned", str(path), "-o", str(out)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert read_updates(out)["state"].tolist() == [GraspState(u.state).label for u in direct]


def test_the_features_ignore_the_rivals_profile_sections(paper_profile, model):
    # the model was trained on the rivals' scores at their defaults: a profile that
    # retunes the rivals must not change what the learned method sees
    from dataclasses import replace

    from eskin_industrial.detect.settings import ForceRateSettings, HfEnergySettings

    f = grasp(600, seed=5)
    f[:100] = 0.0
    f[300:380] = np.roll(f[300:380], 1, axis=1)
    retuned = replace(paper_profile, detector=replace(
        paper_profile.detector, force_rate=ForceRateSettings(lag_s=0.03), hf_energy=HfEnergySettings(smooth_s=0.2)))
    a, b = run(paper_profile, model, f), run(retuned, model, f)
    assert [u.score_a for u in a] == [u.score_a for u in b] and [u.state for u in a] == [u.state for u in b]
