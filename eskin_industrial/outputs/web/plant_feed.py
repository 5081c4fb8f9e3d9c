"""What the plant page is handed: one :class:`PlantRow` per Sparkplug B edge node and
device, plain values only.  The web kind imports no other output kind (pyproject.toml's
import contracts): ``eskin-bus plant`` reads its host view and hands the rows over, as
``bridge`` hands over the served PLC block.

The CLI's side (:meth:`PlantFeed.put`) replaces the rows and wakes the server; the
server's side reads the newest rows under the lock.  Nothing is queued: a page that
draws slowly sees the newest rows, never a backlog.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

Status = Literal["online", "offline", "stale"]


@dataclass(frozen=True)
class PlantRow:
    """An edge node (``device`` None) or one of its devices, as the page shows it."""

    group: str
    edge: str
    device: str | None
    #: ``online`` by its births; ``stale`` online but nothing from it within the stale time;
    #: ``offline`` by its death (NDEATH of its session, or DDEATH).
    status: Status
    state: str | None = None
    valid: bool | None = None
    method: str | None = None
    slips: int | None = None
    last_slip_ms: int | None = None
    rate: float | None = None  #: messages a second
    frame_max: float | None = None
    frame_sum: float | None = None
    seq_gaps: int = 0
    bd_seq: int | None = None

    def as_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class PlantFeed:
    """The newest rows, shared by the thread that watches the broker and the server's."""

    kick: Callable[[], None] = lambda: None
    lock: threading.Lock = field(default_factory=threading.Lock)
    seq: int = 0  #: bumped when the rows change
    messages: int = 0  #: Sparkplug messages seen on the broker

    def __post_init__(self) -> None:
        self.rows: tuple[PlantRow, ...] = ()

    def put(self, rows: Sequence[PlantRow], messages: int = 0) -> bool:
        """New rows; True (and the server woken) when they differ from the last."""
        rows = tuple(rows)
        with self.lock:
            self.messages = messages
            if rows == self.rows:
                return False
            self.rows = rows
            self.seq += 1
        self.kick()
        return True

    def read(self) -> tuple[int, tuple[PlantRow, ...], int]:
        with self.lock:
            return self.seq, self.rows, self.messages
