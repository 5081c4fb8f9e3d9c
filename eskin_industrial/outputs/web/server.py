"""The console's server: aiohttp on a thread and an asyncio loop of its own.

Why aiohttp: one maintained package gives the HTTP server, WebSockets and static
files on asyncio, with no ASGI server beside it (docs/web.md).

- ``GET /``, ``/node/N``, ``/events``: the pages (static files of the package);
  ``/static/...`` their scripts and styles.  No CDN: a plant network is often offline.
- ``GET /api/info``: the nodes (layout, scores and thresholds) and the session.
- ``POST /api/login``, ``/api/logout``: a session in an HttpOnly, SameSite=Strict cookie.
- ``POST /api/nodes/N/command``: tare, ack, enable, disable; an operator's session and
  its CSRF token (``X-CSRF-Token``), judged under :func:`~eskin_industrial.node.refusal`,
  then queued for the node's loop (its sink's ``take_commands``).
- ``GET /api/episodes/ID.csv``: an episode's raw scans as a recording CSV.
- ``GET /ws``: the live state, one binary message a display frame (:mod:`.wire`: JSON
  and the frame's float32 forces); the Origin header must be the console's own.

A ticker on the server's loop, once a display frame (``frame_interval_s``), does the
feeds' work for every viewer together (:meth:`.hub.NodeFeed.tick`: the trends, the
captures) and wakes the senders when something is new; a node's loop wakes it itself
only at a state change.  Each WebSocket has a sender that waits for a wake-up, builds
one message of what is new for it (of parts encoded once for all: the snapshot's JSON,
the frame's bytes) and sends it.  The page acknowledges each message once it has drawn it;
at most :data:`IN_FLIGHT` messages go unacknowledged, so a browser that draws slowly
is sent fewer messages, each with the newest frame (the one it missed is never sent:
it is decimated), and one that takes none for :data:`SEND_TIMEOUT_S` is dropped.
Nothing is queued per browser.
"""

from __future__ import annotations

import asyncio
import collections
import concurrent.futures
import hmac
import io
import json
import secrets
import ssl
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from aiohttp import WSMsgType, web

from ...errors import ListenError
from ...netaddr import listen_error
from ...node import Command, refusal
from ...recording import write_recording
from .hub import EPISODES_MAX, NodeFeed, Truth
from .users import Role, WebUser, login
from .wire import encode

if TYPE_CHECKING:
    from .options import WebOptions

_T = TypeVar("_T")
STATIC = Path(__file__).parent / "static"
#: A browser that has not taken (acknowledged) a message within this time is dropped.
SEND_TIMEOUT_S = 5.0
#: Messages sent and not yet acknowledged by the page, at most.
IN_FLIGHT = 2
SESSIONS_MAX = 256
#: Logins waiting for their scrypt at most (one is hashed at a time, on a thread of its
#: own): a guessing client takes at most one core's share, never the node's loop's.
LOGINS_PENDING_MAX = 4
COOKIE = "eskin_session"
_COMMANDS = ("ack", "tare", "enable", "disable")
_SECURITY_HEADERS = {
    "Content-Security-Policy": "default-src 'self'; img-src 'self' data:; connect-src 'self'; "
                               "frame-ancestors 'none'; base-uri 'none'; form-action 'self'",
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",
    "Cache-Control": "no-store",
}


@dataclass
class Session:
    user: str
    role: Role
    csrf: str
    last_seen: float


#: A register block as the page shows it: the registers by name, the STATUS bits set,
#: and what it is (``{"source": "served" | "written", "acknowledged": bool}``; a reader
#: of two elements is a served block's).
RegisterBlock = tuple[dict[str, int], tuple[str, ...]] | tuple[dict[str, int], tuple[str, ...], dict[str, Any]]
RegisterReader = Callable[[], RegisterBlock | None]


@dataclass
class Wiring:
    """What the console is handed beside its options, kept by the output across a
    restart of its instance (``OpenContext.kept``): the register blocks' readers and
    the scenes' truths, given once after the bridge opened, and the login sessions (a
    logged-in operator stays logged in)."""

    sessions: dict[str, Session] = field(default_factory=dict)
    #: node -> a function giving the register block, or None; set by whoever wires the PLC beside
    registers: dict[int, RegisterReader] = field(default_factory=dict)
    truths: dict[int, Truth] = field(default_factory=dict)  #: node -> the onsets of its scene


