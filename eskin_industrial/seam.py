"""The seam both wings plug into: what a source kind (``bus/``) or an output kind
(``outputs/``) is handed to open its nodes.

A module of its own, below both wings, so that neither takes the other's types: a
source kind and an output kind see the same resolved node and the same bridge-wide
context, and neither imports the other's seam.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol, TypeVar

from .identity import DeviceIdentity

if TYPE_CHECKING:
    from .profile import Profile

#: Frames a reader may hold for its consumer before it drops (and counts) the newest:
#: about 25 s of a saturated 1 Mbit/s classic bus.
DEFAULT_QUEUE_FRAMES = 200_000
#: ``queue_frames`` at most (``bridge.toml``, ``receive --queue-frames``): ten times the default.
MAX_QUEUE_FRAMES = 10 * DEFAULT_QUEUE_FRAMES

OptionsT_co = TypeVar("OptionsT_co", covariant=True)


class NodeLike(Protocol[OptionsT_co]):
    """What a kind is handed to open a node: a resolved ``[[node]]`` (see
    :class:`eskin_industrial.bridge.config.ResolvedNode`), its source options of type
    ``OptionsT_co``.  Read-only: a resolved node is frozen."""

    @property
    def name(self) -> str: ...

    @property
    def profile(self) -> Profile: ...

    @property
    def rate_hz(self) -> float: ...

    @property
    def options(self) -> OptionsT_co: ...


@dataclass
class OpenContext:
    """Bridge-wide settings and the place to register what must be closed at the end."""

    queue_frames: int = DEFAULT_QUEUE_FRAMES
    #: A receiver watching one node: it also gets the other frames of its bus (counted
    #: as foreign), where a bridge routes each frame to its node only.
    all_frames: bool = False
    closers: list[Callable[[], None]] = field(default_factory=list)
    #: An output opened again after a failure (its supervisor's restart): a file is
    #: appended to, not started anew.
    reopen: bool = False
    #: The device identity the outputs name (``[identity]`` of the bridge configuration).
    identity: DeviceIdentity = field(default_factory=DeviceIdentity)
    #: What an output keeps across its restarts, under its kind's name: the same dict at
    #: every open of one output (what it was handed after the first, its sessions).
    kept: dict[str, Any] = field(default_factory=dict)
