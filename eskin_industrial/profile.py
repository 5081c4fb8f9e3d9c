"""Profiles: one TOML file describes one sensor installation; loaded here, once.

Loading validates everything into frozen dataclasses before anything starts.  A bad
file is refused with one line: ``FILE: [section] key: what was expected``.  The
sections, in the order of the data flow: ``[sensor]``, ``[layout]``,
``[calibration]``, ``[detector]``, and the transports ``[can]`` and ``[modbus]``.
See ``docs/profiles.md`` for every key.
"""

from __future__ import annotations

import tomllib
import warnings
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from pathlib import Path
from typing import Literal

import numpy as np

from .detect.settings import DetectorSettings
from .errors import DeprecatedKey, ProfileError
from .identity import DeviceIdentity
from .netaddr import check_host
from .schema import (
    SchemaError,
    in_range,
    ip_network,
    parse_toml,
    positive,
    positive_at_most,
    read_toml_file,
    to_table,
)

#: A sensor silent for this many scan periods is stale (the PLC must see it within three).
STALE_PERIODS = 2.5
#: ... but never less than this: the bridge's threads share one interpreter, which
#: switches between them every 5 ms (``sys.getswitchinterval()``), so a loop can take
#: a scan that long after it came and a 1 kHz node's 2.5 ms flagged a healthy sensor
#: stale now and then, each time a flicker of SENSOR_STALE and DATA_VALID for the PLC
#: (15 in 20 s for one node in a busy process: docs/benchmarks.md).  Four switch
#: intervals; from 125 Hz down the periods decide.
STALE_FLOOR_S = 0.02
#: The learnt stale limit's ceiling, in stale_s (``[output] stale_max_s``'s default).
STALE_MAX_FACTOR = 4.0

# Bounds of the settings, each in docs/profiles.md: past them a value is a typo or a
# unit mistake, and is refused before the run rather than met in it.
#: Scan and poll rates: a fast tactile ADC scans at a few kHz; below 1 Hz no window of
#: the detector holds two scans of a slip.
MAX_RATE_HZ = 100_000.0
MIN_RATE_HZ = 1.0
#: Taxels per node (64 x 64): a node's per-taxel arrays are sized from it at load.
MAX_TAXELS = 4096
#: RTU retries within one scan period.
MAX_RETRIES = 10
#: R x r_scale is sent as an integer up to 65535: beyond 10000 every slip saturates.
MAX_R_SCALE = 10_000.0
#: CAN bit rates: classic CAN ends at 1 Mbit/s (ISO 11898); an FD data phase at 8-16.
MAX_BITRATE_BPS = 1_000_000
MAX_DATA_BITRATE_BPS = 16_000_000
#: Samples in the detector's window and lag (10 s at 100 kHz): its buffers are sized
#: from them when it starts.
MAX_WINDOW_SAMPLES = 1_000_000
#: Taxel coordinates and pitches (mm): a skin larger than 10 m is a unit mistake, and
#: squares of coordinates must stay far inside a float's range.
MAX_COORD_MM = 10_000.0
#: A reading in the node's raw unit (ohm, ADC counts, N): zero and per_newton up to 1e12.
MAX_RAW = 1e12
#: ... and per_newton at least this in magnitude (a slope of 1e-300 makes every reading
#: a meganewton).
MIN_SLOPE = 1e-9


#: ``[detector]``'s own keys and sections; any other section is a plug-in method's.
_DETECTOR_KEYS = frozenset(f.name for f in fields(DetectorSettings))


def derived_stale_s(rate_hz: float, poll_hz: float | None) -> float:
    """The default ``[output] stale_s``: 2.5 periods of the slower of the scan rate
    and the RTU poll rate, at least :data:`STALE_FLOOR_S`."""
    return max(STALE_PERIODS / min(rate_hz, poll_hz or rate_hz), STALE_FLOOR_S)


@dataclass(frozen=True)
class SensorSection:
    name: str
    description: str = ""
    #: Nominal scan rate; offline input takes its rate from the timestamps instead.
    rate_hz: float = field(default=100.0, metadata=in_range(MIN_RATE_HZ, MAX_RATE_HZ))


