"""``eskin-bus``: a thin click shell; each subcommand lives in its own module and only
wires a source, the pipeline and a sink from a profile and options."""

from __future__ import annotations

import sys
import warnings
from typing import Any, NoReturn, TextIO

import click

from ..errors import DeprecatedKey, EskinError
from .console import add_command_envvars, add_global_verbosity, add_verbosity, sigterm_as_interrupt
from .docs_cmd import DOCS_LINE
from .help_tail import add_command_help_tail
from .lazy import LazyCommands


def _usage_line(exc: click.UsageError) -> NoReturn:
    """A usage error as one line, as every other error (click's own is three:
    ``Usage: ...``, ``Try ...``, ``Error: ...``), the help to see named at its end."""
    where = f"; help: {exc.ctx.command_path} -h" if exc.ctx is not None else ""
    click.echo(f"eskin-bus: error: {exc.format_message().rstrip('.')}{where}", err=True)
    sys.exit(exc.exit_code)


class _Group(click.Group):
    """Turn expected errors into one line on stderr and an exit code, never a traceback."""

    def make_context(self, info_name: str | None, args: list[str], parent: click.Context | None = None,
                     **extra: Any) -> click.Context:
        try:  # the group's own options (eskin-bus --bogus)
            return super().make_context(info_name, args, parent, **extra)
        except click.exceptions.NoArgsIsHelpError:
            raise  # the help page, as click shows it
        except click.UsageError as exc:
            _usage_line(exc)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except click.exceptions.NoArgsIsHelpError:
            raise  # a group given no command (eskin-bus plc): its help page
        except click.UsageError as exc:  # a command's options, arguments and checks
            _usage_line(exc)
        except EskinError as exc:
            if ctx.obj and ctx.obj.get("debug"):
                raise
            click.echo(f"eskin-bus: error: {exc}", err=True)
            sys.exit(exc.exit_code)
        except BrokenPipeError:
            sys.exit(0)  # `eskin-bus detect ... | head` is not an error
        except KeyboardInterrupt:
            # Ctrl-C or SIGTERM in a command with no stop of its own (a finite job:
            # evaluate, simulate, detect FILE): cut short, its output not whole; one
            # line and the shell's code for it, not click's "Aborted!" and 1
            if ctx.obj and ctx.obj.get("debug"):
                raise
            click.echo("eskin-bus: interrupted", err=True)
            sys.exit(INTERRUPTED)


#: The exit code of a finite job cut short by Ctrl-C or SIGTERM (128 + SIGINT, as a shell gives it).
INTERRUPTED = 130


_show_warning = warnings.showwarning


def _one_line_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                      file: TextIO | None = None, line: str | None = None) -> None:
    """A key that moved is one line, as an error is (the rest as Python shows them)."""
    if issubclass(category, DeprecatedKey):
        click.echo(f"eskin-bus: warning: {message}", err=True)
        return
    _show_warning(message, category, filename, lineno, file, line)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]}, epilog=f"\b\n{DOCS_LINE}")
@click.option("--debug", is_flag=True, help="Show tracebacks for errors.")
@click.version_option(package_name="eskin-industrial", message=f"%(prog)s, version %(version)s\n{DOCS_LINE}")
@click.pass_context
def main(ctx: click.Context, debug: bool) -> None:
    """Electronic-skin tactile arrays on industrial grippers: decode, detect slip, tell the PLC."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug
    sigterm_as_interrupt(ctx)  # SIGTERM as Ctrl-C: each long command's own clean end
    warnings.showwarning = _one_line_warning
    warnings.simplefilter("always", DeprecatedKey)  # each moved key of each file, every time


#: Each command's module, imported when the command is named (a command line names
#: one; the help and the completion list them all): ``eskin-bus X`` pays for X's imports
#: only (``eskin-bus --version`` took 0.54 s importing every module, 0.36-0.38 s so).
COMMANDS: dict[str, tuple[str, str]] = {
    "bridge": ("bridge_cmd", "bridge"),
    "demo": ("demo_cmd", "demo"),
    "detect": ("detect_cmd", "detect"),
    "profile": ("profile_cmd", "profile"),
    "simulate": ("simulate_cmd", "simulate"),
    "plot": ("plot_cmd", "plot"),
    "evaluate": ("evaluate_cmd", "evaluate_cmd"),
    "plc": ("plc_cmd", "plc"),
    "plc-sim": ("plc_sim_cmd", "plc_sim"),
    "modbus-node": ("modbus_cmd", "modbus_node"),
    "modbus-bridge": ("modbus_cmd", "modbus_bridge"),
    "node": ("node_cmd", "node"),
    "receive": ("receive_cmd", "receive"),
    "monitor": ("monitor_cmd", "monitor"),
    "examples": ("examples_cmd", "examples"),
    "plant": ("plant_cmd", "plant"),
    "opcua": ("opcua_cmd", "opcua"),
    "docs": ("docs_cmd", "docs"),
    "completion": ("completion", "completion"),
}


def _dress(name: str, cmd: click.Command) -> None:
    """What every command gets as it is loaded: -v/-q on it and on each command under
    it, each option also from the environment, ESKIN_<COMMAND>_<OPTION> (docs/cli.md),
    and its help's tail (examples, those variables), in that order."""
    add_verbosity(cmd, root=False)
    add_command_envvars(cmd, name)
    add_command_help_tail(cmd, name)


main.commands = LazyCommands(__name__, COMMANDS, _dress)
add_global_verbosity(main)  # -v/-q before the command too: eskin-bus -q bridge ...
