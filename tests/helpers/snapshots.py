"""Node snapshots for tests: from a :class:`NodeStatus` as the loop makes them, or
built field by field for a sink that only reads them."""

from __future__ import annotations

from typing import Any

from eskin_industrial.node import Health, NodeSnapshot, NodeStatus

#: A 100 Hz node's stale limit (2.5 periods).
STALE_S = 0.025


def node_status(stale_s: float = STALE_S, method: str = "cof-track", code: int = 7,
                scores: tuple[str, str] = ("onset_score", "slow_score"), **kw: Any) -> NodeStatus:
    return NodeStatus(stale_s, method, code, scores, **kw)


def snapshot_of(status: NodeStatus, frame_age_s: float | None = 0.002, bus_fault: bool = False, lost_scans: int = 0,
                bus_errors: int = 0, *, urgent: bool = True, scans: int = 0, offline: bool = False) -> NodeSnapshot:
    """The snapshot the loop would publish now, with this health."""
    health = Health(frame_age_s, bus_fault, lost_scans, bus_errors)
    if offline:
        return status.offline_snapshot(health, scans=scans, t_event=0.0, wall_time_s=0.0)
    return status.snapshot(health, scans=scans, t_event=0.0, wall_time_s=0.0, urgent=urgent)


def made(**fields: Any) -> NodeSnapshot:
    """A snapshot with every field at a quiet default (a fresh, valid, stable grip)
    and ``fields`` as given."""
    base = dict(state=1, valid=True, enabled=True, slip_latched=False, stale=False, bus_fault=False, offline=False,
                r_coe=0.0, r_dw=0.0, score_a=0.0, score_b=0.0, f_sum_n=5.0, xc_mm=10.0, yc_mm=10.0, flags=0,
                frame_age_s=0.002, slip_events=0, state_changes=0, lost_scans=0, bus_errors=0, scans=0,
                method="cof-track", method_code=7, score_names=("onset_score", "slow_score"), t=0.0, t_event=0.0,
                wall_time_s=0.0, urgent=True, detected_state=1, detected_valid=True)
    base.update(fields)
    return NodeSnapshot(**base)


class StatusImage:
    """A node's status and its PLC register image, composed as the loop and the PLC
    output compose them: updates and commands in, registers out."""

    def __init__(self, settings: Any, stale_s: float = STALE_S, *, enabled: bool = True, method_code: int = 0) -> None:
        from eskin_industrial.outputs.plc.image import PlcImage

        self.status = NodeStatus(stale_s, "", method_code, enabled=enabled)
        self.image = PlcImage(settings)

    def observe(self, update: Any) -> bool:
        return self.status.observe(update)

    def apply(self, command: Any) -> None:
        self.status.apply(command)

    def snapshot(self, health: Health) -> NodeSnapshot:
        return self.status.snapshot(health, scans=0, t_event=0.0, wall_time_s=0.0, urgent=True)

    def render(self, health: Health) -> list[int]:
        return self.image.render(self.snapshot(health))

    def render_offline(self, health: Health) -> list[int]:
        return self.image.render(self.status.offline_snapshot(health, scans=0, t_event=0.0, wall_time_s=0.0))

    def values(self, health: Health) -> dict[str, int]:
        return self.image.values(self.snapshot(health))

    def offline_values(self, health: Health) -> dict[str, int]:
        return self.image.values(self.status.offline_snapshot(health, scans=0, t_event=0.0, wall_time_s=0.0))

    def bits(self, health: Health) -> int:
        """STATUS for this health, the heartbeat as it stands."""
        return self.image.status(self.snapshot(health))

    def refusal(self, command: Any) -> str | None:
        from eskin_industrial.node import refusal

        return refusal(command, self.snapshot(Health(0.0)))

    @property
    def tail(self) -> list[int]:
        return self.image.tail

    @property
    def heartbeat(self) -> int:
        return self.image.heartbeat

    def __getattr__(self, name: str) -> Any:  # enabled, latched, slip_events, state_changes, update
        return getattr(self.status, name)


def rendering_sink(settings: Any) -> Any:
    """A sink that renders every snapshot into the PLC's registers, as the PLC output
    does, and keeps them all (``published``) with the snapshots (``snapshots``)."""
    from eskin_industrial.outputs.plc.kept import KeptRegisters

    class Rendering(KeptRegisters):
        def __init__(self) -> None:
            super().__init__(settings)
            self.published: list[list[int]] = []
            self.snapshots: list[NodeSnapshot] = []

        def _publish(self, snapshot: NodeSnapshot) -> None:
            super()._publish(snapshot)
            assert self.registers is not None
            self.published.append(list(self.registers))
            self.snapshots.append(snapshot)

    return Rendering()