@dataclass(frozen=True)
class LayoutSection:
    rows: int = field(metadata=positive("an integer >= 1"))
    cols: int = field(metadata=positive("an integer >= 1"))
    #: Distance between neighbouring taxels along a row (x) and, unless
    #: ``row_pitch_mm`` is given, between rows (y).
    pitch_mm: float = field(metadata=in_range(0.01, 1000.0))
    row_pitch_mm: float | None = field(default=None, metadata=in_range(0.01, 1000.0))
    #: Explicit taxel coordinates, row-major, one per taxel; default: the grid.
    x_mm: tuple[float, ...] | None = field(default=None, metadata=in_range(-MAX_COORD_MM, MAX_COORD_MM))
    y_mm: tuple[float, ...] | None = field(default=None, metadata=in_range(-MAX_COORD_MM, MAX_COORD_MM))
    #: Names of the rows when each row is a separate strip (the hand's fingers).
    row_names: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        n = self.rows * self.cols
        if n > MAX_TAXELS:  # before anything is sized from it (coordinates, calibration)
            raise ValueError(f"rows: expected rows x cols at most {MAX_TAXELS} taxels, got {self.rows} x {self.cols}")
        for key in ("x_mm", "y_mm"):
            value = getattr(self, key)
            if value is not None and len(value) != n:
                raise ValueError(f"{key}: expected {n} coordinates (rows x cols), got {len(value)}")
        if self.row_names is not None and len(self.row_names) != self.rows:
            raise ValueError(f"row_names: expected {self.rows} names (one per row), got {len(self.row_names)}")

    @property
    def taxels(self) -> int:
        return self.rows * self.cols

    def coordinates_mm(self) -> tuple[np.ndarray, np.ndarray]:
        """x and y of each taxel in mm, row-major (row r, column c -> index r*cols+c)."""
        rows, cols = np.divmod(np.arange(self.taxels), self.cols)
        row_pitch = self.row_pitch_mm if self.row_pitch_mm is not None else self.pitch_mm
        x = np.asarray(self.x_mm, dtype=np.float64) if self.x_mm is not None else cols * self.pitch_mm
        y = np.asarray(self.y_mm, dtype=np.float64) if self.y_mm is not None else rows * row_pitch
        return x.astype(np.float64), y.astype(np.float64)


@dataclass(frozen=True)
class TaxelCalibration:
    zero: float | None = field(default=None, metadata=in_range(-MAX_RAW, MAX_RAW))
    per_newton: float | None = field(default=None, metadata=in_range(-MAX_RAW, MAX_RAW))

    def __post_init__(self) -> None:
        if self.per_newton == 0:
            raise ValueError("per_newton: expected a non-zero slope, got 0")


@dataclass(frozen=True)
class CalibrationSection:
    #: What the node reports: resistance, ADC counts, or forces already in newtons.
    raw_unit: Literal["ohm", "adc_counts", "newton"]
    #: Reading at 0 N in ``raw_unit``: one number, or one per taxel (row-major).
    zero: float | tuple[float, ...] = field(metadata=in_range(-MAX_RAW, MAX_RAW))
    #: Change of the reading per newton: one number, or one per taxel.
    per_newton: float | tuple[float, ...] = field(metadata=in_range(-MAX_RAW, MAX_RAW))
    #: raw value x raw_scale = reading in ``raw_unit`` (e.g. 0.1 ohm per LSB).
    raw_scale: float = field(default=1.0, metadata=in_range(1e-09, 1000000000.0))
    #: Readings outside [valid_min, valid_max] (after scaling) are invalid.
    valid_min: float = field(default=-1e300, metadata=in_range(-1e300, 1e300))
    valid_max: float = field(default=1e300, metadata=in_range(-1e300, 1e300))
    #: Forces at or above this are flagged saturated and clipped.
    full_scale_n: float = field(default=1e300, metadata=in_range(1e-06, 1e+300))
    #: Per-taxel corrections keyed by the taxel's row-major index: {"7" = {zero = ...}}.
    overrides: dict[str, TaxelCalibration] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for key in ("zero", "per_newton"):
            if isinstance(getattr(self, key), tuple) and len(getattr(self, key)) == 0:
                raise ValueError(f"{key}: expected a number or one number per taxel, got an empty list")
        slopes = self.per_newton if isinstance(self.per_newton, tuple) else (self.per_newton,)
        if any(s == 0 for s in slopes):
            raise ValueError("per_newton: expected non-zero slopes, got 0")
        if any(abs(s) < MIN_SLOPE for s in slopes):
            raise ValueError(f"per_newton: expected slopes of at least {MIN_SLOPE:g} raw units per newton in "
                             f"magnitude, got {min(slopes, key=abs):g}")
        if self.valid_min >= self.valid_max:
            raise ValueError("valid_min: expected valid_min < valid_max")
        for index in self.overrides:
            if not index.isdigit():
                raise ValueError(f"overrides: expected taxel indices such as \"7\" as keys, got {index!r}")


