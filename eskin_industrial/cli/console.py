"""What every command shares on the terminal: ``-v/-q``, progress on stderr, JSON.

``-v``/``-q`` are added to every command by :func:`add_verbosity` (a command that has
its own ``-q`` keeps it).  ``-v`` lets the package's and, with ``-vv``, python-can's and
pymodbus' logs through to stderr; ``-q`` leaves only errors: no progress, no summary.
Progress bars go to stderr, only when it is a terminal and ``-q`` is not given, so a
pipe or a log file never sees them.
"""

from __future__ import annotations

import functools
import json
import logging
import shutil
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from types import FrameType
from typing import Any, TypeVar

import click

T = TypeVar("T")
_KEY = "eskin.verbosity"  # in ctx.meta, which every context of one invocation shares


def verbosity() -> int:
    """-1 with ``-q``, 0 by default, 1 with ``-v``, 2 with ``-vv``."""
    ctx = click.get_current_context(silent=True)
    return ctx.meta.get(_KEY, 0) if ctx is not None else 0


def quiet(own_flag: bool = False) -> bool:
    return own_flag or verbosity() < 0


def _set_verbose(ctx: click.Context, _param: click.Parameter, value: int) -> None:
    if value:
        ctx.meta[_KEY] = value
        logging.basicConfig(stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
        logging.getLogger("eskin_industrial").setLevel(logging.DEBUG if value > 1 else logging.INFO)
        if value > 1:
            for name in ("can", "pymodbus", "paho"):
                logging.getLogger(name).setLevel(logging.DEBUG)


def _set_quiet(ctx: click.Context, _param: click.Parameter, value: bool) -> None:
    if value:
        ctx.meta[_KEY] = -1


def _remember_quiet(ctx: click.Context, _param: click.Parameter, value: bool) -> bool:
    """A command's own exposed ``-q``: still recorded, so that progress honours it;
    set too by a ``-q`` before the command (``eskin-bus -q detect ...``)."""
    _set_quiet(ctx, _param, value)
    return value or verbosity() < 0


def _verbose_option() -> click.Option:
    return click.Option(["-v", "--verbose"], count=True, expose_value=False, callback=_set_verbose,
                        help="More on stderr: -v the package's logs, -vv python-can's and pymodbus' too.")


def _quiet_option() -> click.Option:
    return click.Option(["-q", "--quiet"], is_flag=True, expose_value=False, callback=_set_quiet,
                        help="Only errors on stderr: no progress, no summary.")


def add_global_verbosity(root: click.Group) -> None:
    """``-v``/``-q`` before the command too (``eskin-bus -q bridge ...``): the group's
    own options, recorded where every command of the invocation reads them."""
    root.params.extend([_verbose_option(), _quiet_option()])


def add_verbosity(cmd: click.Command, root: bool = True) -> None:
    """Give ``cmd`` (and every command under a group, and the group itself but the
    root: ``eskin-bus plc -q map``) ``-v/--verbose`` and ``-q/--quiet``, unless it has
    them already.  The root's are :func:`add_global_verbosity`'s."""
    if isinstance(cmd, click.Group):
        for sub in cmd.commands.values():
            add_verbosity(sub, root=False)
        if root:
            return
    taken = {opt for p in cmd.params for opt in getattr(p, "opts", [])}
    for p in cmd.params:
        if "-q" in getattr(p, "opts", []) and p.callback is None:
            p.callback = _remember_quiet
    if "-v" not in taken:
        cmd.params.append(_verbose_option())
    if "-q" not in taken:
        cmd.params.append(_quiet_option())


def sigterm_as_interrupt(ctx: click.Context) -> None:
    """SIGTERM (``kill``, ``systemctl stop``, ``timeout``) ends a command as Ctrl-C
    does: a KeyboardInterrupt in the main thread, so that each command's own Ctrl-C
    path runs (the output flushed, the counters printed), where the default action
    would end the process mid-write.  Commands that handle the signals themselves
    (``bridge``: bridge/signals.py) install their own handlers over this one for their
    run.  Only a default handler is replaced; the previous one is back when the
    invocation ends."""
    if threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        return  # an embedding program's own handler stays
    before = signal.signal(signal.SIGTERM, _interrupt)
    ctx.call_on_close(lambda: signal.signal(signal.SIGTERM, before))


def _interrupt(_signum: int, _frame: FrameType | None) -> None:
    raise KeyboardInterrupt


@contextmanager
def signals_ask(stop: Callable[[], None]) -> Iterator[None]:
    """Ctrl-C and SIGTERM call ``stop`` (a plain flag's setter, which a loop reads at
    each step) for the length of the block, in place of a KeyboardInterrupt: an
    exception raised between two bytecodes may land between an update counted and
    the same update written, and a stopped ``receive`` then wrote one row fewer
    than it counted.  A second one is a KeyboardInterrupt, for a stop that does not
    come.  The previous handlers are back on the way out."""
    asked_before = False

    def asked(_signum: int, _frame: FrameType | None) -> None:
        nonlocal asked_before
        if asked_before:
            raise KeyboardInterrupt
        asked_before = True
        stop()

    with _on_stop_signals(asked):
        yield


class HeldInterrupt:
    """Ctrl-C and SIGTERM as a KeyboardInterrupt, except inside :meth:`whole`, where
    the interrupt waits for the block's end: a command blocked on its input
    (``detect --can-log -``) must be interruptible there, but not between an update
    counted and the same update written."""

    def __init__(self) -> None:
        self._inside = False
        self._pending = False

    def _handler(self, _signum: int, _frame: FrameType | None) -> None:
        if self._inside:
            self._pending = True
        else:
            raise KeyboardInterrupt

    @contextmanager
    def whole(self) -> Iterator[None]:
        self._inside = True
        try:
            yield
        finally:
            self._inside = False
            if self._pending:
                self._pending = False
                raise KeyboardInterrupt

    @contextmanager
    def installed(self) -> Iterator[HeldInterrupt]:
        """The handler on SIGINT and SIGTERM for the length of the block."""
        with _on_stop_signals(self._handler):
            yield self


@contextmanager
def _on_stop_signals(handler: Callable[[int, FrameType | None], None]) -> Iterator[None]:
    """``handler`` on SIGINT and SIGTERM for the length of the block (the main thread
    only, as Python requires; elsewhere nothing), the previous handlers back after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, old in before.items():
            signal.signal(s, old)


def json_alias(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--json`` beside a command's ``--format`` (its ``fmt`` parameter): the same as
    ``--format json``, so that every command that offers JSON takes ``--json``."""

    @functools.wraps(f)
    def with_json(*args: Any, as_json: bool = False, **kwargs: Any) -> Any:
        if as_json:
            kwargs["fmt"] = "json"
        return f(*args, **kwargs)

    return click.option("--json", "as_json", is_flag=True, help="JSON: the same as --format json.")(with_json)


def add_command_envvars(cmd: click.Command, name: str, prefix: str = "ESKIN") -> None:
    """Every option of ``cmd`` (and of every command under it) also from an environment
    variable named after the command path and the option's long name, the way click's
    ``auto_envvar_prefix`` names them, but from the option's name rather than its
    Python parameter: ``--plc`` of ``bridge`` is ``ESKIN_BRIDGE_PLC``, ``-p/--profile``
    of ``plc map`` is ``ESKIN_PLC_MAP_PROFILE`` (``name``: the command's, ``prefix``:
    the group's variables').  The command line wins over the environment, the
    environment over the defaults."""
    prefix = f"{prefix}_{_upper(name)}"
    if isinstance(cmd, click.Group):
        for sub_name, sub in cmd.commands.items():
            add_command_envvars(sub, sub_name, prefix)
        return
    for p in cmd.params:
        if isinstance(p, click.Option) and p.envvar is None and not p.hidden:
            longs = [o for o in p.opts if o.startswith("--")]
            if longs and longs[0] not in ("--help", "--version"):
                p.envvar = f"{prefix}_{_upper(longs[0][2:])}"


def _upper(name: str) -> str:
    return name.upper().replace("-", "_")


@contextmanager
def progress(items: Iterable[T], label: str, length: int | None = None,
             own_quiet: bool = False) -> Iterator[Iterable[T]]:
    """``items``, with a progress bar on stderr when stderr is a terminal and not quiet."""
    if quiet(own_quiet) or not sys.stderr.isatty():
        yield items
        return
    with click.progressbar(items, length=length, label=label, file=sys.stderr,
                           show_pos=True, show_eta=True) as bar:
        yield bar


#: Work that is usually short (a recording read, a scene written) shows a bar only
#: once it has taken this long.
PROGRESS_DELAY_S = 1.0


#: Columns a line takes besides its label and the bar ("  [", "]  ", the count, "  ",
#: the ETA), and the least bar worth drawing; the bar takes the rest of the terminal.
_BAR_CLUTTER = 3 + 3 + 21 + 2 + 8
_BAR_LEAST = 10


class Ticker:
    """A bar on stderr for work that reports through :class:`~eskin_industrial.progress.Progress`
    (stages of known length, steps done), shown only when stderr is a terminal and
    not quiet.

    ``delay_s``: nothing is shown before the work has run that long, so that a short
    job (a small file, a short scene) draws no bar at all.  ``stdout_data``: the
    command writes its data to stdout while it works; when that is the terminal too,
    no bar, so that the bar never lands among the rows (curl's rule for its meter).
    """

    def __init__(self, total: int = 0, label: str = "", own_quiet: bool = False, delay_s: float = 0.0,
                 stdout_data: bool = False) -> None:
        self._quiet = quiet(own_quiet)
        self._on = _watched(self._quiet, stdout_data)
        self._since = time.time()
        self._delay_s = delay_s
        self._bar: Any = None
        self._label, self._total, self._pos, self._percent = label, total, 0, False
        self._started = self._since
        self._width = len(label)
        self._show()

    def stage(self, label: str, total: int, percent: bool = False) -> None:
        self._end_bar()
        self._label, self._total, self._pos, self._percent = label, total, 0, percent
        self._started = time.time()
        self._width = len(label)
        self._show()

    def advance(self, n: int = 1, label: str | None = None) -> None:
        self._pos += n
        if label is not None:
            self._width = max(self._width, len(label))
            self._label = label
        if not self._on:
            return
        if self._bar is None:
            self._show()
            return
        self._bar.label = self._fit()
        self._bar.update(n)

    def step(self, n: int = 1, label: str | None = None) -> None:
        self.advance(n, label)

    def write(self, line: str) -> None:
        """A line on stderr (unless quiet), in place of the bar, which comes back below
        it at the next step."""
        if self._quiet:
            return
        click.echo(("\r\033[K" if self._bar is not None else "") + line, err=True)

    def close(self) -> None:
        self._end_bar()
        self._on = False

    def __enter__(self) -> Ticker:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def _show(self) -> None:
        if not self._on or self._bar is not None or self._total <= 0:
            return
        if time.time() - self._since < self._delay_s:
            return
        self._bar = click.progressbar(length=self._total, label=self._fit(), file=sys.stderr, width=0,
                                      show_pos=not self._percent, show_eta=True)  # (0: the terminal's width)
        self._bar.__enter__()
        self._bar.start = self._started  # the ETA counts from the stage's start, not from when the bar appeared
        if self._pos:
            self._bar.update(self._pos)

    def _fit(self) -> str:
        """The label, padded to the longest so far (a steady bar while labels differ in
        length) and cut to leave the bar, the count and the ETA room on one line: a
        line that wraps cannot be drawn over."""
        room = max(10, shutil.get_terminal_size().columns - _BAR_CLUTTER - _BAR_LEAST)
        return self._label.ljust(self._width)[:room]

    def _end_bar(self) -> None:
        if self._bar is not None:
            self._bar.__exit__(None, None, None)
            self._bar = None


def _watched(quiet_: bool, stdout_data: bool) -> bool:
    """Whether a bar or a count may be drawn: stderr is a terminal, not quiet, and the
    command's rows do not go to that terminal too."""
    return not quiet_ and sys.stderr.isatty() and not (stdout_data and sys.stdout.isatty())


class Counter:
    """A running count on stderr for work of no known length (a live log on stdin),
    under the :class:`Ticker`'s rules; drawn at most five times a second, so that a
    step costs a clock read."""

    def __init__(self, label: str, own_quiet: bool = False, delay_s: float = 0.0, stdout_data: bool = False) -> None:
        self._on = _watched(quiet(own_quiet), stdout_data)
        self._label = label
        self._n = 0
        self._shown = False
        self._next = time.monotonic() + delay_s

    def add(self, n: int = 1) -> None:
        self._n += n
        if self._on:
            now = time.monotonic()
            if now >= self._next:
                self._next = now + 0.2
                self._draw()

    def close(self) -> None:
        if self._shown:
            self._draw()
            sys.stderr.write("\n")
            sys.stderr.flush()
        self._on = self._shown = False

    def __enter__(self) -> Counter:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def _draw(self) -> None:
        sys.stderr.write(f"\r\033[K{self._label}  {self._n}")
        sys.stderr.flush()
        self._shown = True


def echo_json(value: Any) -> None:
    """One JSON document on stdout (numbers that are not finite become null)."""
    click.echo(json.dumps(_finite(value), indent=2))


def _finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if value == value and abs(value) != float("inf") else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value
