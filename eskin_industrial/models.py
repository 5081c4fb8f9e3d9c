"""The ``learned`` method's model as the package ships it: one file of package data,
``data/models/learned.npz``, read with numpy alone (no scikit-learn, no training).

The file is written by ``scripts/train-learned`` (the evaluation's training, on the
tuning seeds: ``eskin_industrial/evaluation/train.py``); the package only reads it.
It is a NumPy ``.npz`` archive of the four :class:`~.detect.learned.TreeEnsemble`
arrays plus ``meta``, a JSON text: the format version, the feature names and the
classes in the model's order (checked against :mod:`~.detect.learned`'s, so that a
model of other features is refused rather than fed the wrong vector), the training
configuration it came from and the versions that made it.  The archive is written
deterministically (fixed entry order and times): the same training gives the same
bytes, so a rebuilt file that differs from the shipped one means the model changed.

This module sits outside ``detect/`` (which does no I/O) and below every part that
builds a method by name (``methods.bind``).
"""

from __future__ import annotations

import io
import json
import zipfile
import zlib
from dataclasses import dataclass
from functools import cache
from importlib import resources
from importlib.resources.abc import Traversable
from pathlib import Path
from typing import Any

import numpy as np

from .detect.learned import CLASSES, FEATURES, TreeEnsemble
from .errors import InputFormatError

#: Bumped whenever the arrays or ``meta`` change meaning; a file of another version is refused.
FORMAT = 1
#: The arrays of the archive, each an ``.npy`` entry (and ``meta``).
ARRAYS: tuple[str, ...] = ("feature", "threshold", "table", "init")
#: Splits per tree and leaf codes per tree (depth <= 3: see ``TreeEnsemble``).
SPLITS = 7
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # the earliest time a zip entry can carry: no clock in the bytes


class ModelFileError(InputFormatError):
    """The learned method's model file is missing, unreadable or of another format;
    the message names the file."""


def shipped_model_file() -> Traversable:
    """The model file inside the installed package."""
    return resources.files(__package__) / "data" / "models" / "learned.npz"


@dataclass(frozen=True)
class StoredModel:
    """A model file's content: the model and what it says of itself."""

    model: TreeEnsemble
    trained: dict[str, Any]  #: the training configuration (``TrainConfig``'s fields)
    made_with: dict[str, str]  #: package versions of the training (numpy, scikit-learn)


def write_model(path: Path, model: TreeEnsemble, trained: dict[str, Any], made_with: dict[str, str]) -> None:
    """Write ``model`` to ``path`` (its folder made if missing), byte for byte the same
    for the same model and meta."""
    meta = {"format": FORMAT, "features": list(FEATURES), "classes": list(CLASSES), "trained": trained,
            "made_with": made_with}
    entries = {name: np.ascontiguousarray(getattr(model, name)) for name in ARRAYS}
    entries["meta"] = np.array(json.dumps(meta, sort_keys=True))
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, array in entries.items():
            npy = io.BytesIO()
            np.lib.format.write_array(npy, array, allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            archive.writestr(info, npy.getvalue(), compresslevel=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(buffer.getvalue())


def read_model(path: Path | Traversable) -> StoredModel:
    """The model stored at ``path``; a missing, unreadable or inconsistent file is a
    :class:`ModelFileError` naming it."""
    try:
        with path.open("rb") as f:
            loaded = np.load(f, allow_pickle=False)
            if not isinstance(loaded, np.lib.npyio.NpzFile):
                raise ValueError("a single array, not an .npz archive")
            with loaded as npz:
                stored = {name: npz[name] for name in npz.files}
    except FileNotFoundError:
        raise ModelFileError(f"{path}: the learned method's model file is missing (a broken install; in a "
                             "checkout, scripts/train-learned writes it)") from None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise ModelFileError(f"{path}: not a model file the learned method can read ({exc})") from None
    return _checked(path, stored)


def _checked(path: Path | Traversable, stored: dict[str, np.ndarray]) -> StoredModel:
    def bad(why: str) -> ModelFileError:
        return ModelFileError(f"{path}: not a model file the learned method can read ({why})")

    missing = [n for n in (*ARRAYS, "meta") if n not in stored]
    if missing:
        raise bad(f"no {', '.join(missing)}")
    try:
        meta = json.loads(str(stored["meta"]))
    except ValueError as exc:
        raise bad(f"meta: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else None
        raise bad(f"format {got!r}, this version reads format {FORMAT}")
    if tuple(meta.get("features", ())) != FEATURES:
        raise bad(f"its features {meta.get('features')} are not the method's {list(FEATURES)}")
    if tuple(meta.get("classes", ())) != CLASSES:
        raise bad(f"its classes {meta.get('classes')} are not the method's {list(CLASSES)}")
    feature, threshold, table, init = (stored[n] for n in ARRAYS)
    trees = len(feature)
    shapes = {"feature": (trees, SPLITS), "threshold": (trees, SPLITS), "table": (trees, 1 << SPLITS),
              "init": (len(CLASSES),)}
    for name, shape in shapes.items():
        if stored[name].shape != shape:
            raise bad(f"{name}: shape {stored[name].shape}, expected {shape}")
    if not np.issubdtype(feature.dtype, np.integer) or not all(
            np.issubdtype(a.dtype, np.floating) for a in (threshold, table, init)):
        raise bad("feature must be integers, threshold, table and init floats")
    if trees == 0 or trees % len(CLASSES):
        raise bad(f"{trees} trees: expected whole rounds of one tree per class ({len(CLASSES)})")
    if feature.min() < 0 or feature.max() >= len(FEATURES):
        raise bad(f"feature indices {feature.min()}..{feature.max()} outside 0..{len(FEATURES) - 1}")
    if not (np.isfinite(table).all() and np.isfinite(init).all() and not np.isnan(threshold).any()):
        raise bad("table and init must be finite, no threshold NaN")
    model = TreeEnsemble(feature.astype(np.int64), threshold.astype(float), table.astype(float), init.astype(float))
    return StoredModel(model, dict(meta.get("trained", {})), dict(meta.get("made_with", {})))


@cache
def default_model() -> TreeEnsemble:
    """The shipped model, read once per process."""
    return read_model(shipped_model_file()).model


__all__ = ["FORMAT", "ModelFileError", "StoredModel", "default_model", "read_model", "shipped_model_file",
           "write_model"]
