"""``eskin-bus``: a thin click shell; each subcommand lives in its own module and only
wires a source, the pipeline and a sink from a profile and options."""

from __future__ import annotations

import sys
import warnings
from typing import Any, NoReturn, TextIO

import click

from ..errors import DeprecatedKey, EskinError
from .bridge_cmd import bridge
from .completion import completion
from .console import add_envvars, add_global_verbosity, add_verbosity, sigterm_as_interrupt
from .demo_cmd import demo
from .detect_cmd import detect
from .docs_cmd import DOCS_LINE, docs
from .evaluate_cmd import evaluate_cmd
from .examples_cmd import examples
from .help_tail import add_help_tail
from .modbus_cmd import modbus_bridge, modbus_node
from .monitor_cmd import monitor
from .node_cmd import node
from .opcua_cmd import opcua
from .plant_cmd import plant
from .plc_cmd import plc
from .plc_sim_cmd import plc_sim
from .plot_cmd import plot
from .profile_cmd import profile
from .receive_cmd import receive
from .simulate_cmd import simulate


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


main.add_command(bridge)
main.add_command(demo)
main.add_command(detect)
main.add_command(profile)
main.add_command(simulate)
main.add_command(plot)
main.add_command(evaluate_cmd, name="evaluate")
main.add_command(plc)
main.add_command(plc_sim)
main.add_command(modbus_node)
main.add_command(modbus_bridge)
main.add_command(node)
main.add_command(receive)
main.add_command(monitor)
main.add_command(examples)
main.add_command(plant)
main.add_command(opcua)
main.add_command(docs)
main.add_command(completion)
# After every command is added: -v/-q on each, and each option also from the
# environment, ESKIN_<COMMAND>_<OPTION> (docs/cli.md).
add_verbosity(main)
add_global_verbosity(main)  # and before the command: eskin-bus -q bridge ...
add_envvars(main, "ESKIN")
add_help_tail(main)  # each help page ends with examples and its ESKIN_* names