@dataclass(frozen=True)
class CanSection:
    """How the node's scans travel over CAN (frame layout in ``docs/can.md``).

    A node owns 16 arbitration IDs from ``base_id``: its data segments from
    ``base_id`` up, its heartbeat at ``base_id + 15``.
    """

    #: The node's number, carried in its heartbeat (and checked by the receiver).
    node_id: int = field(default=1, metadata=in_range(0, 255))
    #: First arbitration ID of the node's range.
    base_id: int = field(default=0x200, metadata=in_range(0, 0x1FFFFFFF))
    #: 29-bit identifiers instead of 11-bit ones.
    extended_id: bool = False
    #: Bits per taxel on the wire; the raw values up to ``[calibration] valid_max``
    #: (in raw units) must fit, or the layout is refused.
    taxel_bits: Literal[12, 16] = 12
    #: Byte order of the header and the taxel values in each frame.
    byte_order: Literal["little", "big"] = "little"
    #: One CAN FD frame per scan (with bit-rate switching) instead of classic segments.
    fd: bool = False
    bitrate_bps: int = field(default=1_000_000, metadata=positive_at_most(MAX_BITRATE_BPS, "an integer"))
    #: Data-phase bit rate of CAN FD frames.
    data_bitrate_bps: int = field(default=5_000_000, metadata=positive_at_most(MAX_DATA_BITRATE_BPS, "an integer"))
    #: Period of the node's heartbeat (status) frame.
    heartbeat_s: float = field(default=0.1, metadata=in_range(0.001, 60.0))

    def __post_init__(self) -> None:
        top = 0x1FFFFFFF if self.extended_id else 0x7FF
        if self.base_id + 15 > top:
            raise ValueError(f"base_id: expected at most {top - 15:#x} (the node uses base_id .. base_id + 15 "
                             f"and {'29' if self.extended_id else '11'}-bit IDs end at {top:#x}), got {self.base_id:#x}")
        if self.data_bitrate_bps < self.bitrate_bps:
            raise ValueError("data_bitrate_bps: expected at least bitrate_bps")


