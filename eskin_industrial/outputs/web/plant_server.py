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

import json
import time
from typing import TYPE_CHECKING, Any

from aiohttp import web

from .server import Client, WebServer

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

    def _routes(self, router: web.UrlDispatcher) -> None:
        """The plant's page and its rows (read-only: no command route)."""
        router.add_get("/", self._page("plant.html"))
        router.add_get("/plant", self._page("plant.html"))
        router.add_get("/api/plant", self._rows)

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
