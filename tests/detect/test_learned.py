"""The learned ceiling: trained on the tuning seeds only, scored on held-out seeds,
defined output on the edge cases; its model shipped as package data, read with numpy
alone (no training at run time), and scikit-learn needed only to train it."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from eskin_industrial.detect import GraspState, get_method
from eskin_industrial.detect.learned import CLASSES, FEATURES, Learned
from eskin_industrial.evaluation.suite import EVALUATION_SEEDS, SUITE, TUNING_SEEDS, evaluate
from eskin_industrial.evaluation.train import TrainConfig, config_record
from eskin_industrial.models import default_model, read_model, shipped_model_file
from tests.helpers.paths import PROFILES, ROOT
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
    pytest.importorskip("sklearn")
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


def _without_sklearn(tmp_path, code: str) -> subprocess.CompletedProcess[str]:
    # a site directory whose sklearn cannot be imported stands in for a missing extra
    (tmp_path / "sklearn.py").write_text("raise ImportError('no scikit-learn here')\n")
    return subprocess.run([sys.executable, "-c", f"import sys; sys.path.insert(0, {str(tmp_path)!r}); {code}"],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.slow
def test_without_scikit_learn_the_method_runs_and_only_training_names_the_extra(tmp_path):
    rec = tmp_path / "case2.csv"
    subprocess.run([sys.executable, "-m", "eskin_industrial", "simulate", "case2", "-o", str(rec)], check=True,
                   capture_output=True, timeout=60)
    run = "from eskin_industrial.cli import main; main({})"
    detect = _without_sklearn(tmp_path, run.format(["detect", "-p", "paper-5x5", "--method", "learned", "--changes",
                                                    str(rec)]))
    assert detect.returncode == 0 and "slip" in detect.stdout, detect.stderr
    evaluated = _without_sklearn(tmp_path, run.format(["evaluate", "-m", "learned", "-s", "case2", "--seeds", "1000"]))
    assert evaluated.returncode == 0 and "learned" in evaluated.stdout, evaluated.stderr
    # training is what needs it: one line, exit 4 as every missing extra (tests/cli/test_cli_conventions.py)
    script = str(ROOT / "scripts" / "train-learned")
    train = _without_sklearn(tmp_path, f"import runpy; sys.argv = [{script!r}, '--check']; "
                                       f"runpy.run_path({script!r}, run_name='__main__')")
    assert train.returncode == 4, train.stderr
    assert train.stderr.strip().splitlines() == [
        "train-learned: error: training the learned method needs scikit-learn: pip install 'eskin-industrial[learn]'"]


def test_nothing_imports_sklearn_at_import_time():
    code = "import sys, eskin_industrial.cli, eskin_industrial.evaluation.charts; print('sklearn' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.slow
def test_a_learned_pipeline_loads_neither_the_evaluation_nor_scikit_learn():
    # the bridge's path, built and run: the model comes from package data (the layer
    # contract in pyproject.toml forbids the import; this is the same, at run time)
    code = ("import sys, numpy as np; from eskin_industrial.pipeline import Pipeline; "
            "from eskin_industrial.profile import load_profile; from eskin_industrial.frames import RawScan; "
            f"pipe = Pipeline(load_profile({str(PROFILES / 'paper-5x5.toml')!r}), method='learned'); "
            "[pipe.push(RawScan(seq=k, t=k / 100, raw=np.full(25, 5e4))) for k in range(200)]; "
            "print(pipe.last_update.valid, sorted({m.split('.')[1] for m in sys.modules "
            "if m.startswith('eskin_industrial.')} & {'evaluation', 'scenes'}), 'sklearn' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.split() == ["True", "[]", "False"], out.stderr


def test_the_shipped_model_says_what_it_was_trained_on(model):
    stored = read_model(shipped_model_file())
    assert stored.trained == config_record(TrainConfig())  # the evaluation's default training
    assert set(stored.trained["seeds"]) <= set(TUNING_SEEDS) and not set(stored.trained["seeds"]) & set(
        EVALUATION_SEEDS)
    assert set(stored.made_with) == {"numpy", "scikit-learn"}
    assert len(model.table) == 3 * TrainConfig().trees  # one tree per class and round
    p = model(np.zeros(len(FEATURES)))
    assert p.shape == (3,) and abs(p.sum() - 1.0) < 1e-12


def test_the_model_file_is_written_deterministically(model, tmp_path):
    from eskin_industrial.models import write_model

    a, b = tmp_path / "a.npz", tmp_path / "b" / "b.npz"
    stored = read_model(shipped_model_file())
    write_model(a, model, stored.trained, stored.made_with)
    write_model(b, read_model(a).model, stored.trained, stored.made_with)
    assert a.read_bytes() == b.read_bytes()
    again = read_model(b)
    for name in ("feature", "threshold", "table", "init"):
        assert np.array_equal(getattr(again.model, name), getattr(model, name))


def test_a_model_file_that_is_not_the_training_s_is_told_apart(model):
    from dataclasses import replace

    from eskin_industrial.evaluation.train import differences

    shipped = read_model(shipped_model_file())
    assert differences(shipped, shipped) == []
    table = model.table.copy()
    table[5, 17] += 1e-9  # one leaf, off in its last digits
    other = replace(shipped, model=type(model)(model.feature, model.threshold, table, model.init))
    assert differences(shipped, other) == ["table differs"]
    fewer = replace(shipped, trained={**shipped.trained, "seeds": [0, 1]})
    assert differences(shipped, fewer) == [f"trained on {shipped.trained}, the training is {fewer.trained}"]


def test_the_classes_of_many_rows_are_the_model_s_row_by_row(model):
    """``classes`` (the check's batch form) gives each row the class the detector's
    own call gives it, over rows that fall on both sides of the splits."""
    rng = np.random.default_rng(5)
    x = np.zeros((500, len(FEATURES)))
    for j in range(len(FEATURES)):
        cuts = model.threshold[(model.feature == j) & np.isfinite(model.threshold)]
        x[:, j] = rng.choice(cuts, len(x)) + rng.normal(0, cuts.std() + 1e-3, len(x)) if len(cuts) else rng.normal(size=len(x))
    row_by_row = np.array([int(np.argmax(model(r))) for r in x])
    assert len(set(row_by_row)) == len(CLASSES)  # every class among them
    assert np.array_equal(model.classes(x, chunk=64), row_by_row)


@pytest.mark.slow
def test_the_shipped_model_is_what_the_training_gives(paper_profile, model, tmp_path):
    """Trains afresh (about 16 s of CPU): the same arrays on the CPU that trained the
    file, and on another the same training in another rounding: the same class on all
    but ``SAME_TRAINING_SHARE`` of the training rows; either way the same verdicts
    (``scripts/train-learned --check`` is the same comparison)."""
    pytest.importorskip("sklearn")
    from eskin_industrial.evaluation.train import check, write_trained
    from eskin_industrial.scenes import render

    fresh = write_trained(tmp_path / "learned.npz")
    assert check(read_model(shipped_model_file()), fresh).stale == []
    rec = render("case2", RATE, EVALUATION_SEEDS[0])
    x, y = paper_profile.coordinates_mm
    shipped, trained = (Learned(paper_profile.detector, x, y, RATE, model=m).feed(rec.t, rec.forces)
                        for m in (model, fresh.model))
    assert [u.state for u in shipped] == [u.state for u in trained]
    assert GraspState.SLIP in {u.state for u in shipped}


def _broken_files(tmp_path, model):
    from eskin_industrial.models import write_model

    good = tmp_path / "good.npz"
    write_model(good, model, {}, {})
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:3000])
    text = tmp_path / "text.npz"
    text.write_text("feature,threshold\n1,2\n")
    arrays = {n: getattr(model, n) for n in ("feature", "threshold", "table", "init")}
    meta = {"format": 1, "features": list(FEATURES), "classes": list(CLASSES)}
    fewer = tmp_path / "fewer.npz"  # a model of other features
    np.savez(fewer, **arrays, meta=np.array(json.dumps({**meta, "features": list(FEATURES[:-1])})))
    newer = tmp_path / "newer.npz"  # a format this version does not know
    np.savez(newer, **arrays, meta=np.array(json.dumps({**meta, "format": 2})))
    short = tmp_path / "short.npz"  # one tree short of whole rounds
    np.savez(short, **{**arrays, "feature": model.feature[:-1]}, meta=np.array(json.dumps(meta)))
    return {"missing": tmp_path / "none.npz", "truncated": truncated, "text": text, "fewer": fewer, "newer": newer,
            "short": short}


def test_a_missing_or_damaged_model_file_is_one_line_naming_it(model, tmp_path):
    from eskin_industrial.models import ModelFileError

    said = {}
    for kind, path in _broken_files(tmp_path, model).items():
        with pytest.raises(ModelFileError) as err:
            read_model(path)
        said[kind] = str(err.value)
        assert said[kind].startswith(f"{path}: ") and "\n" not in said[kind], (kind, said[kind])
    assert "model file is missing" in said["missing"]
    assert "features" in said["fewer"] and "format 2" in said["newer"]
    assert "shape (120, 7), expected (119, 7)" in said["short"]


def test_a_damaged_shipped_model_stops_the_command_with_one_line(model, tmp_path, monkeypatch):
    from click.testing import CliRunner

    from eskin_industrial import models
    from eskin_industrial.cli import main
    from eskin_industrial.recording import write_recording

    rec = tmp_path / "rec.csv"
    write_recording(rec, np.arange(300) / RATE, grasp(300, seed=1))
    bad = _broken_files(tmp_path, model)["truncated"]
    monkeypatch.setattr(models, "shipped_model_file", lambda: bad)  # the package's file, as if damaged
    models.default_model.cache_clear()
    try:
        res = CliRunner().invoke(main, ["detect", "-p", "paper-5x5", "--method", "learned", str(rec)])
    finally:
        models.default_model.cache_clear()
    assert res.exit_code == 2, res.output
    (line,) = res.output.strip().splitlines()
    assert line.startswith(f"eskin-bus: error: {bad}: not a model file the learned method can read ("), line


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
