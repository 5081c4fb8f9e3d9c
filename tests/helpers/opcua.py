"""Peers of the OPC UA tests: node-opcua (an independent stack, ``tests/opcua_peer``,
installed by ``scripts/setup test`` with ``npm ci``) driven over JSON lines, and a
bridge configuration with the OPC UA output.  Every peer is a child process of the
test's own, killed by its pid."""

from __future__ import annotations

import contextlib
import json
import os
import queue
import shutil
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from eskin_industrial.node import NodeSnapshot
from eskin_industrial.outputs.base import Sink
from tests.helpers.paths import ROOT

PEER_DIR = ROOT / "tests" / "opcua_peer"
NAMESPACE_URI = "urn:eskin-industrial:opcua:grasp"


def need_node_peer(peer_dir: Path, package: str) -> str:
    """The ``node`` executable, with ``package`` installed in ``peer_dir`` (a test-only
    npm package set, pinned by its lock file); a missing one skips the test (fails it
    in CI: ``CI=true``)."""
    node = shutil.which("node")
    problem = None
    if node is None:
        problem = "node (Node.js) is missing: scripts/setup test installs it from Debian"
    elif not (peer_dir / "node_modules" / package).is_dir():
        problem = f"{peer_dir.relative_to(ROOT)}/node_modules is missing: run scripts/setup test (npm ci)"
    if problem is not None:
        if os.environ.get("CI") == "true":
            pytest.fail(problem)
        pytest.skip(problem)
    assert node is not None
    return node


def need_peer() -> str:
    """The ``node`` executable with node-opcua installed (:func:`need_node_peer`)."""
    return need_node_peer(PEER_DIR, "node-opcua-client")


class PeerError(AssertionError):
    """The peer answered ``ok: false``."""

    def __init__(self, answer: dict[str, Any]) -> None:
        super().__init__(f"{answer.get('error')} ({answer.get('status')})")
        self.answer = answer
        self.status = answer.get("status")


class NodePeer:
    """One node-opcua client process: :meth:`ask` sends a request and waits for its
    answer; what subscriptions deliver is in :attr:`events`."""

    def __init__(self, timeout_s: float = 20.0) -> None:
        self.timeout_s = timeout_s
        self.proc = subprocess.Popen([need_peer(), str(PEER_DIR / "peer.js")], cwd=PEER_DIR, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
        self._answers: queue.Queue[dict[str, Any]] = queue.Queue()
        self.events: queue.Queue[dict[str, Any]] = queue.Queue()
        self.stderr: list[str] = []
        self._ids = 0
        self._reader = threading.Thread(target=self._read, name="opcua-peer-out", daemon=True)
        self._errors = threading.Thread(target=self._read_err, name="opcua-peer-err", daemon=True)
        self._reader.start()
        self._errors.start()
        ready = self.events.get(timeout=timeout_s)
        assert ready.get("event") == "ready", ready

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            try:
                msg = json.loads(line)
            except ValueError:
                self.stderr.append(line)
                continue
            (self.events if "event" in msg else self._answers).put(msg)

    def _read_err(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self.stderr.append(line)

    def ask(self, op: str, timeout_s: float | None = None, **fields: Any) -> dict[str, Any]:
        """The answer to one request; :class:`PeerError` for ``ok: false``."""
        answer = self.try_ask(op, timeout_s, **fields)
        if not answer["ok"]:
            raise PeerError(answer)
        return answer

    def try_ask(self, op: str, timeout_s: float | None = None, **fields: Any) -> dict[str, Any]:
        self._ids += 1
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"id": self._ids, "op": op, **fields}) + "\n")
        self.proc.stdin.flush()
        try:
            answer = self._answers.get(timeout=timeout_s or self.timeout_s)
        except queue.Empty:
            raise AssertionError(f"node-opcua peer: no answer to {op} within {timeout_s or self.timeout_s} s; "
                                 f"stderr: {''.join(self.stderr[-20:])}") from None
        assert answer.get("id") == self._ids, answer
        return answer

    def wait_event(self, match: Callable[[dict[str, Any]], bool], timeout_s: float = 10.0,
                   what: str = "event") -> dict[str, Any]:
        """The first event (data change, alarm) that ``match`` accepts; the others seen
        on the way are kept in :attr:`seen`."""
        deadline = time.monotonic() + timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise AssertionError(f"node-opcua peer: no {what} within {timeout_s} s")
            try:
                e = self.events.get(timeout=left)
            except queue.Empty:
                continue
            self.seen.append(e)
            if match(e):
                return e

    seen: list[dict[str, Any]] = []

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                assert self.proc.stdin is not None
                self.proc.stdin.close()
                self.proc.wait(timeout=5)
            except (subprocess.TimeoutExpired, OSError):
                self.proc.kill()  # by its own handle: this process's child
                self.proc.wait(timeout=5)
        for stream in (self.proc.stdout, self.proc.stderr):
            if stream is not None:
                stream.close()
        self._reader.join(timeout=5)
        self._errors.join(timeout=5)


@contextlib.contextmanager
def node_peer(timeout_s: float = 20.0) -> Iterator[NodePeer]:
    peer = NodePeer(timeout_s)
    peer.seen = []
    try:
        yield peer
    finally:
        peer.close()


def wait_listening(port: int, timeout_s: float = 60.0) -> None:
    """A server listens on the loopback port (a bridge starting in another process)."""
    import socket

    deadline = time.monotonic() + timeout_s
    while True:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        assert time.monotonic() < deadline, f"nothing listens on 127.0.0.1:{port} within {timeout_s} s"
        time.sleep(0.05)


def by_path(nodes: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    return {n["path"]: n for n in nodes}


def opcua_config(*nodes: Any, **options: Any) -> Any:
    """A bridge of these nodes with the OPC UA output alone, on a free loopback port
    (``options``: more ``[opcua]`` keys)."""
    from eskin_industrial.bridge.config import BridgeConfig, LogSettings
    from eskin_industrial.outputs.opcua.options import OpcuaOptions
    from tests.helpers.modbus import free_port

    keys = {"endpoint": f"opc.tcp://127.0.0.1:{free_port()}", "offline_linger_s": 0.3, **options}
    return BridgeConfig(node=nodes, outputs={"opcua": OpcuaOptions(**keys)},
                        log=LogSettings(format="json", status_every_s=0))


class Capture(Sink):
    """A sink that keeps every snapshot and frame the loop hands it (beside the
    OPC UA output, on the same loop): what the server was given."""

    def __init__(self, frame_every_s: float | None = None) -> None:
        super().__init__()
        self.snapshots: list[NodeSnapshot] = []
        self.frames: list[Any] = []
        self.frame_every_s = frame_every_s

    def _publish(self, snapshot: NodeSnapshot) -> None:
        self.snapshots.append(snapshot)

    def on_frame(self, frame: Any) -> None:
        self.frames.append(frame.forces.astype("<f4").copy())
