"""The package's error hierarchy: one root, a few branches, each message one line.

Every expected failure (a bad profile, a malformed input file, a frame that does not
decode) raises a subclass of :class:`EskinError` whose ``str()`` names the thing that
is wrong and where.  The CLI prints that line and exits non-zero; it never shows a
traceback unless ``--debug`` is given.
"""

from __future__ import annotations


class EskinError(Exception):
    """Root of every error this package raises on purpose."""

    #: Exit code the CLI uses for this kind of error.
    exit_code: int = 1


class ProfileError(EskinError):
    """A profile file is missing, malformed or inconsistent (rejected before start)."""

    exit_code = 2


class InputFormatError(EskinError):
    """An input file (recording CSV, log) is malformed; the message names the line."""

    exit_code = 2


class DecodeError(EskinError):
    """A frame from a transport does not decode; sources count and drop these."""
