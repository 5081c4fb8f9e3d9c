"""Recording and result files: CSV in, CSV out, with one-line errors naming the line.

A recording has the header ``t,f0,...,f{n-1}`` (seconds, then forces in newtons in
the profile's row-major taxel order) or ``t,raw0,...,raw{n-1}`` (the node's raw
unit, calibrated through the profile).  Cells may be ``nan``/``inf`` (the detector
flags and replaces them); anything else that is not a number is an error.
"""

from __future__ import annotations

import contextlib
import csv
import io
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Literal

import numpy as np

from .detect.state import LABELS
from .detect.updates import COLUMNS, Update, UpdateTable
from .errors import InputFormatError
from .progress import NO_PROGRESS, Progress

Unit = Literal["newton", "raw"]


@dataclass(frozen=True)
class Recording:
    t: np.ndarray  #: (K,) seconds
    values: np.ndarray  #: (K, n) newtons or raw units, see ``unit``
    unit: Unit
    name: str  #: where it came from, for messages

    @property
    def taxels(self) -> int:
        return self.values.shape[1]

    def rate_hz(self, default: float) -> float:
        """The sample rate the timestamps show (median positive step), else ``default``."""
        steps = np.diff(self.t[: 100_001])
        steps = steps[np.isfinite(steps) & (steps > 0)]
        return float(1.0 / np.median(steps)) if steps.size else default


def _read_text(source: str | Path) -> tuple[str, str]:
    if str(source) == "-":
        return sys.stdin.read(), "<stdin>"
    path = Path(source)
    try:
        return path.read_text(encoding="utf-8"), str(path)
    except UnicodeDecodeError:
        raise InputFormatError(f"{path}: not a text (UTF-8) CSV file") from None
    except OSError as exc:
        raise InputFormatError(f"{path}: cannot read: {exc.strerror or exc}") from None


def parse_header(header: str, name: str) -> tuple[Unit, int]:
    cells = [c.strip() for c in header.split(",")]
    if not cells or cells[0] != "t":
        raise InputFormatError(f"{name}: line 1: expected a header starting with 't', got {header[:60]!r}")
    rest = cells[1:]
    if not rest:
        raise InputFormatError(f"{name}: line 1: expected taxel columns after 't' (f0, f1, ... or raw0, raw1, ...)")
    prefix = "raw" if rest[0].startswith("raw") else "f"
    for i, cell in enumerate(rest):
        if cell != f"{prefix}{i}":
            raise InputFormatError(f"{name}: line 1, column {i + 2}: expected '{prefix}{i}', got {cell!r}")
    return ("raw" if prefix == "raw" else "newton"), len(rest)


def read_recording(source: str | Path, taxels: int | None = None, progress: Progress = NO_PROGRESS) -> Recording:
    """Read a recording CSV; ``taxels`` (from the profile) is checked against the header;
    ``progress``: a stage over the file's characters."""
    text, name = _read_text(source)
    if not text.strip():
        raise InputFormatError(f"{name}: empty file (expected a header 't,f0,...' and data rows)")
    header, _, body = text.partition("\n")
    unit, n = parse_header(header.strip().lstrip("\ufeff"), name)
    if taxels is not None and n != taxels:
        raise InputFormatError(f"{name}: line 1: {n} taxel columns, but the profile has {taxels} taxels")
    if not body.strip():
        raise InputFormatError(f"{name}: no data rows after the header")
    data = _parse_rows(body, n + 1, name, progress)
    return Recording(data[:, 0].copy(), data[:, 1:].copy(), unit, name)


#: Rows are parsed and written in pieces of about this many characters and rows, so
#: that a large file can show its progress; each row is read and written alone, so the
#: pieces give what the whole does, byte for byte.
_PIECE_CHARS = 4 << 20
_PIECE_ROWS = 20_000


def _parse_rows(body: str, columns: int, name: str, progress: Progress) -> np.ndarray:
    progress.stage(f"reading {name}", len(body), percent=True)
    parts = []
    for piece in _pieces(body):
        try:
            data = np.loadtxt(io.StringIO(piece), delimiter=",", dtype=np.float64, ndmin=2, comments=None)
        except ValueError:
            raise _diagnose(body, columns, name) from None
        if data.shape[1] != columns:
            raise _diagnose(body, columns, name)
        parts.append(data)
        progress.advance(len(piece))
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def _pieces(body: str) -> list[str]:
    """``body`` cut after a newline every ``_PIECE_CHARS`` or so.  A piece of nothing but
    blank lines goes with its neighbour: alone, np.loadtxt would find no rows in it
    (and warn), where in the whole it skips them."""
    pieces: list[str] = []
    start = 0
    while start < len(body):
        cut = body.find("\n", start + _PIECE_CHARS)
        end = len(body) if cut < 0 else cut + 1
        piece = body[start:end]
        if pieces and (not piece.strip() or not pieces[-1].strip()):
            pieces[-1] += piece
        else:
            pieces.append(piece)
        start = end
    return pieces


