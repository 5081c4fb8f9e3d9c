"""``eskin-bus plant``: the commissioning view of a Sparkplug B namespace."""

from __future__ import annotations

import json
import queue
import sys
import threading
import time
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any

import click

from .outputs import kind_options, outputs_from_cli

#: A row online by its births with nothing from it for this long is shown stale.
STALE_S = 10.0
#: The web page's rows are refreshed this often (and at every event) when served.
WEB_REFRESH_S = 0.25


@dataclass(frozen=True)
class _Conn:
    """What :mod:`eskin_industrial.outputs.sparkplug.transport` reads of a connection."""

    broker: str
    ca_file: str | None = None
    cert_file: str | None = None
    key_file: str | None = None
    username: str | None = None
    password_file: str | None = None
    password_env: str | None = None


def _line(e: dict[str, Any]) -> str:
    who = "/".join(e[k] for k in ("group", "edge", "device") if k in e)
    rest = " ".join(f"{k}={v}" for k, v in e.items() if k not in ("event", "group", "edge", "device") and v is not None)
    return f"{time.strftime('%H:%M:%S')} {e['event']:<8} {who} {rest}".rstrip()


@click.command()
@click.argument("broker", metavar="mqtt[s]://HOST:PORT")
@click.option("--group-id", default="+", show_default=True, help="Sparkplug group to watch (+: every group).")
@click.option("--plain", is_flag=True, help="One line per event (births, deaths, state changes) instead of the live "
              "table (the default when stdout is not a terminal).")
@click.option("--json", "as_json", is_flag=True, help="One JSON object per event instead of the live table.")
@click.option("--rebirth", is_flag=True, help="Ask an edge node seen before its birth for a rebirth (an NCMD "
              "Node Control/Rebirth, once per node): the only thing this command then publishes.")
@click.option("--duration", "duration_s", type=float, default=None, help="Stop after this many seconds.")
@click.option("--ca-file", default=None, metavar="FILE", help="mqtts: CA certificates (PEM) of the broker.")
@click.option("--cert-file", default=None, metavar="FILE", help="mqtts: client certificate (PEM).")
@click.option("--key-file", default=None, metavar="FILE", help="mqtts: the client certificate's key (PEM).")
@click.option("--username", default=None, help="MQTT username.")
@click.option("--password-file", default=None, metavar="FILE", help="MQTT password: the first line of this file.")
@click.option("--password-env", default=None, metavar="NAME", help="MQTT password: this environment variable.")
@click.option("--stale-s", type=click.FloatRange(min=0.5), default=STALE_S, show_default=True,
              help="An edge node or device online with nothing from it for this long is shown stale (--web).")
