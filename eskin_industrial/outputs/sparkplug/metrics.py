"""The metrics of a Sparkplug device (in alias order) and of the edge node, how a
node's snapshot reads as them, and their table in ``docs/plant.md``."""

from __future__ import annotations

import math
from typing import Any, NamedTuple

from ...detect.state import LABELS
from ...node import NodeSnapshot
from . import payload as pb
from .commands import COMMAND_ALIAS, COMMANDS

REBIRTH = "Node Control/Rebirth"


class MetricDef(NamedTuple):
    name: str
    datatype: int
    unit: str
    analog: bool  #: deadband and minimum interval (else: published at once on change)
    doc: str


#: The device metrics, in alias order (alias = device base + index).
DEVICE_METRICS: tuple[MetricDef, ...] = (
    MetricDef("State", pb.STRING, "", False, "no_contact, stable, variable_force, slip (STATE)"),
    MetricDef("State Code", pb.UINT8, "code", False, "0 no_contact, 1 stable, 2 variable_force, 3 slip"),
    MetricDef("Slip", pb.BOOLEAN, "", False, "slip now (STATUS bit SLIP)"),
    MetricDef("Slip Latched", pb.BOOLEAN, "", False, "a slip since the last acknowledge"),
    MetricDef("Data Valid", pb.BOOLEAN, "", False, "the state is a verdict"),
    MetricDef("Sensor Stale", pb.BOOLEAN, "", False, "no scan for longer than stale_s"),
    MetricDef("Bus Fault", pb.BOOLEAN, "", False, "the sensor bus fails"),
    MetricDef("Contact", pb.BOOLEAN, "", False, "total force at or above the contact threshold"),
    MetricDef("Enabled", pb.BOOLEAN, "", False, "detection enabled"),
    MetricDef("R_coe", pb.FLOAT, "", True, "the paper's R_coe, whatever method decides (0 while no state is claimed)"),
    MetricDef("R_dw", pb.FLOAT, "", True, "the paper's R_dw, whatever method decides (0 while no state is claimed)"),
    MetricDef("Total Force", pb.FLOAT, "N", True, "total force of the newest frame"),
    MetricDef("CoF X", pb.FLOAT, "mm", True, "centre of force, x"),
    MetricDef("CoF Y", pb.FLOAT, "mm", True, "centre of force, y"),
    # No UInt32: the specification carries it in int_value, Tahu's JavaScript codec and
    # hosts that followed Tahu before 2022 in long_value; UInt16 and UInt64 read alike
    # everywhere (docs/plant.md, A second host).
    MetricDef("Frame Age", pb.UINT16, "ms", True, "age of the newest frame, 65535 = none"),
    MetricDef("Counters/Slip Events", pb.UINT64, "count", True, "entries into slip since start"),
    MetricDef("Counters/State Changes", pb.UINT64, "count", True, "state changes since start"),
    MetricDef("Counters/Lost Scans", pb.UINT64, "count", True, "failed polls and sequence gaps"),
    MetricDef("Counters/Bus Errors", pb.UINT64, "count", True, "timeouts, CRC and exception responses"),
    MetricDef("Counters/Scans", pb.UINT64, "count", True, "scans the node's loop has taken since start"),
    MetricDef("Score A", pb.FLOAT, "", True, "the deciding method's first score (0 while no state is claimed); "
              "DBIRTH properties: method, score (its name), description"),
    MetricDef("Score B", pb.FLOAT, "", True, "the deciding method's second score, likewise"),
    MetricDef("Turn Unseen", pb.BOOLEAN, "", False, "in contact, but a turn about the normal would go unseen: "
              "read stable (FLAGS bit TURN_UNSEEN)"),
    MetricDef("Sensor Fault", pb.UINT16, "bits", False, "the sensor's faults (FLAGS bits DEAD_TAXELS 1024, FROZEN "
              "2048, RATE 4096, STREAM 8192; 0 none): while one is set no state is claimed and Data Valid is false"),
)
#: The taxel frame: declared (and sent) only with ``frame_interval_s``; its alias is
#: the device's base + :data:`FRAME_ALIAS`.
FRAME_METRIC = MetricDef("Taxels/Frame", pb.FLOAT_ARRAY, "N", False,
                         "the calibrated taxel frame, row-major (rows x cols), NaN for a refused reading")