@dataclass(frozen=True)
class ModbusNodeSection:
    """The sensor node as a Modbus RTU slave, polled by the bridge (``docs/plc.md``).

    One read of ``taxels x words`` registers from ``start_address`` (0-based
    protocol address) is one scan, row-major; each value is the calibration's raw
    value (``[calibration] raw_scale`` turns it into the raw unit).
    """

    unit_id: int = field(default=1, metadata=in_range(1, 247))
    #: 4 = read input registers, 3 = read holding registers.
    function: Literal[3, 4] = 4
    start_address: int = field(default=0, metadata=in_range(0, 65535))
    #: How one taxel is encoded: 16-bit, or 32-bit over two registers.
    value_type: Literal["uint16", "int16", "uint32", "int32"] = "uint16"
    #: For 32-bit values: which register holds the high word.
    word_order: Literal["big", "little"] = "big"
    baudrate: int = field(default=115200, metadata=in_range(300, 10000000))
    parity: Literal["N", "E", "O"] = "N"
    stopbits: Literal[1, 2] = 1
    #: How long to wait for an answer before the poll counts as a timeout.
    timeout_s: float = field(default=0.05, metadata=in_range(0.001, 10.0))
    #: Further attempts after a failed poll, within the same scan period.
    retries: int = field(default=1, metadata=in_range(0, MAX_RETRIES))
    #: Poll rate; default: the sensor's ``rate_hz``.
    poll_hz: float | None = field(default=None, metadata=in_range(MIN_RATE_HZ, MAX_RATE_HZ))
    #: Consecutive failed polls after which the bus-fault bit is set.
    fault_after_failures: int = field(default=3, metadata=in_range(1, 1000000))
    #: The node keeps its scan counter (uint16, wrapping) in the register before the
    #: taxels: scans are then timed on the node's clock (counter / rate_hz), a scan
    #: polled twice is used once, and skipped scans count as lost.
    counter_register: bool = False
    #: Without a scan counter: an answer bit-identical to the one before is the node's
    #: scan polled again (dropped: a scan is used once) while it comes within this of
    #: the first of them; later, the node has scanned since and the answer is replayed
    #: (a man in the middle, a gateway's cache): FLAGS STREAM, no verdict until a
    #: different answer.  A live array's noise never repeats a scan to the bit.
    #: Default: 1.5 scan periods of ``[sensor] rate_hz``; 0: every repeat is a replay.
    repeat_s: float | None = field(default=None, metadata=in_range(0.0, 60.0))

    @property
    def words_per_taxel(self) -> int:
        return 2 if self.value_type.endswith("32") else 1


#: ``[modbus.plc.identity]`` of earlier releases: the bridge configuration's
#: ``[identity]`` now (:mod:`eskin_industrial.identity`); still read, with a warning.
DeviceIdentitySection = DeviceIdentity


@dataclass(frozen=True)
class ModbusPlcSection:
    """The node's register block as the PLC sees it (``base_address``, ``word_order``,
    ``r_scale``), and the PLC output's settings as a profile of earlier releases gave
    them (:data:`PLC_MOVED_OUT`, ``identity``: deprecated here, the bridge
    configuration's ``[plc]`` and ``[identity]`` now); the PLC output lays its
    ``[plc]`` over them (``eskin_industrial/outputs/plc/legacy.py``)."""

    #: ``client``: the bridge writes into the PLC's holding registers;
    #: ``server``: the bridge serves the registers and the PLC reads them.
    mode: Literal["client", "server"] = "server"
    unit_id: int = field(default=1, metadata=in_range(0, 255))
    #: 0-based protocol address of the first register (and of the first coil and
    #: discrete input); 4xxxx number = base_address + offset + 40001.
    base_address: int = field(default=0, metadata=in_range(0, 65000))
    #: For 32-bit values: which register holds the high word.
    word_order: Literal["big", "little"] = "big"
    #: Client mode: the PLC's address.
    host: str = "127.0.0.1"
    port: int = field(default=502, metadata=in_range(1, 65535))
    #: Client mode: the delay after a failed connection or write (refused, reset, no
    #: answer, an exception reply), doubled after each failure up to the maximum.
    backoff_s: float = field(default=0.1, metadata=in_range(0.01, 60))
    backoff_max_s: float = field(default=2.0, metadata=in_range(0.01, 600))
    #: Client mode: how long the PLC has to answer a request (an answer up to as long
    #: again is still taken, and counted as late).
    timeout_s: float = field(default=0.5, metadata=in_range(0.01, 30))
    #: Server mode: the address to listen on (loopback unless told otherwise).
    bind: str = "127.0.0.1"
    #: Server mode over TCP: client connections at once (beyond: see docs/operations.md),
    #: and how long one may stay quiet before it is closed.
    max_connections: int = field(default=8, metadata=in_range(1, 1024))
    idle_timeout_s: float = field(default=60.0, metadata=in_range(0.1, 86400))
    #: Server mode over TCP: the client addresses or networks that may connect and
    #: read, and those that may write (empty: any).
    allow_read: tuple[str, ...] = field(default=(), metadata=ip_network())
    allow_write: tuple[str, ...] = field(default=(), metadata=ip_network())
    #: Server mode: every write refused (exception 01): no command from the PLC.
    read_only: bool = False
    #: Server mode over TCP: the unit ids answered (empty: ``unit_id``, 0 and 255).
    unit_ids: tuple[int, ...] = field(default=(), metadata=in_range(0, 255))
    identity: DeviceIdentitySection = field(default_factory=DeviceIdentitySection)
    #: R_coe and R_dw are sent as round(R x r_scale), saturated at 65535.
    r_scale: float = field(default=100.0, metadata=in_range(0.001, MAX_R_SCALE))

    def __post_init__(self) -> None:
        if self.backoff_max_s < self.backoff_s:
            raise ValueError("backoff_max_s: expected at least backoff_s")
        check_host(self.host, "host")
        check_host(self.bind, "bind")


