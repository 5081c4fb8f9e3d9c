"""Training the ``learned`` method's model (scikit-learn, the optional extra ``learn``).

Only the tuning seeds of the built-in scenes are rendered for training; the held-out
evaluation seeds never are (``TrainConfig`` refuses them).  The fitted estimator is
turned into the numpy-only forms of ``detect.learned`` so that the detector neither
imports scikit-learn nor pays its per-call overhead.

Nothing trains at run time: ``scripts/train-learned`` calls :func:`write_trained` to
write the package's model file (``eskin_industrial/models.py`` reads it), and
``scripts/train-learned --check`` trains again and compares (the same arrays, or on
another CPU the same classes on all but a rounding's share of the training rows).  A training is about
16 s of CPU, almost all of it rendering the scenes and running the detector over them.
"""

from __future__ import annotations

import functools
from dataclasses import asdict, dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from ..detect.learned import CLASSES, FEATURES, Learned, TreeEnsemble
from ..detect.settings import DetectorSettings
from ..errors import MissingExtra
from ..models import StoredModel, read_model, write_model
from ..scenes import load_scene, render
from .corpus import EVALUATION_SEEDS, SUITE, TUNING_SEEDS, coordinates

MISSING = MissingExtra.of("training the learned method", "scikit-learn", "learn")


@dataclass(frozen=True)
class TrainConfig:
    scenes: tuple[str, ...] = SUITE
    seeds: tuple[int, ...] = TUNING_SEEDS
    rate_hz: float = 100.0
    trees: int = 40  #: boosting rounds (one tree of depth <= 3 per class each)
    random_state: int = 0

    def __post_init__(self) -> None:
        held_out = set(self.seeds) & set(EVALUATION_SEEDS)
        if held_out:
            raise ValueError(f"seeds: the evaluation seeds are held out, never trained on (got {sorted(held_out)})")


def require_sklearn() -> None:
    """Raise the one-line error naming the extra when scikit-learn is missing."""
    try:
        import sklearn  # noqa: F401
    except ImportError:
        raise MISSING from None


class _Recorder(Learned):
    """The detector itself, recording each feature vector it would classify (and when)."""

    def __init__(self, *args: Any) -> None:
        self.rows: list[np.ndarray] = []
        self.times: list[float] = []
        uniform = np.full(len(CLASSES), 1.0 / len(CLASSES))

        def model(x: np.ndarray) -> np.ndarray:
            self.rows.append(x.copy())
            return uniform

        super().__init__(*args, model=model)

    def score(self, t: float, f: np.ndarray, s: float, xc: float, yc: float) -> tuple[float, float, bool, bool]:
        n = len(self.rows)
        out = super().score(t, f, s, xc, yc)
        if len(self.rows) > n:
            self.times.append(t)
        return out


@functools.lru_cache(maxsize=1)
def dataset(config: TrainConfig = TrainConfig(), settings: DetectorSettings = DetectorSettings()
            ) -> tuple[np.ndarray, np.ndarray]:
    """Feature rows the detector classifies on the config's scenes and seeds, and the
    class index of each (rows labelled ``transition`` or ``no_contact`` are left out:
    the first is don't-care, the second the detector decides without the model).
    The last one is kept, read-only: a check after a training needs the same rows,
    about 11 s of CPU to make again."""
    xs, ys = [], []
    for scene in config.scenes:
        spec = load_scene(scene)
        for seed in config.seeds:
            rec = render(spec, config.rate_hz, seed)
            det = _Recorder(settings, *coordinates(rec), rec.rate_hz)
            det.feed(rec.t, rec.forces)
            if not det.rows:
                continue
            idx = np.searchsorted(rec.t, np.asarray(det.times), side="right") - 1
            labels = rec.labels[np.clip(idx, 0, len(rec.t) - 1)]
            keep = np.isin(labels, CLASSES)
            xs.append(np.asarray(det.rows)[keep])
            ys.append(np.array([CLASSES.index(v) for v in labels[keep]], np.int64))
    x, y = np.concatenate(xs), np.concatenate(ys)
    x.setflags(write=False)
    y.setflags(write=False)
    return x, y


def fit(config: TrainConfig = TrainConfig()) -> TreeEnsemble:
    """Gradient-boosted trees (scikit-learn's histogram boosting) on :func:`dataset`."""
    require_sklearn()
    from sklearn.ensemble import HistGradientBoostingClassifier
    from threadpoolctl import threadpool_limits

    x, y = dataset(config)
    clf = HistGradientBoostingClassifier(max_iter=config.trees, max_depth=3, learning_rate=0.2,
                                         early_stopping=False, random_state=config.random_state)
    # one thread: on a busy machine OpenMP threads made the fit six times slower
    with threadpool_limits(limits=1):
        clf.fit(x, y)
    return trees_from_sklearn(clf)