FRAME_ALIAS = 50
#: The metric whose DBIRTH properties describe the method (``method_properties``) and
#: the one with the layout (``layout_properties``).
METHOD_METRIC, LAYOUT_METRIC = "State", "CoF X"
ANALOG = tuple(m.analog for m in DEVICE_METRICS)
ENABLED = next(i for i, m in enumerate(DEVICE_METRICS) if m.name == "Enabled")
#: ``Device Control/Enable`` (its alias offset) reads what ``Enabled`` reads, and changes with it.
ENABLE_COMMAND = COMMAND_ALIAS + next(i for i, c in enumerate(COMMANDS) if c.on_false is not None)
FLOATS = tuple(m.datatype == pb.FLOAT for m in DEVICE_METRICS)
#: Node metrics (aliases 1..); a device's metrics start at 1000 x (its index + 1).
NODE_METRICS = ("bdSeq", REBIRTH, "Node Info/Version", "Node Info/Uptime", "Store/Pending", "Store/Overflow")


def metric_values(s: NodeSnapshot) -> tuple[Any, ...]:
    """The device metrics of one snapshot, in :data:`DEVICE_METRICS` order.  While no
    state is claimed (disabled, stale), State reads ``no_contact`` (code 0), with Data
    Valid false, and the indicators and scores read 0, as the PLC's registers do."""
    code = 0 if s.state is None else s.state
    age = s.frame_age_s
    return (LABELS[code] if code < len(LABELS) else str(code), code, s.state == _SLIP, s.slip_latched, s.valid,
            s.stale, s.bus_fault, s.contact, s.enabled, _real(s.r_coe), _real(s.r_dw), _real(s.f_sum_n),
            _real(s.xc_mm), _real(s.yc_mm), _FRAME_AGE_NONE if age is None else min(_ms(age), _FRAME_AGE_NONE),
            s.slip_events, s.state_changes, s.lost_scans, s.bus_errors, s.scans, _real(s.score_a), _real(s.score_b),
            s.turn_unseen, s.sensor_fault)


_SLIP = 3  #: GraspState.SLIP
_FRAME_AGE_NONE = 0xFFFF  #: Frame Age when there is no scan (as the PLC's FRAME_AGE)


def _real(v: float | None) -> float:
    """A metric's float: 0 for none (no state claimed) and for a value that is not
    finite, so that a host never reads NaN as news at every publication."""
    return float(v) if v is not None and math.isfinite(v) else 0.0


def _ms(age_s: float) -> int:
    return round(age_s * 1000.0) if math.isfinite(age_s) else _FRAME_AGE_NONE


_TYPE_NAMES = {pb.INT8: "Int8", pb.INT16: "Int16", pb.INT32: "Int32", pb.INT64: "Int64", pb.UINT8: "UInt8",
               pb.UINT16: "UInt16", pb.UINT32: "UInt32", pb.UINT64: "UInt64", pb.FLOAT: "Float",
               pb.DOUBLE: "Double", pb.BOOLEAN: "Boolean", pb.STRING: "String", pb.FLOAT_ARRAY: "FloatArray"}


def metric_table() -> list[str]:
    """The device metric table of ``docs/plant.md`` (Markdown lines), from :data:`DEVICE_METRICS`."""
    rows = ["| alias | metric | datatype | unit | sent | meaning |", "|---|---|---|---|---|---|"]
    for i, m in enumerate(DEVICE_METRICS):
        sent = "deadband, min interval" if m.analog else "at once"
        rows.append(f"| base+{i} | `{m.name}` | {_TYPE_NAMES[m.datatype]} | {m.unit or '-'} | {sent} | {m.doc} |")
    m = FRAME_METRIC
    rows.append(f"| base+{FRAME_ALIAS} | `{m.name}` | {_TYPE_NAMES[m.datatype]} | {m.unit} | "
                f"every `frame_interval_s` (0: not declared) | {m.doc} |")
    for i, c in enumerate(COMMANDS):
        sent = "DBIRTH and DDATA (as `Enabled`); DCMD" if c.on_false is not None else "DBIRTH (false); DCMD"
        rows.append(f"| base+{COMMAND_ALIAS + i} | `{c.name}` | Boolean | - | {sent} | {c.doc} |")
    return rows