@dataclass(frozen=True)
class OutputSection:
    """How every output sees this node (the PLC, Sparkplug, a recorder alike)."""

    #: A snapshot is published at every change of the state or of a health condition,
    #: and every ``refresh_s`` when nothing changes (a PLC in client mode is written
    #: that often; a heartbeat advances).
    refresh_s: float = field(default=0.05, metadata=in_range(0.001, 60.0))
    #: The newest scan older than this makes the sensor stale: no state is claimed and
    #: no verdict is valid.  Default: 2.5 scan periods (of the slower of ``[sensor]
    #: rate_hz`` and ``[modbus.node] poll_hz``), so a silent sensor shows within three.
    stale_s: float | None = field(default=None, metadata=in_range(0.001, 3600.0))
    #: The stale limit learns the sensor's arrivals (``node/staleness.py``): it rises to
    #: 1.5 times the longest interval between scans seen lately, never above this.
    #: Default: 4 x ``stale_s``; equal to ``stale_s``: a fixed limit.
    stale_max_s: float | None = field(default=None, metadata=in_range(0.001, 3600.0))
    #: A sensor fault makes the state no verdict (``docs/plc.md``, FLAGS bits 10-12).
    #: An invalid reading (open line, short, NaN) is replaced by the taxel's last good
    #: value for at most ``hold_s`` (on the sensor's clock), and in at most
    #: ``hold_share`` of the taxels at once; beyond either: DEAD_TAXELS.
    hold_s: float = field(default=0.25, metadata=in_range(0.0, 60.0))
    hold_share: float = field(default=0.25, metadata=in_range(0.0, 1.0))
    #: Raw scans identical to the bit for longer than this: FROZEN (0: not judged).
    frozen_s: float = field(default=0.5, metadata=in_range(0.0, 3600.0))
    #: The scans' timestamps showing a rate more than this factor from the detector's:
    #: RATE (0: not judged).
    rate_tolerance: float = field(default=2.0, metadata=in_range(0.0, 100.0))

    def __post_init__(self) -> None:
        if 0 < self.rate_tolerance < 1.1:
            raise ValueError("rate_tolerance: expected 0 (not judged) or a factor of at least 1.1, "
                             f"got {self.rate_tolerance:g}")


#: Keys that moved, old dotted path -> new one: still read, with a warning.
MOVED_KEYS: dict[str, str] = {
    "modbus.plc.refresh_s": "output.refresh_s",
    "modbus.plc.stale_s": "output.stale_s",
}


@dataclass(frozen=True)
class ModbusSection:
    node: ModbusNodeSection = field(default_factory=ModbusNodeSection)
    plc: ModbusPlcSection = field(default_factory=ModbusPlcSection)