def trees_from_sklearn(clf: Any) -> TreeEnsemble:
    """Tabulate a fitted multiclass HistGradientBoostingClassifier of depth <= 3 (from
    its predictors' node arrays; ``tests/detect/test_learned.py`` checks the result against
    ``predict_proba``)."""
    trees = [nodes for it in clf._predictors for nodes in (p.nodes for p in it)]
    splits = 7
    feature = np.zeros((len(trees), splits), np.int64)
    threshold = np.full((len(trees), splits), np.inf)
    table = np.zeros((len(trees), 1 << splits))
    for i, nodes in enumerate(trees):
        inner = [j for j in range(len(nodes)) if not nodes["is_leaf"][j]]
        if len(inner) > splits:
            raise ValueError(f"tree {i}: {len(inner)} splits, at most {splits} (depth 3) can be tabulated")
        slot = {j: k for k, j in enumerate(inner)}
        for k, j in enumerate(inner):
            feature[i, k] = nodes["feature_idx"][j]
            threshold[i, k] = nodes["num_threshold"][j]
        for code in range(1 << splits):
            j = 0
            while not nodes["is_leaf"][j]:
                j = nodes["right"][j] if code >> slot[j] & 1 else nodes["left"][j]
            table[i, code] = nodes["value"][j]
    init = np.asarray(clf._baseline_prediction, float).ravel()
    return TreeEnsemble(feature, threshold, table, init)


def config_record(config: TrainConfig) -> dict[str, Any]:
    """``config`` as the model file records it (JSON: lists for tuples)."""
    return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(config).items()}


def write_trained(path: Path, config: TrainConfig = TrainConfig()) -> StoredModel:
    """Train on ``config`` and write the model file to ``path`` (the same bytes for the
    same config, package versions and CPU: :data:`SAME_TRAINING_SHARE`); returns what
    was written."""
    model = fit(config)
    made_with = {name: metadata.version(name) for name in ("numpy", "scikit-learn")}
    write_model(path, model, config_record(config), made_with)
    return read_model(path)


#: The share of the training rows two models may class otherwise and still be the same
#: training.  Trained again on another CPU, numpy's vector paths may round a feature's
#: last bits otherwise, and a split between two near values moves (``scripts/train-learned
#: --check`` says how far: the shipped file, trained on an Intel Xeon, against the same
#: training on an AMD EPYC, 1 row of 168,720).  A file the training has left behind (a
#: feature or a scene changed) differs on far more.
SAME_TRAINING_SHARE = 1e-4


@dataclass(frozen=True)
class Check:
    """The shipped model against a training made again."""

    stale: list[str]  #: why the shipped file is not what the training gives; empty: it is
    rounding: str = ""  #: when the arrays differ by another CPU's rounding alone: how far


def check(shipped: StoredModel, trained: StoredModel, config: TrainConfig = TrainConfig()) -> Check:
    """The same arrays, or the same training in another rounding (the same class on all
    but :data:`SAME_TRAINING_SHARE` of the training rows), or stale and why."""
    found = differences(shipped, trained)
    if not found or shipped.trained != trained.trained:
        return Check(found)
    x, _ = dataset(config)
    share = float(np.mean(shipped.model.classes(x) != trained.model.classes(x)))
    how = f"{share:.4%} of the {len(x)} training rows classed otherwise"
    if share > SAME_TRAINING_SHARE:
        return Check([*found, how])
    a, b = shipped.model.feature, trained.model.feature
    moved = f", {int(np.sum(a != b))} of {a.size} splits reading another feature" if a.shape == b.shape else ""
    return Check([], f"{'; '.join(found)}{moved}, {how}")


def differences(shipped: StoredModel, trained: StoredModel) -> list[str]:
    """What differs between two stored models (the versions that made them aside):
    nothing when the shipped file is what the training gives."""
    out = []
    if shipped.trained != trained.trained:
        out.append(f"trained on {shipped.trained}, the training is {trained.trained}")
    for name in ("feature", "threshold", "table", "init"):
        a, b = getattr(shipped.model, name), getattr(trained.model, name)
        if a.shape != b.shape or not np.array_equal(a, b):
            out.append(f"{name} differs")
    return out


__all__ = ["FEATURES", "SAME_TRAINING_SHARE", "Check", "TrainConfig", "check", "config_record", "dataset",
           "differences", "fit", "require_sklearn", "trees_from_sklearn", "write_trained"]
