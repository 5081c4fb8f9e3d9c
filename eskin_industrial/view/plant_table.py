"""The live table of ``eskin-bus plant``: one line per edge node and per device, from
:meth:`eskin_industrial.outputs.sparkplug.watch.PlantModel.rows` (no I/O: lines out)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

_COLUMNS = (("edge node / device", 24), ("online", 8), ("state", 16), ("valid", 6), ("last slip", 13), ("slips", 6),
            ("msg/s", 7), ("frame max / sum N", 18))


def _clock(ms: int | None) -> str:
    if ms is None:
        return "-"
    return time.strftime("%H:%M:%S", time.localtime(ms / 1000)) + f".{ms % 1000:03d}"


def _yes(v: bool | None) -> str:
    return "-" if v is None else ("yes" if v else "no")


def _frame(peak: float | None, total: float | None) -> str:
    return "-" if peak is None or total is None else f"{peak:.2f} / {total:.1f}"


def plant_lines(rows: Sequence[dict[str, Any]], title: str, width: int, height: int) -> list[str]:
    """The frame: a title, a header, then the rows (cut to the screen)."""
    edges = sum("device" not in r for r in rows)
    devices = len(rows) - edges
    lines = [f"{title} | {edges} edge node{'s' * (edges != 1)}, {devices} device{'s' * (devices != 1)}"]
    lines.append("".join(name.ljust(w) for name, w in _COLUMNS).rstrip())
    for r in rows:
        if "device" not in r:
            cells = [f"{r['group']}/{r['edge']}", "online" if r["online"] else "OFFLINE",
                     f"bdSeq {r['bdSeq'] if r['bdSeq'] is not None else '-'}", "", "",
                     "", f"seq gaps {r['seq_gaps']}" if r["seq_gaps"] else "", ""]
        else:
            cells = [f"  {r['device']}", "online" if r["online"] else "OFFLINE", r["state"] or "-", _yes(r["valid"]),
                     _clock(r["last_slip_ms"]), "-" if r["slips"] is None else str(r["slips"]), f"{r['rate']:.1f}",
                     _frame(r.get("frame_max"), r.get("frame_sum"))]
        lines.append("".join(c[: w - 1].ljust(w) for c, (_, w) in zip(cells, _COLUMNS)).rstrip())
    if not rows:
        lines.append("(no edge node seen yet: each shows from its next birth)")
    return [line[:width] for line in lines[:height]]
