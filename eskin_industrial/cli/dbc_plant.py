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
    dbc_nodes = []
    for n in resolve(config):
        kind = n.kind
        if issubclass(kind, CanSource):  # live or from a log: CAN frames either way
            layout = CanLayout.from_profile(n.profile, fd=kind.fd(n))
            dbc_nodes.append(DbcNode(dbc_name(n.name), n.profile, layout, n.rate_hz))
    if not dbc_nodes:
        raise ProfileError(f"{config_path}: [node]: no CAN node (source = \"can\" or \"can-log\") to describe")
    try:
        return plant_dbc_text(dbc_nodes)
    except ValueError as exc:
        raise ProfileError(f"{config_path}: [node] {exc}") from None
