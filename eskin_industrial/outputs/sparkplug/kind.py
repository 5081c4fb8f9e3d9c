"""Sparkplug B 3.0 on MQTT as an output kind (``[sparkplug]`` in the bridge
configuration, ``--sparkplug mqtt://HOST:PORT`` on the command line).

The bridge process is one edge node (``group_id``, ``edge_node_id``) over one MQTT
connection; each sensor node is a device named after the node.  The metrics are the
node's snapshot (:class:`~eskin_industrial.node.NodeSnapshot`), the same the PLC's
register image is rendered from, so that the plant and the PLC see the same state.

The parts: the settings (:mod:`.options`), the metrics (:mod:`.metrics`), the MQTT
session (:mod:`.edge`), each node's device, its sink (:mod:`.device`).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import ProfileError
from ...schema import SchemaError, build
from ..base import CliOption, OutputKind, Sink
from .bdseq import bdseq_path, writable
from .device import SparkplugDevice
from .edge import NAMESPACE, EdgeNode
from .metrics import FRAME_METRIC, LAYOUT_METRIC, METHOD_METRIC
from .options import SparkplugOptions, check_id, nonconforming
from .properties import Property, frame_properties, layout_properties, method_properties, score_properties
from .transport import check_files, configure, parse_broker

if TYPE_CHECKING:
    from ...seam import NodeLike, OpenContext


class SparkplugKind(OutputKind[SparkplugOptions]):
    """The output kind "sparkplug": one edge node for the bridge, one
    :class:`SparkplugDevice` per node."""

    name = "sparkplug"
    Options = SparkplugOptions
    #: paho's network thread (``paho-mqtt-client-GROUP-EDGE``) is this output's.
    thread_names = ("paho-mqtt-client-",)
    cli_options = (
        CliOption("--sparkplug", "sparkplug", "Publish as a Sparkplug B edge node to this MQTT broker "
                  "(mqtt://HOST:PORT, or mqtts:// for TLS); needs --group-id and --edge-node-id.", metavar="URL"),
        CliOption("--group-id", "group_id", "Sparkplug group id (with --sparkplug).", metavar="ID"),
        CliOption("--edge-node-id", "edge_node_id", "Sparkplug edge node id (with --sparkplug).", metavar="ID"),
        CliOption("--sparkplug-nonconforming-qos1", "sparkplug_nonconforming_qos1", "Publish births, data and "
                  "DDEATH at MQTT QoS 1, against the specification's QoS 0 (a strict host may reject the node).",
                  type=bool),
        CliOption("--sparkplug-keepalive", "sparkplug_keepalive_s", "MQTT keepalive, seconds.", type=int,
                  metavar="S"),
        CliOption("--sparkplug-deadband", "sparkplug_deadband", "An analog metric is sent when it moved by more "
                  "than this, in its own unit (default 0.01).", type=float, metavar="X"),
        CliOption("--sparkplug-min-interval", "sparkplug_min_interval_s", "An analog metric is sent at most this "
                  "often, seconds (default 0.5; a state change goes at once).", type=float, metavar="S"),
        CliOption("--sparkplug-reconnect-min", "sparkplug_reconnect_min_s", "Back-off between connection "
                  "attempts, from this (seconds, default 0.2) ...", type=float, metavar="S"),
        CliOption("--sparkplug-reconnect-max", "sparkplug_reconnect_max_s", "... doubling up to this (seconds, "
                  "default 5).", type=float, metavar="S"),
        CliOption("--sparkplug-frame-interval", "sparkplug_frame_interval_s", "Publish each node's calibrated "
                  "taxel frame (metric Taxels/Frame, a FloatArray) at most this often, seconds (default 0: off).",
                  type=float, metavar="S"),
        CliOption("--sparkplug-store-dir", "sparkplug_store_dir", "Folder of the on-disk queue of the data "
                  "messages of a broker outage (default: in memory).", metavar="DIR"),
        CliOption("--sparkplug-store-max", "sparkplug_store_max", "Data messages held at most during an "
                  "outage (the rest are counted).", type=int, metavar="N"),
        CliOption("--sparkplug-ca-file", "sparkplug_ca_file", "mqtts: CA certificates (PEM) of the broker's "
                  "certificate (default: the system's).", metavar="FILE"),
        CliOption("--sparkplug-cert-file", "sparkplug_cert_file", "mqtts: client certificate (PEM), with "
                  "--sparkplug-key-file.", metavar="FILE"),
        CliOption("--sparkplug-key-file", "sparkplug_key_file", "mqtts: the client certificate's key (PEM).",
                  metavar="FILE"),
        CliOption("--sparkplug-primary-host", "sparkplug_primary_host_id", "Publish only while this Sparkplug "
                  "primary host application is online (its STATE topic).", metavar="ID"),
        CliOption("--sparkplug-state-future", "sparkplug_state_future_s", "A primary host's STATE stamped more "
                  "than this ahead of this host's clock is refused, seconds (default 60).", type=float, metavar="S"),
        CliOption("--sparkplug-rebirth-interval", "sparkplug_rebirth_min_interval_s", "At most one rebirth in "
                  "this time; the requests within it get one at its end, seconds (default 1).", type=float,
                  metavar="S"),
        CliOption("--sparkplug-command-rate", "sparkplug_command_rate", "NCMDs and each device's DCMDs taken at "
                  "most this many a second; past it dropped undecoded and counted (default 100).", type=float,
                  metavar="N"),
        CliOption("--sparkplug-username", "sparkplug_username", "MQTT username.", metavar="NAME"),
        CliOption("--sparkplug-password-file", "sparkplug_password_file", "MQTT password: the first line of "
                  "this file (no password option takes the secret itself).", metavar="FILE"),
        CliOption("--sparkplug-password-env", "sparkplug_password_env", "MQTT password: this environment "
                  "variable.", metavar="NAME"),
    )
    #: ``--sparkplug-*`` option -> the ``[sparkplug]`` key it sets.
    _CLI_KEYS = {"sparkplug_nonconforming_qos1": "nonconforming_qos1", "sparkplug_keepalive_s": "keepalive_s",
                 "sparkplug_deadband": "deadband", "sparkplug_min_interval_s": "min_interval_s",
                 "sparkplug_reconnect_min_s": "reconnect_min_s", "sparkplug_reconnect_max_s": "reconnect_max_s",
                 "sparkplug_frame_interval_s": "frame_interval_s",
                 "sparkplug_store_dir": "store_dir", "sparkplug_store_max": "store_max",
                 "sparkplug_ca_file": "ca_file", "sparkplug_cert_file": "cert_file", "sparkplug_key_file": "key_file",
                 "sparkplug_username": "username", "sparkplug_primary_host_id": "primary_host_id", "sparkplug_password_file": "password_file",
                 "sparkplug_state_future_s": "state_future_s",
                 "sparkplug_rebirth_min_interval_s": "rebirth_min_interval_s",
                 "sparkplug_command_rate": "command_rate",
                 "sparkplug_password_env": "password_env"}

    @classmethod
    def options_from_cli(cls, values: dict[str, Any]) -> SparkplugOptions | None:
        url = values.get("sparkplug")
        # (a flag not given reads False: not given either)
        extra = {key: values[dest] for dest, key in cls._CLI_KEYS.items() if values.get(dest) not in (None, False)}
        if url is None:
            given = [o.flag for o in cls.cli_options[1:] if values.get(o.dest) not in (None, False)]
            if given:
                raise ValueError(f"{'/'.join(given)}: give --sparkplug URL too")
            return None
        if not values.get("group_id") or not values.get("edge_node_id"):
            raise ValueError("give --group-id and --edge-node-id with --sparkplug")
        flags = {cls._CLI_KEYS[o.dest]: o.flag for o in cls.cli_options if o.dest in cls._CLI_KEYS}
        try:
            return build(SparkplugOptions, {"broker": url, "group_id": values["group_id"],
                                            "edge_node_id": values["edge_node_id"], **extra})
        except SchemaError as exc:  # the flag, not the key, in the one line
            raise ValueError(f"{flags.get(exc.key, exc.key)}: {exc.message}") from None
        except ValueError as exc:  # a rule across keys: named by its first key
            key, sep, rest = str(exc).partition(": ")
            raise ValueError(f"{flags[key]}: {rest}" if sep and key in flags else str(exc)) from None

    @classmethod
    def describe(cls, options: SparkplugOptions, node: NodeLike[Any]) -> str:
        host, port, _ = parse_broker(options.broker)
        frames = (f", {FRAME_METRIC.name} every {options.frame_interval_s:g} s ({node.profile.layout.rows} x "
                  f"{node.profile.layout.cols})" if options.frame_interval_s else "")
        return (f"Sparkplug B {NAMESPACE}/{options.group_id}/DDATA/{options.edge_node_id}/{node.name} at "
                f"{host}:{port}{frames}")

    @classmethod
    def check(cls, options: SparkplugOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        seen: dict[str, str] = {}
        for n in nodes:
            check_id("device id (node name)", n.name)
            other = seen.setdefault(n.name.lower(), n.name)
            if other != n.name:  # tck-id-case-sensitivity-sparkplug-ids: a host may fold case
                raise ValueError(f"device id (node name): {n.name!r} and {other!r} differ only in case")
        check_files(options)
        if options.store_dir is not None:
            d = Path(options.store_dir)
            while not d.exists() and d != d.parent:  # created at open: its first existing parent
                d = d.parent
            if not d.is_dir() or not os.access(d, os.W_OK | os.X_OK):
                raise ValueError(f"store_dir: {options.store_dir!r}: {str(d)!r} is not a writable folder")

    @classmethod
    def probe(cls, options: SparkplugOptions, nodes: Sequence[NodeLike[Any]]) -> None:
        """``--check``: a warning line for each departure from the specification that
        the run will make (the run logs the same as ``sparkplug_nonconforming``)."""
        path = bdseq_path(options.store_dir, options.group_id, options.edge_node_id)
        for line in nonconforming(options, writable(path), str(path)):
            sys.stderr.write(f"eskin-bus: warning: [sparkplug] {line}\n")

    @classmethod
    def _open_nodes(cls, options: SparkplugOptions, nodes: Sequence[NodeLike[Any]], context: OpenContext) -> list[Sink]:
        edge, devices = _edge_with_devices(
            options, [(n.name, {METHOD_METRIC: method_properties(n.profile),
                                LAYOUT_METRIC: layout_properties(n.profile),
                                FRAME_METRIC.name: frame_properties(n.profile, options.frame_interval_s),
                                **score_properties(n.profile)})
                      for n in nodes])
        context.closers.append(edge.close)  # closers run last first: the devices' DDEATH, then NDEATH
        for dev in devices:
            context.closers.append(dev.close)
        edge.start()
        return list(devices)


def open_edge(options: SparkplugOptions, devices: Sequence[tuple[str, dict[str, tuple[Property, ...]]]]
              ) -> EdgeNode:
    """An edge node (not started) with one device per ``(name, properties)``."""
    return _edge_with_devices(options, devices)[0]


def _edge_with_devices(options: SparkplugOptions, devices: Sequence[tuple[str, dict[str, tuple[Property, ...]]]]
                       ) -> tuple[EdgeNode, list[SparkplugDevice]]:
    try:
        import paho.mqtt.client as mqtt
    except ImportError:  # pragma: no cover - a runtime dependency
        from ...errors import MissingExtra

        # a dependency of the package itself: only a damaged install lacks it
        raise MissingExtra("the sparkplug output needs paho-mqtt: pip install 'paho-mqtt>=2.1,<2.3'") from None
    client = mqtt.Client(callback_api_version=mqtt.CallbackAPIVersion.VERSION2,
                         client_id=f"{options.group_id}-{options.edge_node_id}", clean_session=True)
    try:
        configure(client, options)
    except ValueError as exc:  # a password file emptied since --check
        raise ProfileError(f"[sparkplug] {exc}") from None
    edge = EdgeNode(options, client)
    made = [SparkplugDevice(edge, name, i, props) for i, (name, props) in enumerate(devices)]
    edge.devices.extend(made)
    return edge, made
