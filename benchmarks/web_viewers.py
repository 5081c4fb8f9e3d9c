"""N viewers of the web console for the benchmarks: WebSocket clients that watch a node
and acknowledge each message as the page does once it has drawn it (console.js), on a
thread and loop of their own.  Not chromium: five headless browsers on a loaded 2-core
machine would measure the browsers' own CPU as much as the bridge's."""

from __future__ import annotations

import asyncio
import threading


class Viewers:
    def __init__(self, base: str, n: int, watch: int = 0) -> None:
        self.base, self.n, self.watch = base, n, watch
        self.messages = [0] * n
        self._stop: asyncio.Event | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), name="bench-viewers", daemon=True)

    def __enter__(self) -> Viewers:
        if self.n:
            self._thread.start()
            if not self._ready.wait(15):
                raise SystemExit(f"bench: {self.n} viewers did not connect to {self.base} within 15 s")
        return self

    def __exit__(self, *exc: object) -> None:
        if self._loop is not None and self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
            self._thread.join(10)

    async def _main(self) -> None:
        import aiohttp

        self._loop, self._stop = asyncio.get_running_loop(), asyncio.Event()
        async with aiohttp.ClientSession() as http:
            sockets = [await http.ws_connect(f"{self.base}/ws", headers={"Origin": self.base}) for _ in range(self.n)]
            for ws in sockets:
                await ws.send_str(f'{{"watch": {self.watch}}}')
            self._ready.set()
            tasks = [asyncio.ensure_future(self._view(i, ws)) for i, ws in enumerate(sockets)]
            await self._stop.wait()
            for t in tasks:
                t.cancel()
            for ws in sockets:
                await ws.close()

    async def _view(self, i: int, ws) -> None:
        import aiohttp

        async for msg in ws:
            if msg.type != aiohttp.WSMsgType.TEXT:
                break
            self.messages[i] += 1
            await ws.send_str('{"ack":1}')
