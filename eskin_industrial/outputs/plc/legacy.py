"""The one place a node profile's ``[modbus.plc]`` still gives the PLC output's
settings: the keys that are the bridge configuration's ``[plc]`` now
(:data:`eskin_industrial.profile.PLC_MOVED_OUT`, deprecated in a profile, one warning
each at load) fall back to the profile's where ``[plc]`` (or ``--plc``) leaves them
unset, as they did before they moved.  Nothing else combines the two; the profile's
own keys of the register image (``base_address``, ``word_order``, ``r_scale``) pass
through unchanged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Literal

from ...profile import PLC_MOVED_OUT, ModbusPlcSection
from .options import PlcOptions

if TYPE_CHECKING:
    from ...seam import NodeLike

#: The ``[plc]`` keys a profile's ``[modbus.plc]`` may still give (``host`` is the
#: profile's ``bind`` in server mode: :func:`profile_key`).
FALLBACK_KEYS = tuple(dict.fromkeys(PLC_MOVED_OUT.values()))


def profile_key(key: str, mode: Literal["client", "server"]) -> str:
    """The profile's (dotted) key that ``[plc] key`` falls back to."""
    return "modbus.plc.bind" if key == "host" and mode == "server" else f"modbus.plc.{key}"


def plc_mode(options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> Literal["client", "server"]:
    mode = options.mode or nodes[0].profile.modbus.plc.mode
    return "client" if mode == "client" else "server"


def block_settings(options: PlcOptions, plc: ModbusPlcSection, mode: Literal["client", "server"]
                   ) -> ModbusPlcSection:
    """A node's block as the output runs it: its profile's ``[modbus.plc]`` with every
    key ``[plc]`` gives laid over it; ValueError ``key: what`` when the two together
    break a rule (``backoff_max_s`` below ``backoff_s``)."""
    given = {profile_key(k, mode).rpartition(".")[2]: getattr(options, k) for k in FALLBACK_KEYS
             if getattr(options, k) is not None}
    return replace(plc, **{**given, "mode": mode})


def serve_address(options: PlcOptions, nodes: Sequence[NodeLike[Any]]) -> tuple[str, int]:
    """Server mode over TCP: where to listen (``[plc]`` / ``--plc`` host and port, else
    the first node's profile's deprecated ``[modbus.plc] bind`` and ``port``)."""
    first = block_settings(options, nodes[0].profile.modbus.plc, "server")
    return first.bind, first.port


def explain_keys(mode: Literal["client", "server"]) -> dict[str, str]:
    """``[plc]`` key -> the profile key it falls back to, for ``--explain``."""
    return {k: profile_key(k, mode) for k in FALLBACK_KEYS}
