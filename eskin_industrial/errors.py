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


class ListenError(EskinError):
    """A server cannot listen (its port in use, an address not this machine's): a
    setting to change, which a restart does not mend; exit 2 as a bad configuration
    (the service unit restarts neither), the same line as ``--check``'s."""

    exit_code = 2


class InputFormatError(EskinError):
    """An input file (recording CSV, log) is malformed; the message names the line."""

    exit_code = 2


class OutputFileError(EskinError):
    """A file a command writes cannot be created or written (no such folder, no
    permission, the disk full); the message names the option and the path."""

    exit_code = 2


class DecodeError(EskinError):
    """A frame from a transport does not decode; sources count and drop these."""


class MissingExtra(EskinError):
    """An optional dependency the chosen command or method needs is not installed.
    Every one reads the same and exits 4:
    ``WHAT needs PACKAGE: pip install 'eskin-industrial[EXTRA]'`` (quoted for zsh)."""

    exit_code = 4

    @classmethod
    def of(cls, what: str, package: str, extra: str) -> MissingExtra:
        return cls(f"{what} needs {package}: pip install 'eskin-industrial[{extra}]'")


class TransportError(EskinError):
    """A bus or a peer cannot be reached or answers wrongly (sources and sinks)."""

    exit_code = 3


class CanBusError(TransportError):
    """The CAN bus cannot be opened (unknown interface, missing channel, no driver)."""


class SocketCanMissing(CanBusError):
    """The kernel has no SocketCAN (``AF_CAN`` is not supported): no channel name and
    no interface option can help, only a kernel module or another machine; exit 5."""

    exit_code = 5


class NothingReceived(TransportError):
    """``--idle-exit`` passed with not one scan of the node since the start: a channel
    nobody sends on, a node that is off, or another node's IDs; exit 6."""

    exit_code = 6


class ModbusFault(TransportError):
    """A Modbus transaction failed; ``kind`` is ``timeout``, ``crc``, ``exception`` or
    ``connection``; ``code`` is the exception code for ``exception``."""

    def __init__(self, kind: str, message: str, code: int = 0) -> None:
        super().__init__(message)
        self.kind = kind
        self.code = code


class Refused(EskinError):
    """A PLC write the register image does not accept; ``code`` is the Modbus
    exception code to answer with."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code


class DeprecatedKey(FutureWarning):
    """A configuration key that moved: still read, under its new spelling, with one
    warning line naming both (shown by the CLI as ``eskin-bus: warning: ...``)."""