@dataclass(frozen=True)
class Profile:
    sensor: SensorSection
    layout: LayoutSection
    calibration: CalibrationSection
    detector: DetectorSettings = field(default_factory=DetectorSettings)
    can: CanSection = field(default_factory=CanSection)
    modbus: ModbusSection = field(default_factory=ModbusSection)
    output: OutputSection = field(default_factory=OutputSection)
    #: The file it came from, for messages (not a TOML key).
    source: str = field(default="<profile>", init=False, compare=False)

    def __post_init__(self) -> None:
        n = self.layout.taxels
        cal = self.calibration
        for key in ("zero", "per_newton"):
            value = getattr(cal, key)
            if isinstance(value, tuple) and len(value) != n:
                raise SchemaError(
                    f"calibration.{key}",
                    f"expected 1 or {n} entries ({self.layout.rows}x{self.layout.cols} layout), got {len(value)}",
                )
        for index in cal.overrides:
            if int(index) >= n:
                raise SchemaError(f"calibration.overrides.{index}", f"expected a taxel index below {n}")
        from .methods import get_method, method_names  # the registry imports detectors, not profiles

        if self.detector.method not in (known := method_names()):
            raise SchemaError("detector.method", f"expected one of {', '.join(sorted(known))}, got {self.detector.method!r}")
        method = get_method(self.detector.method)
        if method.settings is not None and method.key and method.key not in _DETECTOR_KEYS \
                and method.key not in dict(self.detector.plugins):
            # a plug-in's section the file leaves out: its defaults, shown and published like a built-in's
            det = self.detector.with_section(method.key, method.settings_of(self.detector))
            object.__setattr__(self, "detector", det)
        try:
            geo = self.detector.geometry(self.sensor.rate_hz)
        except (ValueError, OverflowError):
            # Finite but huge times x rate overflow when they become sample counts; name
            # the rate rather than let the arithmetic error out unlabelled.
            raise SchemaError(
                "sensor.rate_hz", f"expected a rate at which the detector's times are countable samples, "
                f"got {self.sensor.rate_hz:g} Hz (window_s = {self.detector.window_s:g}, hop_s = "
                f"{self.detector.hop_s:g}, max_gap_s = {self.detector.max_gap_s:g})") from None
        for key, samples in (("window_s", geo.window), ("lag_s", geo.lag)):
            if samples > MAX_WINDOW_SAMPLES:
                raise SchemaError(f"detector.{key}", f"expected at most {MAX_WINDOW_SAMPLES} samples at "
                                  f"{self.sensor.rate_hz:g} Hz, got {getattr(self.detector, key):g} s ({samples} samples)")
        if geo.window < geo.filter_len:
            raise SchemaError(
                "detector.window_s",
                f"expected a window of at least {geo.filter_len} samples at {self.sensor.rate_hz:g} Hz "
                f"(the {self.detector.wavelet} filter length), got {geo.window}",
            )

        if self.output.stale_s is None:
            # Resolved here, once, so every consumer reads a number.
            out = replace(self.output, stale_s=derived_stale_s(self.sensor.rate_hz, self.modbus.node.poll_hz))
            object.__setattr__(self, "output", out)
        if self.output.stale_max_s is None:
            object.__setattr__(self, "output", replace(self.output, stale_max_s=STALE_MAX_FACTOR * self.stale_s))
        elif self.output.stale_max_s < self.stale_s:
            raise SchemaError("output.stale_max_s", f"expected at least stale_s ({self.stale_s:g} s), "
                                                    f"got {self.output.stale_max_s:g}")

    @property
    def stale_s(self) -> float:
        """``[output] stale_s``, resolved (a number once loaded)."""
        stale = self.output.stale_s
        assert stale is not None  # resolved in __post_init__
        return stale

    @property
    def stale_max_s(self) -> float:
        """``[output] stale_max_s``, resolved."""
        stale_max = self.output.stale_max_s
        assert stale_max is not None  # resolved in __post_init__
        return stale_max

    @property
    def name(self) -> str:
        return self.sensor.name

    @property
    def taxels(self) -> int:
        return self.layout.taxels

    @cached_property
    def coordinates_mm(self) -> tuple[np.ndarray, np.ndarray]:
        return self.layout.coordinates_mm()

    def to_table(self) -> dict:
        """Every key as loaded, defaults filled in, but for the PLC's connection and the
        device identity (the bridge configuration's now): only those a profile of
        earlier releases set otherwise, so that the table read back warns as its file did."""
        table = to_table(self)
        plc, default = table["modbus"]["plc"], ModbusPlcSection()
        for key in PLC_MOVED_OUT:
            if getattr(self.modbus.plc, key) == getattr(default, key):
                del plc[key]
        ident = plc["identity"]
        for key in list(ident):
            if getattr(self.modbus.plc.identity, key) == getattr(default.identity, key):
                del ident[key]
        if not ident:
            del plc["identity"]
        return table