def _diagnose(body: str, columns: int, name: str) -> InputFormatError:
    """The slow path: find the first bad line for the message."""
    for lineno, row in enumerate(csv.reader(io.StringIO(body)), start=2):
        if not row or all(not c.strip() for c in row):
            return InputFormatError(f"{name}: line {lineno}: empty line")
        if len(row) != columns:
            return InputFormatError(f"{name}: line {lineno}: {len(row)} cells, expected {columns}")
        for col, cell in enumerate(row, start=1):
            try:
                float(cell)
            except ValueError:
                return InputFormatError(f"{name}: line {lineno}, column {col}: not a number: {cell.strip()[:30]!r}")
    return InputFormatError(f"{name}: cannot parse as CSV numbers")


def write_recording(dest: str | Path | IO[str], t: np.ndarray, values: np.ndarray, unit: Unit = "newton",
                    progress: Progress = NO_PROGRESS) -> None:
    """``progress``: a stage over the rows."""
    prefix = "f" if unit == "newton" else "raw"
    header = "t," + ",".join(f"{prefix}{i}" for i in range(values.shape[1]))
    _write(dest, header, np.column_stack([t, values]), ["%.6f"] + ["%.9g"] * values.shape[1], progress)


def write_updates(dest: str | Path | IO[str], table: UpdateTable) -> None:
    """One row per update (:func:`update_row`); ``state`` as its label, floats with 9
    significant digits."""
    with _opened(dest) as out:
        out.write(",".join(COLUMNS) + "\n")
        for row in zip(*(getattr(table, c).tolist() for c in COLUMNS)):
            u = Update(*row)
            out.write(update_row(u, LABELS[u.state]))


def update_row(u: Update, label: str) -> str:
    """One update as a row of the updates CSV (``detect``'s output, the recorder's)."""
    return (f"{u.t:.6f},{u.r_coe:.9g},{u.r_dw:.9g},{label},{int(u.valid)},{u.f_sum:.9g},"
            f"{u.xc:.9g},{u.yc:.9g},{u.flags},{u.score_a:.9g},{u.score_b:.9g}\n")


def read_updates(source: str | Path) -> dict[str, np.ndarray]:
    """Read an output CSV back (for tests and plots): columns by name."""
    text, name = _read_text(source)
    rows = list(csv.reader(io.StringIO(text)))
    if not rows or rows[0][:4] != list(COLUMNS[:4]):
        raise InputFormatError(f"{name}: line 1: expected a header starting with {','.join(COLUMNS[:4])}")
    head, data = rows[0], rows[1:]
    out: dict[str, np.ndarray] = {}
    for j, col in enumerate(head):
        cells = [r[j] for r in data]
        out[col] = np.array(cells, dtype=object if col == "state" else np.float64)
    return out


@contextlib.contextmanager
def _opened(dest: str | Path | IO[str]) -> Iterator[IO[str]]:
    """A stream to write to: an open stream as is, ``-`` for stdout, else a new file."""
    if hasattr(dest, "write"):
        yield dest  # type: ignore[misc]  # hasattr does not narrow: anything with write() is the stream
    elif str(dest) == "-":
        yield sys.stdout
    else:
        with open(dest, "w", encoding="utf-8", newline="") as f:
            yield f


def _write(dest: str | Path | IO[str], header: str, data: np.ndarray, fmt: list[str],
           progress: Progress = NO_PROGRESS) -> None:
    progress.stage(f"writing {'<stdout>' if str(dest) == '-' else getattr(dest, 'name', dest)}", len(data))
    with _opened(dest) as out:
        out.write(header + "\n")
        for a in range(0, len(data), _PIECE_ROWS):
            piece = data[a:a + _PIECE_ROWS]
            np.savetxt(out, piece, delimiter=",", fmt=fmt)
            progress.advance(len(piece))