@dataclass(eq=False)  # one per connection, kept in a set
class Client:
    """One browser's WebSocket: what it watches, and what it has been sent."""

    ws: web.WebSocketResponse
    peer: str = "-"
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    watch: int | None = None
    in_flight: int = 0
    acked: asyncio.Event = field(default_factory=asyncio.Event)
    snap_seq: dict[int, int] = field(default_factory=dict)
    lane_seq: dict[int, int] = field(default_factory=dict)
    episodes_seq: dict[int, int] = field(default_factory=dict)
    frame_seq: int = 0
    trend_seq: int = 0
    episodes: dict[tuple[int, int], bool] = field(default_factory=dict)


@dataclass(frozen=True)
class NodeView:
    """What the pages need to draw a node (sent once, by /api/info)."""

    name: str
    rows: int
    cols: int
    x_mm: list[float]
    y_mm: list[float]
    row_names: list[str]
    method: str
    score_names: tuple[str, str]
    slip: tuple[float | None, float | None]
    variable: tuple[float | None, float | None]
    rate_hz: float


class WebServer:
    """One server for the bridge's nodes (``feeds``, in order)."""

    def __init__(self, options: WebOptions, views: list[NodeView], feeds: list[NodeFeed],
                 users: tuple[WebUser, ...], wiring: Wiring | None = None) -> None:
        self.options = options
        self.views = views
        self.feeds = feeds
        self.users = {u.name: u for u in users}
        self.wiring = wiring or Wiring()
        self.sessions = self.wiring.sessions
        for token, s in list(self.sessions.items()):  # a user the users file no longer gives goes
            if self.users.get(s.user) is None or self.users[s.user].role != s.role:
                del self.sessions[token]
        self.clients: set[Client] = set()
        self.registers = self.wiring.registers
        self._blocks: dict[int, tuple[int, str | None]] = {}  #: node -> (snap_seq, its block's JSON)
        self._trends: dict[int, tuple[int, int, str]] = {}  #: node -> (from seq, to seq, the points' JSON)
        self.counts = {"web_clients": 0, "web_clients_dropped": 0, "web_messages": 0, "web_frames_skipped": 0,
                       "web_logins": 0, "web_logins_refused": 0, "web_commands": 0, "web_commands_refused": 0,
                       "web_origin_refused": 0}
        self.on_event: Callable[..., None] = lambda name, level, **fields: None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._logins = concurrent.futures.ThreadPoolExecutor(max_workers=1, thread_name_prefix="web-login")
        self._logins_pending = 0
        self._kicked = False
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        for feed in feeds:
            feed.kick = self.kick

    # -- the caller's side -------------------------------------------------------------
    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="web-server", daemon=True)
        self._thread.start()
        self._ready.wait(timeout=15)
        if self._error is not None:
            raise self._error
        if self._loop is None:
            raise ListenError(f"{self.options.bind}: the web console did not start within 15 s")

    def stop(self) -> None:
        loop, stop = self._loop, self._stop
        if loop is not None and stop is not None:
            try:
                loop.call_soon_threadsafe(stop.set)
            except RuntimeError:
                pass  # already closed
        if self._thread is not None:
            self._thread.join(timeout=10)
        self._logins.shutdown(wait=False, cancel_futures=True)

    def kick(self) -> None:
        """Something is new (any thread): wake the server's loop, once until it has looked."""
        if self._kicked:
            return
        loop = self._loop
        if loop is None:
            return
        self._kicked = True
        try:
            loop.call_soon_threadsafe(self._woken)
        except RuntimeError:
            pass  # the loop has closed: the bridge is stopping

    def counters(self) -> dict[str, int]:
        return dict(self.counts)

    # -- the server's thread -----------------------------------------------------------
    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:
            if not self._ready.is_set():
                self._error = exc
            else:
                raise
        finally:
            self._ready.set()

    def _routes(self, router: web.UrlDispatcher) -> None:
        """The pages and the routes of this server's own (beside the login, the info,
        the WebSocket and the static files every console has)."""
        router.add_get("/", self._page("cell.html"))
        router.add_get("/node/{i}", self._page("node.html"))
        router.add_get("/events", self._page("events.html"))
        router.add_post("/api/nodes/{i}/command", self._command)
        router.add_get("/api/episodes/{node}/{id}.csv", self._capture)

    async def _main(self) -> None:
        self._stop = asyncio.Event()
        app = web.Application(middlewares=[self._headers], client_max_size=64 * 1024)
        self._routes(app.router)
        app.router.add_get("/api/info", self._info)
        app.router.add_post("/api/login", self._login)
        app.router.add_post("/api/logout", self._logout)
        app.router.add_get("/ws", self._ws)
        app.router.add_static("/static/", STATIC, follow_symlinks=False)
        runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=1.0)
        await runner.setup()
        context = None
        if self.options.tls:
            context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
            context.minimum_version = ssl.TLSVersion.TLSv1_2
            assert self.options.tls_cert is not None and self.options.tls_key is not None
            context.load_cert_chain(self.options.tls_cert, self.options.tls_key)
        site = web.TCPSite(runner, self.options.host, self.options.port, ssl_context=context, reuse_address=True)
        try:
            await site.start()
        except OSError as exc:
            await runner.cleanup()
            raise ListenError(listen_error(self.options.host, self.options.port, exc)) from None
        self._loop = asyncio.get_running_loop()
        ticker = asyncio.ensure_future(self._ticker())
        self._ready.set()
        self.on_event("web_listening", "info", url=self.options.url, users=len(self.users),
                      tls=self.options.tls)
        try:
            await self._stop.wait()
        finally:
            ticker.cancel()
            for c in list(self.clients):
                await c.ws.close()
            await runner.cleanup()
            self._loop = None

    def _woken(self) -> None:
        self._kicked = False
        for c in self.clients:
            c.wake.set()

    async def _ticker(self) -> None:
        """Once a display frame: the feeds' work for every viewer together, then the
        senders woken when a feed has something new."""
        interval = self.options.frame_interval_s
        seen: list[tuple[int, int]] = [(-1, -1)] * len(self.feeds)
        while True:
            await asyncio.sleep(interval)
            now = time.monotonic()
            new = False
            for i, feed in enumerate(self.feeds):
                feed.tick(now)
                mark = (feed.snap_seq, feed.frame_seq)
                if mark != seen[i]:
                    seen[i], new = mark, True
            if new:
                for c in self.clients:
                    c.wake.set()

    @web.middleware
    async def _headers(self, request: web.Request, handler: Callable[..., Any]) -> web.StreamResponse:
        response: web.StreamResponse = await handler(request)
        if not response.prepared:
            for k, v in _SECURITY_HEADERS.items():
                response.headers.setdefault(k, v)
            if self.options.tls:
                response.headers.setdefault("Strict-Transport-Security", "max-age=31536000")
        return response

    def _page(self, name: str) -> Callable[[web.Request], Any]:
        async def page(request: web.Request) -> web.StreamResponse:
            if "i" in request.match_info:
                self._node_index(request)
            return web.FileResponse(STATIC / name)

        return page

    # -- sessions ----------------------------------------------------------------------
    def _session(self, request: web.Request) -> Session | None:
        token = request.cookies.get(COOKIE)
        if not token:
            return None
        s = self.sessions.get(token)
        now = time.monotonic()
        if s is None or now - s.last_seen > self.options.session_timeout_s:
            self.sessions.pop(token, None)
            return None
        s.last_seen = now
        return s

    def _may_view(self, request: web.Request) -> bool:
        """With users, every value needs a login; without, the console is open read-only."""
        return not self.users or self._session(request) is not None

    def _same_origin(self, request: web.Request) -> bool:
        origin = request.headers.get("Origin")
        want = f"{'https' if self.options.tls else 'http'}://{request.host}"
        return origin is not None and hmac.compare_digest(origin, want)

    def _session_json(self, s: Session | None) -> dict[str, Any]:
        commands = bool(self.users) and not self.options.read_only
        if s is None:
            return {"user": None, "role": None, "csrf": None, "login": bool(self.users), "commands": commands}
        return {"user": s.user, "role": s.role, "csrf": s.csrf, "login": True, "commands": commands}

    async def _info(self, request: web.Request) -> web.Response:
        s = self._session(request)
        body: dict[str, Any] = {"session": self._session_json(s)}
        if self._may_view(request):
            body["nodes"] = [v.__dict__ for v in self.views]
        return web.json_response(body)

    async def _login(self, request: web.Request) -> web.Response:
        if not self._same_origin(request):
            return self._refuse(403, "the request's Origin is not this console's")
        if not self.users:
            return self._refuse(404, "no users: the console is read-only")
        try:
            body = await request.json()
            name, password = str(body["user"]), str(body["password"])
        except (ValueError, KeyError, TypeError):
            return self._refuse(400, "expected JSON {user, password}")
        if self._logins_pending >= LOGINS_PENDING_MAX:
            self.counts["web_logins_refused"] += 1
            return self._refuse(429, "too many logins at once: try again")
        self._logins_pending += 1
        try:
            role = await asyncio.get_running_loop().run_in_executor(self._logins, login, self.users, name, password)
        finally:
            self._logins_pending -= 1
        if role is None:
            self.counts["web_logins_refused"] += 1
            self.on_event("web_login_refused", "warning", user=name, peer=request.remote or "-")
            return self._refuse(401, "wrong user name or password")
        self.counts["web_logins"] += 1
        while len(self.sessions) >= SESSIONS_MAX:  # the one seen longest ago goes
            del self.sessions[min(self.sessions, key=lambda k: self.sessions[k].last_seen)]
        token = secrets.token_urlsafe(32)
        s = Session(name, role, secrets.token_urlsafe(32), time.monotonic())
        self.sessions[token] = s
        self.on_event("web_login", "info", user=name, role=role, peer=request.remote or "-")
        response = web.json_response({"session": self._session_json(s)})
        response.set_cookie(COOKIE, token, httponly=True, samesite="Strict", secure=self.options.tls, path="/")
        return response

    async def _logout(self, request: web.Request) -> web.Response:
        if not self._same_origin(request):
            return self._refuse(403, "the request's Origin is not this console's")
        token = request.cookies.get(COOKIE)
        if token:
            self.sessions.pop(token, None)
        response = web.json_response({"session": self._session_json(None)})
        response.del_cookie(COOKIE, path="/")
        return response

    def _refuse(self, status: int, why: str) -> web.Response:
        return web.json_response({"error": why}, status=status)

    def _node_index(self, request: web.Request) -> int:
        try:
            i = int(request.match_info["i"])
        except ValueError:
            raise web.HTTPNotFound() from None
        if not 0 <= i < len(self.feeds):
            raise web.HTTPNotFound()
        return i

    # -- commands ----------------------------------------------------------------------
    async def _command(self, request: web.Request) -> web.Response:
        i = self._node_index(request)
        s = self._session(request)
        try:
            body = await request.json()
            name = body["command"]
        except (ValueError, KeyError, TypeError):
            return self._refuse(400, "expected JSON {command}")
        if name not in _COMMANDS:
            return self._refuse(400, f"command: expected one of {', '.join(_COMMANDS)}, got {name!r}")
        why, status = None, 0
        if not self.users or self.options.read_only:
            why, status = "read_only", 403
        elif s is None:
            why, status = "login", 401
        elif not self._same_origin(request):
            why, status = "origin", 403
        elif not hmac.compare_digest(request.headers.get("X-CSRF-Token", ""), s.csrf):
            why, status = "csrf", 403
        elif s.role != "operator":
            why, status = "role", 403
        command = Command(name)
        if why is None:
            why = refusal(command, self.feeds[i].snapshot, read_only=self.options.read_only)
            status = 409
        if why is None and not self.feeds[i].queue_command(command):
            why, status = "busy", 503
        node = self.views[i].name
        if why is not None:
            self.counts["web_commands_refused"] += 1
            self.on_event("web_command_refused", "warning", node_event=node, command=name, reason=why,
                          user=s.user if s else "-")
            return self._refuse(status, why)
        self.counts["web_commands"] += 1
        assert s is not None
        self.on_event("web_command", "info", node_event=node, command=name, user=s.user)
        return web.json_response({"queued": name}, status=202)

    # -- captures ----------------------------------------------------------------------
    async def _capture(self, request: web.Request) -> web.StreamResponse:
        if not self._may_view(request):
            return self._refuse(401, "log in first")
        try:
            node, ident = int(request.match_info["node"]), int(request.match_info["id"])
            feed = self.feeds[node]
        except (ValueError, IndexError):
            raise web.HTTPNotFound() from None
        ep = next((e for e in list(feed.episodes) if e.id == ident), None)
        rows = ep.rows if ep is not None else None
        if rows is None or rows.shape[0] == 0 or ep is None:
            raise web.HTTPNotFound(text="no capture of that episode (not over yet, or let go)")
        out = io.StringIO()
        await asyncio.get_running_loop().run_in_executor(None, write_recording, out, rows[:, 0], rows[:, 1:])
        name = f"{self.views[node].name}-{ep.state}-{ep.t:.3f}.csv"
        return web.Response(text=out.getvalue(), content_type="text/csv",
                            headers={"Content-Disposition": f'attachment; filename="{name}"'})

    # -- the live state ----------------------------------------------------------------
    async def _ws(self, request: web.Request) -> web.StreamResponse:
        if not self._same_origin(request):
            self.counts["web_origin_refused"] += 1
            self.on_event("web_origin_refused", "warning", origin=request.headers.get("Origin", "-"),
                          peer=request.remote or "-")
            return self._refuse(403, "the WebSocket's Origin is not this console's")
        if not self._may_view(request):
            return self._refuse(401, "log in first")
        if len(self.clients) >= self.options.max_clients:
            return self._refuse(503, "too many browsers connected")
        # no permessage-deflate: float32 forces hardly compress, and each viewer's copy
        # would be deflated on its own (a quarter of the server's CPU per viewer, measured)
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=4096, compress=False)
        await ws.prepare(request)
        client = Client(ws, peer=request.remote or "-")
        self.clients.add(client)
        self.counts["web_clients"] += 1
        client.wake.set()
        sender = asyncio.ensure_future(self._send_loop(client))
        try:
            async for msg in ws:
                if msg.type != WSMsgType.TEXT:
                    continue
                try:
                    body = json.loads(msg.data)
                    watch = body.get("watch", client.watch)
                    acks = body.get("ack", 0)
                except (ValueError, AttributeError):
                    continue
                if isinstance(acks, int) and acks > 0:
                    client.in_flight = max(0, client.in_flight - acks)
                    client.acked.set()
                if "watch" not in body:
                    continue
                client.watch = watch if isinstance(watch, int) and 0 <= watch < len(self.feeds) else None
                client.frame_seq = client.trend_seq = 0
                client.wake.set()
        finally:
            sender.cancel()
            self.clients.discard(client)
        return ws

    async def _send_loop(self, client: Client) -> None:
        try:
            while not client.ws.closed:
                await client.wake.wait()
                try:
                    while client.in_flight >= IN_FLIGHT:  # the page has not drawn what it has
                        client.acked.clear()
                        await asyncio.wait_for(client.acked.wait(), SEND_TIMEOUT_S)
                    client.wake.clear()
                    message = self._message(client)
                    if message is None:
                        continue
                    send = client.ws.send_bytes(message) if isinstance(message, bytes) else client.ws.send_str(message)
                    await asyncio.wait_for(send, SEND_TIMEOUT_S)
                except TimeoutError:
                    self.counts["web_clients_dropped"] += 1
                    self.on_event("web_client_dropped", "warning", peer=client.peer,
                                  reason=f"no message taken in {SEND_TIMEOUT_S:g} s")
                    await client.ws.close()
                    return
                client.in_flight += 1
                self.counts["web_messages"] += 1
        except (ConnectionError, RuntimeError):
            return  # the browser went away

    def _message(self, client: Client) -> bytes | str | None:
        """What is new for this browser, as one message (:mod:`.wire`; None: nothing).
        The snapshots' JSON and the frame's bytes are the feeds' own, made once for
        every viewer; what is this browser's (the lane, the episodes, the trend points
        it has not had) is small."""
        parts = [f'"server_time":{time.time()!r}']
        nodes, lane, episodes = [], [], []
        for i, feed in enumerate(self.feeds):
            new_lane, eps, summaries = [], [], []
            if feed.lane_seq != client.lane_seq.get(i, 0) or feed.episodes_seq != client.episodes_seq.get(i, 0):
                with feed.lock:  # only when the lane or the episodes changed since this browser's last
                    new_lane = newest(feed.lane, feed.lane_seq - client.lane_seq.get(i, 0))
                    eps = [e for e in feed.episodes
                           if client.episodes.get((i, e.id)) != (e.rows is not None)]
                    summaries = [e.summary() for e in eps]
                    client.episodes_seq[i] = feed.episodes_seq
            snap_seq, snap_text = feed.snapshot_text()
            if snap_seq != client.snap_seq.get(i):
                client.snap_seq[i] = snap_seq
                nodes.append(snap_text)
            if new_lane:
                client.lane_seq[i] = new_lane[-1][0]
                lane += [{"node": i, "seq": s, "t": t, "wall": w, "state": label, "valid": v}
                         for s, t, w, label, v in new_lane]
            for e, summary in zip(eps, summaries):
                client.episodes[(i, e.id)] = summary["capture"]
            episodes += summaries
        if len(client.episodes) > 2 * EPISODES_MAX * len(self.feeds):  # bounded: what the feeds still list
            present = {(i, e.id) for i, feed in enumerate(self.feeds) for e in list(feed.episodes)}
            client.episodes = {k: v for k, v in client.episodes.items() if k in present}
        if nodes:
            parts.append(f'"nodes":[{",".join(nodes)}]')
        if lane:
            parts.append(f'"lane":{_dumps(lane)}')
        if episodes:
            parts.append(f'"episodes":{_dumps(episodes)}')
        tail = b""
        w = client.watch
        if w is not None:
            feed = self.feeds[w]
            frame_seq, frame_head, frame_tail = feed.frame_blob()
            if frame_seq and frame_seq != client.frame_seq:
                if client.frame_seq:
                    self.counts["web_frames_skipped"] += max(0, frame_seq - client.frame_seq - 1)
                client.frame_seq = frame_seq
                parts.append(f'"frame":{frame_head}')
                tail = frame_tail
            if feed.trend_seq != client.trend_seq:
                parts.append(f'"trend":{self._trend(w, client.trend_seq)}')
                client.trend_seq = feed.trend_seq
            block = self._block(w) if nodes else None
            if block is not None:
                parts.append(f'"registers":{block}')
        if len(parts) == 1:
            return None
        return encode("{" + ",".join(parts) + "}", tail)

    def _trend(self, w: int, since: int) -> str:
        """Node ``w``'s trend points after ``since`` as JSON, made once for the browsers
        in step (each has had the same points)."""
        feed = self.feeds[w]
        cached = self._trends.get(w)
        if cached is not None and cached[:2] == (since, feed.trend_seq):
            return cached[2]
        upto = feed.trend_seq
        text = _dumps({"node": w, "points": newest(feed.trend, upto - since)})
        self._trends[w] = (since, upto, text)
        return text

    def _block(self, w: int) -> str | None:
        """Node ``w``'s register block as JSON, read once a snapshot for every viewer."""
        read = self.registers.get(w)
        if read is None:
            return None
        seq = self.feeds[w].snap_seq
        cached = self._blocks.get(w)
        if cached is not None and cached[0] == seq:
            return cached[1]
        try:
            table = read()
        except Exception:  # noqa: BLE001 - a register source that fails leaves the block out, not the page
            table = None
        text = None
        if table is not None:
            meta = table[2] if len(table) > 2 else {"source": "served", "acknowledged": True}
            text = _dumps({"node": w, "values": table[0], "bits": list(table[1]), **meta})
        self._blocks[w] = (seq, text)
        return text


def newest(ring: collections.deque[_T], count: int) -> list[_T]:
    """The ``count`` newest items of a ring numbered in order (its seq minus the one a
    client has), read from its end: a message costs what is new, not the ring's length."""
    if count <= 0:
        return []
    if count >= len(ring):
        return list(ring)
    return [ring[-j] for j in range(count, 0, -1)]


def _dumps(value: Any) -> str:
    return json.dumps(value, allow_nan=False, separators=(",", ":"))
