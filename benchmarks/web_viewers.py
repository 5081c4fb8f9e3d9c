"""N viewers of the web console for the benchmarks: WebSocket clients that watch a node,
decode each message as the page does (console.js) and acknowledge it once "drawn", in a
process of their own, as browsers are: the bridge's process pays for what it sends, not
for its viewers' decoding (nor shares its interpreter's lock with them).  Not chromium:
five headless browsers on a loaded 2-core machine would measure the browsers' own CPU
as much as the bridge's.

    python benchmarks/web_viewers.py http://127.0.0.1:PORT N   # "ready", then the counts at EOF of stdin
"""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


class Viewers:
    """``with Viewers(base, n) as seen``: the viewers connected; ``seen.messages`` per
    viewer once left."""

    def __init__(self, base: str, n: int, watch: int = 0) -> None:
        self.base, self.n, self.watch = base, n, watch
        self.messages = [0] * n
        self._proc: subprocess.Popen[str] | None = None

    def __enter__(self) -> Viewers:
        if self.n:
            self._proc = subprocess.Popen([sys.executable, __file__, self.base, str(self.n), str(self.watch)],
                                          stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
            assert self._proc.stdout is not None
            ready: list[str] = []
            reader = threading.Thread(target=lambda: ready.append(self._proc.stdout.readline()), daemon=True)  # type: ignore[union-attr]
            reader.start()
            reader.join(15)
            if not ready or ready[0].strip() != "ready":
                self._proc.kill()
                raise SystemExit(f"bench: {self.n} viewers did not connect to {self.base} within 15 s")
        return self

    def __exit__(self, *exc: object) -> None:
        if self._proc is not None:
            out, _ = self._proc.communicate("", timeout=15)
            self.messages = json.loads(out.strip().splitlines()[-1])


async def _main(base: str, n: int, watch: int) -> None:
    import aiohttp

    from eskin_industrial.outputs.web.wire import decode

    counts = [0] * n

    async def view(i: int, ws: aiohttp.ClientWebSocketResponse) -> None:
        async for msg in ws:
            if msg.type == aiohttp.WSMsgType.BINARY:
                decode(msg.data)
            elif msg.type == aiohttp.WSMsgType.TEXT:
                json.loads(msg.data)
            else:
                break
            counts[i] += 1
            await ws.send_str('{"ack":1}')

    async with aiohttp.ClientSession() as http:
        sockets = [await http.ws_connect(f"{base}/ws", headers={"Origin": base}) for _ in range(n)]
        for ws in sockets:
            await ws.send_str(f'{{"watch": {watch}}}')
        tasks = [asyncio.ensure_future(view(i, ws)) for i, ws in enumerate(sockets)]
        print("ready", flush=True)
        await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)  # until the bench is done
        for t in tasks:
            t.cancel()
        for ws in sockets:
            await ws.close()
    print(json.dumps(counts), flush=True)


if __name__ == "__main__":
    asyncio.run(_main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]) if len(sys.argv) > 3 else 0))
