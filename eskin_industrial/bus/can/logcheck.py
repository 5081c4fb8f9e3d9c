"""What a CAN log must show before its frames are trusted: complete records, and
frames that fit the node's layout.

python-can's readers stop silently at a record cut short (a BLF object or container
that runs past the end of the file, an ASC or candump line cut in half), and raise
whatever their parser meets (``zlib.error``, ``BLFParseError``, ``struct.error``) for
a corrupt one.  :func:`check_complete` finds the cut before any frame is read;
:data:`READ_ERRORS` is what the reading boundary turns into one
:class:`~eskin_industrial.errors.InputFormatError` line.  :func:`layout_mismatch` tells
a log of another layout on the same IDs from a log with a few damaged frames.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import can
from can.io.blf import BLFParseError

from ...errors import InputFormatError

#: What python-can's log readers raise for a corrupt file (BLFParseError is no
#: CanError; zlib and struct errors come out of the BLF reader raw).
READ_ERRORS: tuple[type[BaseException], ...] = (
    ValueError, IndexError, KeyError, OSError, EOFError, UnicodeDecodeError, struct.error, zlib.error,
    BLFParseError, can.CanError)

#: Text logs whose writers end every line with a newline: a last line without one
#: was cut short.
TEXT_SUFFIXES = (".asc", ".log", ".trc", ".csv", ".txt")

_BLF_FILE_HEADER = struct.Struct("<4sL")  # signature, header size (the rest is not needed)
_BLF_OBJ_HEADER = struct.Struct("<4sHHLL")  # signature, header size, version, object size, type
_BLF_FILE_SIZE_AT = 16  # the file header's "file size" field (uint64), written when the log is closed
_BLF_HEADER_MIN = 72  # the fixed part of the file header python-can reads

#: A log is refused when more than this share of the frames on the node's IDs do not
#: fit its layout (wrong length, wrong segment for the ID), beyond a few: damage gives
#: a handful, another layout on the same IDs gives a large share (one in two, for a
#: 12-bit layout read as a 16-bit one).
MISMATCH_SHARE = 0.05
MISMATCH_FLOOR = 10


def check_complete(path: str | Path) -> None:
    """InputFormatError naming the byte or line where ``path`` was cut short, if it was."""
    path = Path(path)
    name = path.name.lower()
    if name.endswith(".blf"):
        _check_blf(path)
    elif name.endswith(TEXT_SUFFIXES):
        _check_text(path)


def _check_text(path: Path) -> None:
    with open(path, "rb") as f:
        f.seek(0, 2)
        size = f.tell()
        if size == 0:
            return
        f.seek(size - 1)
        if f.read(1) == b"\n":
            return
        f.seek(0)
        lines = sum(chunk.count(b"\n") for chunk in iter(lambda: f.read(1 << 20), b""))
    raise InputFormatError(f"{path}: line {lines + 1}: cut short (no newline at the end of the file): "
                           "the log is truncated")


def _check_blf(path: Path) -> None:
    """Walk the objects (logging containers) by their headers: each must start with
    ``LOBJ`` and end within the file."""
    with open(path, "rb") as f:
        f.seek(0, 2)
        size = f.tell()
        f.seek(0)
        head = f.read(_BLF_HEADER_MIN)
        if len(head) < _BLF_HEADER_MIN:
            raise InputFormatError(f"{path}: byte {len(head)}: not a BLF log: {size} bytes, shorter than its header")
        signature, header_size = _BLF_FILE_HEADER.unpack_from(head)
        if signature != b"LOGG":
            raise InputFormatError(f"{path}: byte 0: not a BLF log (signature {signature!r}, expected b'LOGG')")
        declared = int.from_bytes(head[_BLF_FILE_SIZE_AT:_BLF_FILE_SIZE_AT + 8], "little")
        if declared > header_size and declared != size:  # 0 or the header size: a writer that never closed
            raise InputFormatError(f"{path}: byte {size}: the header says {declared} bytes, the file has {size}: "
                                   "the log is truncated or was appended to")
        pos = header_size
        while pos < size:
            f.seek(pos)
            raw = f.read(_BLF_OBJ_HEADER.size)
            if len(raw) < _BLF_OBJ_HEADER.size:
                raise InputFormatError(f"{path}: byte {pos}: object header cut short at the end of the file "
                                       f"({size} bytes): the log is truncated")
            sig, _, _, obj_size, _ = _BLF_OBJ_HEADER.unpack(raw)
            if sig != b"LOBJ" or obj_size < _BLF_OBJ_HEADER.size:
                raise InputFormatError(f"{path}: byte {pos}: not a BLF object (signature {sig!r}, size {obj_size})")
            if pos + obj_size > size:
                raise InputFormatError(f"{path}: byte {pos}: an object of {obj_size} bytes runs past the end of the "
                                       f"file ({size} bytes): the log is truncated")
            pos += obj_size + obj_size % 4  # (python-can's reader skips the same padding)


def layout_mismatch(counters: dict[str, int], what: str) -> str | None:
    """Why the frames an assembler counted (``frames``, ``malformed_frames``) cannot be
    the layout's (None: they can); ``what`` names the layout, for the message."""
    frames, bad = counters["frames"], counters["malformed_frames"]
    if bad > MISMATCH_FLOOR and bad > MISMATCH_SHARE * frames:
        return (f"{bad} of {frames} frames on {what} do not fit its layout (length or segment): a log of "
                f"another layout? refused")
    return None
