"""``eskin-bus profile dbc --config BRIDGE.toml``: one DBC for every CAN node of a bridge."""

from __future__ import annotations

from ..bridge.config import load_bridge_config, resolve
from ..bus.can.dbc import DbcNode, dbc_name, plant_dbc_text
from ..bus.can.layout import CanLayout
from ..bus.can.source import CanSource
from ..errors import ProfileError


def plant_dbc(config_path: str) -> str:
    """The DBC of the configuration's CAN nodes (live or from a log), each under its
    ``[[node]] name``, with the node's ``base_id``, ``node_id``, ``fd`` and rate."""
    config = load_bridge_config(config_path)
    nodes = [n for n in resolve(config) if issubclass(n.kind, CanSource)]
    if not nodes:
        raise ProfileError(f"{config_path}: [node]: no CAN node (source = \"can\" or \"can-log\") to describe")
    dbc_nodes = [DbcNode(dbc_name(n.name), n.profile, CanLayout.from_profile(n.profile, fd=n.kind.fd(n)), n.rate_hz)
                 for n in nodes]
    try:
        return plant_dbc_text(dbc_nodes)
    except ValueError as exc:
        raise ProfileError(f"{config_path}: [node] {exc}") from None
