"""The state behind a node's snapshots: enable, the slip latch, the counts, and the
newest detector update; the loop keeps one per node.

Pure code, no I/O and no clock: :meth:`NodeStatus.observe` takes each detector
update, :meth:`NodeStatus.apply` each accepted command, and
:meth:`NodeStatus.snapshot` turns them, with the source's :class:`Health`, into the
:class:`NodeSnapshot` every output reads.  The latch and enable live here, not in an
output, so that every output shows the same ones whichever of them commanded.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..detect.state import GraspState
from ..detect.updates import Update, state_changed
from .commands import Command
from .snapshot import Health, NodeSnapshot

_SLIP = int(GraspState.SLIP)

# The bits of :meth:`NodeStatus.conditions` (the loop's "did anything change"; plain
# ints: this runs at every scan).
_STALE, _BUS_FAULT, _ENABLED, _LATCHED, _VALID = 1, 2, 4, 8, 16
_STATE_SHIFT = 5  #: the claimed state's code + 1 from here (0: none claimed)
_FAULT_SHIFT = 8  #: the sensor's fault bits (FrameFlag 1024..8192) from here on


@dataclass
class NodeStatus:
    """Enable, latch and counts of one node, and its newest update."""

    #: Frame age beyond which the sensor is stale (the profile's ``[output] stale_s``).
    stale_s: float
    method: str = ""  #: the deciding method's name
    method_code: int = 0  #: its fixed number (0: none)
    score_names: tuple[str, str] = ("score_a", "score_b")
    enabled: bool = True
    latched: bool = False
    slip_events: int = 0
    state_changes: int = 0
    update: Update | None = None

    # -- input side -------------------------------------------------------------
    def observe(self, update: Update) -> bool:
        """Take a detector update; True when the outputs must hear of it at once (the
        state, its validity or the slip latch changed)."""
        before = self.update
        self.update = update
        changed = before is None or before.state != update.state or before.valid != update.valid
        if state_changed(before, update):  # (a change of validity alone is urgent, but no state change)
            self.state_changes += 1
        if update.state == _SLIP and (before is None or before.state != _SLIP):
            self.slip_events += 1
            if self.enabled and not self.latched:
                self.latched = True
                changed = True
        return changed

    def apply(self, command: Command) -> None:
        """An accepted acknowledge, enable or disable (a tare acts on the calibration:
        the loop does it)."""
        if command.name == "ack":
            # The latch stays set while the slip lasts: an acknowledge cannot hide it.
            self.latched = self.enabled and self.update is not None and self.update.state == _SLIP
        elif command.name == "enable":
            self.enabled = True
        elif command.name == "disable":
            self.enabled = False
            self.latched = False

    # -- output side ------------------------------------------------------------
    def is_stale(self, frame_age_s: float | None) -> bool:
        # written so that a NaN age (a broken clock) reads as stale, never as fresh
        return frame_age_s is None or not frame_age_s <= self.stale_s

    def conditions(self, frame_age_s: float | None, bus_fault: bool, fault: int = 0) -> int:
        """What the outputs show, as one int: equal ints, nothing to tell at once."""
        u = self.update
        stale = frame_age_s is None or not frame_age_s <= self.stale_s
        bits = (_STALE if stale else 0) | (_BUS_FAULT if bus_fault else 0) | (_ENABLED if self.enabled else 0) \
            | (_LATCHED if self.latched else 0) | (fault << _FAULT_SHIFT)
        if u is not None and self.enabled and not stale and not fault:
            bits |= (int(u.state) + 1) << _STATE_SHIFT
            if u.valid and not bus_fault:
                bits |= _VALID
        return bits

    def snapshot(self, health: Health, *, scans: int, t_event: float, wall_time_s: float,
                 urgent: bool) -> NodeSnapshot:
        """The snapshot of this moment: a state is claimed only while enabled, fresh and
        free of a sensor fault (whose bits join the flags; the total force, made of
        held or frozen readings, is then none)."""
        u = self.update
        fault = health.fault
        age = health.frame_age_s
        stale = age is None or not age <= self.stale_s
        if u is None:
            return NodeSnapshot(None, False, self.enabled, self.latched, stale, health.bus_fault, False,
                                None, None, None, None, None, None, None, fault, age, self.slip_events,
                                self.state_changes, health.lost_scans, health.bus_errors, scans, self.method,
                                self.method_code, self.score_names, None, t_event, wall_time_s, urgent, None, False)
        if self.enabled and not stale and not fault:
            return NodeSnapshot(int(u.state), bool(u.valid) and not health.bus_fault, True, self.latched, False,
                                health.bus_fault, False, u.r_coe, u.r_dw, u.score_a, u.score_b, u.f_sum, u.xc, u.yc,
                                int(u.flags), age, self.slip_events, self.state_changes, health.lost_scans,
                                health.bus_errors, scans, self.method, self.method_code, self.score_names, u.t,
                                t_event, wall_time_s, urgent, int(u.state), bool(u.valid))
        return NodeSnapshot(None, False, self.enabled, self.latched, stale, health.bus_fault, False,
                            None, None, None, None, None if fault else u.f_sum, u.xc, u.yc, int(u.flags) | fault,
                            age, self.slip_events,
                            self.state_changes, health.lost_scans, health.bus_errors, scans, self.method,
                            self.method_code, self.score_names, u.t, t_event, wall_time_s, urgent, int(u.state),
                            bool(u.valid))

    def offline_snapshot(self, health: Health, *, scans: int, t_event: float, wall_time_s: float) -> NodeSnapshot:
        """The last snapshot of a bridge that stops, or of a node whose source ended:
        offline and stale (no scan will come), nothing claimed, no force, flags or frame
        age; the counts and the centre of force are kept."""
        u = self.update
        return NodeSnapshot(None, False, self.enabled, self.latched, True,
                            health.bus_fault, True, None, None, None, None, None,
                            None if u is None else u.xc, None if u is None else u.yc, 0, None, self.slip_events,
                            self.state_changes, health.lost_scans, health.bus_errors, scans, self.method,
                            self.method_code, self.score_names, None if u is None else u.t, t_event, wall_time_s,
                            True, None if u is None else int(u.state), False if u is None else bool(u.valid))
