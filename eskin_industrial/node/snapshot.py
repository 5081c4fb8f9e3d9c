"""The node's snapshot: one publication of a sensor node's result, as every output
reads it.

Named fields in SI units (newtons, millimetres, seconds), not register words: the
PLC renders its own register image from it (``plc/``), Sparkplug its metrics, a view
its screen.  What may be claimed is decided here, once, for every output: a state
(and the scores behind it) is claimed only while the node is enabled, the sensor is
fresh and the bridge runs; ``valid`` says whether that state is a verdict.
"""

from __future__ import annotations

from typing import NamedTuple

from ..detect.state import GraspState
from ..frames import SENSOR_FAULTS, FrameFlag

_TURN_UNSEEN = int(FrameFlag.TURN_UNSEEN)
_NO_CONTACT = int(GraspState.NO_CONTACT)
_SLIP = int(GraspState.SLIP)


class Health(NamedTuple):
    """What the source side knows at publication time."""

    frame_age_s: float | None = None  #: None: no scan yet
    bus_fault: bool = False
    lost_scans: int = 0
    bus_errors: int = 0
    #: the sensor's faults now (:data:`~eskin_industrial.frames.SENSOR_FAULTS` bits;
    #: any: no state is claimed)
    fault: int = 0


class NodeSnapshot(NamedTuple):
    """One publication of a node's result.

    A named tuple, not a frozen dataclass: the loop builds one at every publication
    (every state change, and every ``refresh_s``; up to once a scan at 1 kHz), and a
    frozen dataclass's ``__init__`` pays one ``object.__setattr__`` a field.
    """

    #: The claimed grasp state (:class:`~eskin_industrial.detect.state.GraspState`
    #: code); None when no state is claimed: no update yet, detection disabled, the
    #: sensor stale or faulty (FLAGS DEAD_TAXELS, FROZEN, RATE, STREAM), or the bridge offline.
    state: int | None
    #: The state is a verdict: claimed, the detector's indicators valid, no bus fault.
    valid: bool
    enabled: bool  #: detection enabled (by a command)
    slip_latched: bool  #: a slip was seen since the last acknowledge (set while slip lasts)
    stale: bool  #: no scan for longer than the node's ``stale_s``
    bus_fault: bool  #: the sensor bus fails
    offline: bool  #: the bridge has stopped: the last snapshot, nothing claimed
    #: The paper's indicators, whatever method decides (None when no state is claimed).
    r_coe: float | None
    r_dw: float | None
    #: The deciding method's own two scores (:attr:`score_names`; None when no state is claimed).
    score_a: float | None
    score_b: float | None
    f_sum_n: float | None  #: total force of the newest frame (None: no update yet, a sensor fault, or offline)
    xc_mm: float | None  #: centre of force (held while out of contact; None: no update yet)
    yc_mm: float | None
    #: the newest update's frame and update flags (:class:`~eskin_industrial.frames.FrameFlag`),
    #: and the sensor's faults now
    flags: int
    frame_age_s: float | None  #: age of the newest scan at publication (None: none, or offline)
    slip_events: int  #: entries into slip since start
    state_changes: int  #: changes of the state since start
    lost_scans: int  #: failed polls and sequence gaps
    bus_errors: int  #: the transport's error count
    scans: int  #: scans the node's loop has taken since start
    method: str  #: the deciding method's name
    method_code: int  #: its fixed number (``detect.methods``; 0: none)
    score_names: tuple[str, str]  #: what :attr:`score_a` and :attr:`score_b` are
    t: float | None  #: the deciding update's time on the sensor's clock (s; None: no update yet)
    t_event: float  #: ``time.perf_counter()`` when the deciding scan arrived
    #: ``time.time()`` when the deciding scan arrived (a source timestamp for outputs
    #: that carry one).
    wall_time_s: float
    urgent: bool  #: a state, validity, latch or health change: to be sent at once
    #: The detector's own newest state and its validity, claimed or not (what a tare
    #: is judged on: a disabled node's detector still runs).
    detected_state: int | None
    detected_valid: bool

    @property
    def contact(self) -> bool:
        """In contact (any claimed state but ``no_contact``)."""
        return self.state is not None and self.state != _NO_CONTACT

    @property
    def slip(self) -> bool:
        return self.state == _SLIP

    @property
    def turn_unseen(self) -> bool:
        """In contact, but a turn about the normal would go unseen (FrameFlag.TURN_UNSEEN)."""
        return bool(self.flags & _TURN_UNSEEN)

    @property
    def sensor_fault(self) -> int:
        """The sensor's fault bits in :attr:`flags` (DEAD_TAXELS, FROZEN, RATE, STREAM; 0: none)."""
        return self.flags & SENSOR_FAULTS

    @property
    def state_label(self) -> str | None:
        return None if self.state is None else GraspState(self.state).label