#: The profiles shipped inside the package (package data): ``-p paper-5x5`` names one.
BUILTIN_DIR = Path(__file__).resolve().parent / "data" / "profiles"


def builtin_profiles() -> dict[str, Path]:
    """The shipped profiles by name (the file's stem), sorted."""
    return {p.stem: p for p in sorted(BUILTIN_DIR.glob("*.toml"))}


def find_profile(name_or_path: str | Path, base: Path | None = None) -> Path:
    """A profile's file.  A bare name (no folder, no ``.toml``) that is no file names a
    built-in profile (``paper-5x5``); anything else is a path, relative to ``base`` when
    given, else to the working directory, and its read error names it."""
    path = Path(name_or_path)
    here = path if path.is_absolute() or base is None else base / path
    if here.exists() or path.parent != Path(".") or path.suffix == ".toml":
        return here
    builtin = builtin_profiles().get(path.name)
    if builtin is not None:
        return builtin
    known = ", ".join(builtin_profiles()) or "none"
    raise ProfileError(f"{here}: no such profile file, and not a built-in profile (built-in: {known})")


def load_profile(path: str | Path, base: Path | None = None) -> Profile:
    """Read and validate a profile (a path, or a built-in name: :func:`find_profile`);
    :class:`ProfileError` names the file and the key."""
    found = find_profile(path, base)
    text = read_toml_file(found, "profile")
    return parse_profile(text, str(found))


#: ``[modbus.plc]`` keys of earlier releases that are the PLC output's, set in the
#: bridge configuration's ``[plc]`` now (profile key -> ``[plc]`` key; ``bind`` is
#: where server mode listens, ``[plc] host``).  Still read into the profile, and used
#: where ``[plc]`` leaves them unset, with one warning per key.  The keys of the
#: register image stay the profile's (``base_address``, ``word_order``, ``r_scale``:
#: ``eskin-bus plc map`` and ``plc export`` make the PLC's side from a profile alone).
PLC_MOVED_OUT: dict[str, str] = {
    "mode": "mode", "unit_id": "unit_id", "host": "host", "port": "port", "bind": "host",
    "timeout_s": "timeout_s", "backoff_s": "backoff_s", "backoff_max_s": "backoff_max_s",
    "max_connections": "max_connections", "idle_timeout_s": "idle_timeout_s", "allow_read": "allow_read",
    "allow_write": "allow_write", "read_only": "read_only", "unit_ids": "unit_ids",
}
#: ``[modbus.plc.identity]`` of earlier releases: the bridge configuration's ``[identity]``.
IDENTITY_MOVED_OUT = "identity"
_ELSEWHERE = "in the bridge configuration (bridge.toml)"


def moved_out(text: str) -> list[tuple[str, str]]:
    """(old place, new place) of each key the profile's text gives that is the bridge
    configuration's now, both spelled as in a file (``[modbus.plc] port``, ``[plc] port``);
    a text that is no TOML gives none (parse_toml reports it)."""
    try:
        plc = tomllib.loads(text).get("modbus", {}).get("plc", {})
    except (tomllib.TOMLDecodeError, AttributeError):
        return []
    if not isinstance(plc, dict):
        return []
    out = [(f"[modbus.plc] {k}", f"[plc] {PLC_MOVED_OUT[k]}") for k in plc if k in PLC_MOVED_OUT]
    ident = plc.get("identity")
    if isinstance(ident, dict):
        out += [(f"[modbus.plc.identity] {k}", f"[{IDENTITY_MOVED_OUT}] {k}") for k in ident]
    return out


def _warn_moved_out(text: str, source: str) -> None:
    """One :class:`DeprecatedKey` line for each key :func:`moved_out` finds."""
    for old, new in moved_out(text):
        warnings.warn(DeprecatedKey(f"{source}: {old} is deprecated: write {new} {_ELSEWHERE}"), stacklevel=3)


def parse_profile(text: str, source: str = "<profile>") -> Profile:
    from .methods import section_class  # (a plug-in method's [detector.<key>])

    _warn_moved_out(text, source)
    profile = parse_toml(Profile, text, source, MOVED_KEYS, section_class)
    object.__setattr__(profile, "source", source)
    return profile
