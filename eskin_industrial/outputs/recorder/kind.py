"""The recorder as an output kind: ``[recorder]`` of the bridge configuration, or
``--record PATH`` on the command line; one :class:`.sink.Recorder` per node."""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any, Literal

from ...preflight import check_writable_dir
from ...schema import in_range
from ..base import CliOption, OutputKind, Sink
from .sink import Recorder, RowFile

if TYPE_CHECKING:
    from ...seam import NodeLike, OpenContext


@dataclass(frozen=True)
class RecorderOptions:
    #: Output file; ``-`` is standard output; ``{node}`` is replaced by the node's name.
    path: str
    #: ``csv`` or ``jsonl``; default: ``jsonl`` for a ``.jsonl`` / ``.ndjson`` path, else ``csv``.
    format: Literal["csv", "jsonl"] | None = None
    #: Longest time an update stays in the write buffer.
    flush_every_s: float = field(default=1.0, metadata=in_range(0, 3600))

    @property
    def resolved_format(self) -> str:
        if self.format is not None:
            return self.format
        return "jsonl" if Path(self.path).suffix in (".jsonl", ".ndjson") else "csv"


class RecorderKind(OutputKind[RecorderOptions]):
    name = "recorder"
    Options = RecorderOptions
    cli_options = (
        CliOption("--record", "record", "Record every detector update to this file ('-': stdout; {node}: the "
                  "node's name), as CSV or JSON lines (by suffix, or --record-format).", metavar="PATH"),
        CliOption("--record-format", "record_format", "Format of --record (default: by the file's suffix).",
                  choices=("csv", "jsonl")),
    )

    @classmethod
    def options_from_cli(cls, values: dict[str, Any]) -> RecorderOptions | None:
        path = values.get("record")
        if path is None:
            if values.get("record_format") is not None:
                raise ValueError("--record-format: give --record PATH too")
            return None
        return RecorderOptions(path=path, format=values.get("record_format"))

    @classmethod
    def describe(cls, options: RecorderOptions, node: NodeLike[Any]) -> str:
        return f"record {options.resolved_format} {_path_for(options.path, node.name)}"

    @classmethod
    def check(cls, options: RecorderOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        paths = [_path_for(options.path, n.name) for n in nodes]
        if len(nodes) > 1 and len(set(paths)) < len(paths):
            raise ValueError("path: several nodes would write one file; put {node} in the path")
        for p in paths:
            if p != "-":
                check_writable_dir(p, "path")
                if Path(p).is_dir():
                    raise ValueError(f"path: {p}: is a folder, not a file")

    @classmethod
    def _open_nodes(cls, options: RecorderOptions, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink]:
        from ...errors import EskinError

        out: list[Sink] = []
        for n in nodes:
            path = _path_for(options.path, n.name)
            if path == "-":
                rec = Recorder(sys.stdout, options.resolved_format, n.name, where="stdout", owned=False,
                          flush_every_s=options.flush_every_s)
            else:
                try:  # opened again after a failure: what was recorded stays, the rows go on
                    row_file = RowFile(path, append=context.reopen)
                except OSError as exc:
                    raise EskinError(f"{path}: cannot write the record: {exc.strerror or exc}") from None
                stream: IO[str] = row_file  # type: ignore[assignment]  # write, flush, close
                rec = Recorder(stream, options.resolved_format, n.name, where=path, owned=True,
                          flush_every_s=options.flush_every_s, header=row_file.size == 0)
            context.closers.append(rec.close)
            out.append(rec)
        return out


def _path_for(path: str, node: str) -> str:
    return path.replace("{node}", node)