@kind_options("web")
def plant(broker: str, group_id: str, plain: bool, as_json: bool, rebirth: bool, duration_s: float | None,
          ca_file: str | None, cert_file: str | None, key_file: str | None, username: str | None,
          password_file: str | None, password_env: str | None, stale_s: float, **web_values: Any) -> None:
    """Watch every Sparkplug B edge node and device on a broker: online or offline (from
    births and deaths), state, data valid, last slip, slip count, message rate, seq gaps.
    Live on a terminal; one line (--plain) or one JSON object (--json) per event
    otherwise.  Read-only (it publishes nothing) unless --rebirth.  With --web HOST:PORT
    the plant page shows the same rows in a browser, live (docs/web.md)."""
    from ..outputs.sparkplug.transport import check_files, check_security, configure, parse_broker
    from ..outputs.sparkplug.watch import PlantModel, rebirth_command

    conn = _Conn(broker, ca_file, cert_file, key_file, username, password_file, password_env)
    try:
        host, port, _ = parse_broker(broker)
        check_security(conn)
        check_files(conn)
        if "/" in group_id or "#" in group_id:
            raise ValueError(f"--group-id: {group_id!r} is not a Sparkplug group id")
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="BROKER") from None
    try:
        import paho.mqtt.client as mqtt
    except ImportError:  # pragma: no cover - a runtime dependency
        from ..errors import MissingExtra

        raise MissingExtra("eskin-bus plant needs paho-mqtt (pip install paho-mqtt)") from None
    web_options = outputs_from_cli(web_values, ("web",)).get("web")
    live = not plain and not as_json and sys.stdout.isatty()
    model = PlantModel()
    served = _serve(web_options) if web_options is not None else None
    events: queue.Queue[dict[str, Any]] = queue.Queue()
    lock = threading.Lock()

    def on_message(client: Any, userdata: Any, msg: Any) -> None:
        with lock:
            for e in model.take(msg.topic, msg.payload, time.monotonic()):
                events.put(e)
                if rebirth and e["event"] == "unborn":
                    client.publish(f"spBv1.0/{e['group']}/NCMD/{e['edge']}", rebirth_command(), qos=0)  # NCMD: QoS 0

    def on_connect(client: Any, userdata: Any, flags: Any, reason: Any, properties: Any) -> None:
        if reason.is_failure:
            events.put({"event": "refused", "broker": broker, "error": str(reason)})
            return
        client.subscribe(f"spBv1.0/{group_id}/#", qos=0)

    def on_subscribe(client: Any, userdata: Any, mid: Any, reasons: Any, properties: Any) -> None:
        """Connected once the broker has the subscription: what is published after this
        line is seen."""
        events.put({"event": "connected", "broker": broker})

    client = mqtt.Client(callback_api_version=mqtt.CallbackAPIVersion.VERSION2)
    client.on_message, client.on_connect, client.on_subscribe = on_message, on_connect, on_subscribe
    try:
        configure(client, conn)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--password-file") from None
    client.reconnect_delay_set(1, 5)
    client.connect_async(host, port, keepalive=30)
    client.loop_start()
    end = None if duration_s is None else time.monotonic() + duration_s
    title = f"eskin-bus plant | {broker} | group {group_id}"
    screen: Any = nullcontext()
    if live:
        from ..view.plant_table import plant_lines
        from ..view.terminal import LiveScreen

        def frame(width: int, height: int) -> list[str]:
            with lock:
                rows = model.rows(time.monotonic())
            return plant_lines(rows, title, width, height)

        screen = LiveScreen(frame, sys.stdout, fps=4)
    next_rows = 0.0
    try:
        with screen:
            while end is None or time.monotonic() < end:
                if served is not None and time.monotonic() >= next_rows:
                    with lock:
                        rows, messages = model.rows(time.monotonic()), model.messages
                    served[1].put(plant_rows(rows, stale_s), messages)
                    next_rows = time.monotonic() + WEB_REFRESH_S
                try:
                    e = events.get(timeout=0.1)
                except queue.Empty:
                    continue
                next_rows = 0.0  # an event: the page's rows at once
                if not live:
                    click.echo(json.dumps(e) if as_json else _line(e))
    except KeyboardInterrupt:
        pass
    finally:
        client.disconnect()
        client.loop_stop()
        if served is not None:
            served[0].stop()
    with lock:
        rows = model.rows(time.monotonic())
    if as_json:
        for r in rows:
            click.echo(json.dumps({"event": "summary", **r}))
    click.echo(f"plant: {model.messages} messages, {model.malformed} malformed, "
               f"{sum('device' not in r for r in rows)} edge nodes, {sum('device' in r for r in rows)} devices",
               err=True)


def _serve(options: Any) -> tuple[Any, Any]:
    """The plant page's server, started (a port in use: ListenError, exit 2)."""
    from ..outputs.web.kind import need_aiohttp
    from ..outputs.web.plant_feed import PlantFeed
    from ..outputs.web.plant_server import PlantServer
    from ..outputs.web.users import load_users

    need_aiohttp("eskin-bus plant --web")
    users = load_users(options.users_file) if options.users_file else ()
    feed = PlantFeed()
    server = PlantServer(options, feed, users)
    server.on_event = lambda name, level, **fields: click.echo(
        f"{time.strftime('%H:%M:%S')} {name} " + " ".join(f"{k}={v}" for k, v in fields.items()), err=True)
    server.start()
    return server, feed


def plant_rows(rows: list[dict[str, Any]], stale_s: float) -> list[Any]:
    """The host view's rows as the page's neutral :class:`PlantRow` (stale: online, and
    nothing from it for ``stale_s``; an edge node is stale when all its devices are)."""
    from ..outputs.web.plant_feed import PlantRow, Status

    out: list[PlantRow] = []
    for r in rows:
        if "device" not in r:
            out.append(PlantRow(r["group"], r["edge"], None, "online" if r["online"] else "offline",
                                seq_gaps=r["seq_gaps"], bd_seq=r["bdSeq"]))
            continue
        age = r.get("age_s")
        status: Status = "offline" if not r["online"] else ("stale" if age is not None and age > stale_s else "online")
        out.append(PlantRow(r["group"], r["edge"], r["device"], status, state=r["state"], valid=r["valid"],
                            method=r.get("method"), slips=r["slips"], last_slip_ms=r["last_slip_ms"],
                            rate=r["rate"], frame_max=r.get("frame_max"), frame_sum=r.get("frame_sum")))
    # an edge node online whose devices are all stale is stale itself
    for i, e in enumerate(out):
        if e.device is not None or e.status != "online":
            continue
        devices = [d for d in out[i + 1:] if d.device is not None and (d.group, d.edge) == (e.group, e.edge)]
        if devices and all(d.status == "stale" for d in devices):
            out[i] = PlantRow(e.group, e.edge, None, "stale", seq_gaps=e.seq_gaps, bd_seq=e.bd_seq)
    return out
