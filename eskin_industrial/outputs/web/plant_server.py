"""The plant page's server: the console's server (:class:`.server.WebServer`: its own
thread and loop, sessions, TLS, the Origin check on the WebSocket, the acknowledged
sending) serving a :class:`.plant_feed.PlantFeed` instead of nodes.  Read-only: no
command route.

- ``GET /``, ``/plant``: the page; ``/static/...`` its script and styles.
- ``GET /api/info``: the session (and an empty node list: there are no bridge nodes).
- ``GET /api/plant``: the newest rows, JSON.
- ``POST /api/login``, ``/api/logout``: as the console's.
- ``GET /ws``: ``{"plant": {"seq", "messages", "rows"}}`` when the rows change; at most
  :data:`.server.IN_FLIGHT` messages unacknowledged, each with the newest rows.
"""

from __future__ import annotations

import asyncio
import json
import ssl
import time
from typing import TYPE_CHECKING, Any

from aiohttp import web

from ...errors import ListenError
from ...netaddr import listen_error
from .server import STATIC, Client, WebServer

if TYPE_CHECKING:
    from .options import WebOptions
    from .plant_feed import PlantFeed
    from .users import WebUser

_SEEN = -1  #: the key of :attr:`Client.snap_seq` that holds the plant rows' seq a page has


class PlantServer(WebServer):
    def __init__(self, options: WebOptions, feed: PlantFeed, users: tuple[WebUser, ...] = ()) -> None:
        super().__init__(options, [], [], users)
        self.plant = feed
        feed.kick = self.kick

    def plant_json(self) -> dict[str, Any]:
        seq, rows, messages = self.plant.read()
        return {"seq": seq, "messages": messages, "rows": [r.as_json() for r in rows]}

    async def _main(self) -> None:
        # the console's _main with the plant's routes (its routes are fixed inside it)
        self._stop = asyncio.Event()
        app = web.Application(middlewares=[self._headers], client_max_size=64 * 1024)
        app.router.add_get("/", self._page("plant.html"))
        app.router.add_get("/plant", self._page("plant.html"))
        app.router.add_get("/api/info", self._info)
        app.router.add_get("/api/plant", self._rows)
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
        self._ready.set()
        self.on_event("web_listening", "info", url=self.options.url, users=len(self.users), tls=self.options.tls)
        try:
            await self._stop.wait()
        finally:
            for c in list(self.clients):
                await c.ws.close()
            await runner.cleanup()
            self._loop = None

    async def _rows(self, request: web.Request) -> web.Response:
        if not self._may_view(request):
            return self._refuse(401, "log in first")
        return web.json_response(self.plant_json())

    def _message(self, client: Client) -> str | None:
        seq, rows, messages = self.plant.read()
        if seq == client.snap_seq.get(_SEEN):
            return None
        client.snap_seq[_SEEN] = seq
        return json.dumps({"server_time": time.time(), "plant": {
            "seq": seq, "messages": messages, "rows": [r.as_json() for r in rows]}}, allow_nan=False)
