"""The tests' own Sparkplug B decoder and encoder: the ``protobuf`` package with
message classes from the specification's own schema (``sparkplug_b.proto``, as the
Sparkplug 3.0.0 specification prints it), compiled by ``protoc`` when first needed;
and a mosquitto broker and ``mosquitto_sub`` capture on a loopback port of the
test's own."""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from tests.helpers.modbus import free_port, need

PROTO = Path(__file__).with_name("sparkplug_b.proto")
PACKAGE = "org.eclipse.tahu.protobuf"  #: the schema's own package


@functools.cache
def classes() -> dict[str, Any]:
    """The schema's message classes by their short name (``Payload``, ``Metric``,
    ``PropertySet``, ...): ``protoc`` compiles the specification's file to descriptors,
    the ``protobuf`` package builds the classes from them (no generated code kept)."""
    protoc = need("protoc")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "sparkplug_b.pb"
        subprocess.run([protoc, f"--proto_path={PROTO.parent}", f"--descriptor_set_out={out}", PROTO.name],
                       check=True, capture_output=True, timeout=60)
        files = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes())
    pool = descriptor_pool.DescriptorPool()
    for fd in files.file:
        pool.Add(fd)
    payload = pool.FindMessageTypeByName(f"{PACKAGE}.Payload")
    out_classes = {"Payload": message_factory.GetMessageClass(payload)}
    for nested in payload.nested_types:
        out_classes[nested.name] = message_factory.GetMessageClass(nested)
    return out_classes


def __getattr__(name: str) -> Any:
    """``Payload`` and ``MESSAGES``, built on first use (a test without protoc is
    skipped, or fails in CI, there and not at import)."""
    if name == "Payload":
        return classes()["Payload"]
    if name == "MESSAGES":
        return classes()
    raise AttributeError(name)


@pytest.fixture(autouse=True)
def state_home(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Autouse where imported: the edge node's state folder (its bdSeq file, when no
    store_dir is given) is the test's own, not the user's, and starts empty."""
    home = tmp_path_factory.mktemp("state")
    monkeypatch.delenv("STATE_DIRECTORY", raising=False)
    monkeypatch.setenv("XDG_STATE_HOME", str(home))
    return home


def parse(data: bytes) -> Any:
    p = classes()["Payload"]()
    p.ParseFromString(data)
    return p


def value(m: Any) -> Any:
    """The metric's value as the specification's datatype says (None when absent)."""
    for f in ("int_value", "long_value", "float_value", "double_value", "boolean_value", "string_value",
              "bytes_value"):
        if m.HasField(f):
            v = getattr(m, f)
            if f == "int_value" and m.datatype in (1, 2, 3) and v >= 1 << 31:
                v -= 1 << 32
            if f == "long_value" and m.datatype == 4 and v >= 1 << 63:
                v -= 1 << 64
            return v
    return None


def metric_value(p: Any, name: str) -> Any:
    (m,) = [m for m in p.metrics if m.name == name]
    return value(m)


class Broker:
    """A mosquitto of the test's own on a loopback port; killed by its pid."""

    def __init__(self, tmp: Path, port: int | None = None, conf_lines: str = "allow_anonymous true\n") -> None:
        self.port = port or free_port()
        conf = tmp / f"mosquitto-{self.port}.conf"
        #: mosquitto's log: connections ("New client connected ... (p2, c1, k30)"), clean
        #: disconnects ("Client ID disconnected."), subscriptions ("ID QOS TOPIC")
        self.log = tmp / f"mosquitto-{self.port}.log"
        # user root: a broker started as root keeps reading the test's own files (no
        # effect when the tests run as another user)
        conf.write_text(f"listener {self.port} 127.0.0.1\npersistence false\nuser root\n"
                        f"log_dest file {self.log}\nlog_type notice\nlog_type information\nlog_type subscribe\n"
                        f"log_type unsubscribe\n{conf_lines}")
        self.proc = subprocess.Popen([need("mosquitto"), "-c", str(conf)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        try:
            _wait_port(self.port, self.proc)
        except BaseException:
            self.kill()
            raise

    def log_lines(self) -> list[str]:
        """The broker's log, each line without its time stamp."""
        if not self.log.exists():
            return []
        return [line.partition(": ")[2] for line in self.log.read_text(errors="replace").splitlines()]

    def kill(self) -> None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(5)


@contextlib.contextmanager
def broker(tmp: Path) -> Iterator[int]:
    """A broker for the length of the block; yields its port."""
    b = Broker(tmp)
    try:
        yield b.port
    finally:
        b.kill()


def _wait_port(port: int, proc: subprocess.Popen) -> None:
    import socket

    deadline = time.monotonic() + 5
    while True:
        assert proc.poll() is None, "mosquitto exited"
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        assert time.monotonic() < deadline, "mosquitto does not listen"
        time.sleep(0.02)


READY = "eskin-test/ready"


class Capture:
    """``mosquitto_sub`` (the third-party peer): every message as (topic, payload bytes).

    With ``detail`` it subscribes at QoS 1 over MQTT 5 with retain-as-published, so
    that each message's QoS is the one it was published with (up to 1) and its retain
    flag the publisher's: :meth:`records` gives (topic, qos, retain, payload).  Ready
    when a message of its own on :data:`READY` has come back (its subscription is in
    place), never after a fixed wait."""

    def __init__(self, port: int, out: Path, *args: str, detail: bool = False) -> None:
        self.out = out
        self.detail = detail
        self._file = open(out, "w")
        fmt = ["-q", "1", "-V", "mqttv5", "--retain-as-published", "-F", "%t %q %r %x"] if detail else ["-F", "%t %x"]
        self.proc = subprocess.Popen([need("mosquitto_sub"), "-h", "127.0.0.1", "-p", str(port), "-t", "spBv1.0/#",
                                      "-t", READY, "-v", *fmt, *args], stdout=self._file,
                                     stderr=subprocess.DEVNULL)
        try:  # (``args``: the connection's, TLS and credentials: the probe's publisher takes them too)
            deadline = time.monotonic() + 10
            while not any(line.startswith(READY) for line in out.read_text().splitlines()):
                assert self.proc.poll() is None and time.monotonic() < deadline, "mosquitto_sub does not subscribe"
                subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-t", READY, "-m", "1",
                                *args], check=False, timeout=10, capture_output=True)
                time.sleep(0.05)
        except BaseException:
            self.close()
            raise

    def _lines(self) -> list[str]:
        """The whole lines written so far (a line being written is left for later)."""
        text = self.out.read_text()
        return text.splitlines() if text.endswith("\n") else text.splitlines()[:-1]

    def records(self) -> list[tuple[str, int, bool, bytes]]:
        """(topic, qos, retain, payload) of every Sparkplug message (``detail`` only)."""
        out = []
        for line in self._lines():
            if line.startswith(READY):
                continue
            topic, qos, retain, hexed = (line.split(" ") + ["", "", ""])[:4]
            out.append((topic, int(qos), retain == "1", bytes.fromhex(hexed)))
        return out

    def messages(self) -> list[tuple[str, bytes]]:
        if self.detail:
            return [(t, p) for t, _, _, p in self.records()]
        out = []
        for line in self._lines():
            if line.startswith(READY):
                continue
            topic, _, hexed = line.partition(" ")
            out.append((topic, bytes.fromhex(hexed)))
        return out

    def wait(self, cond: Any, timeout_s: float = 10.0) -> list[tuple[str, bytes]]:
        deadline = time.monotonic() + timeout_s
        while True:
            msgs = self.messages()
            if cond(msgs):
                return msgs
            assert time.monotonic() < deadline, f"not seen within {timeout_s} s: {[t for t, _ in msgs]}"
            time.sleep(0.05)

    def close(self) -> None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(5)
        self._file.close()


def send_rebirth(port: int, group: str, edge: str, tmp: Path) -> None:
    """An NCMD ``Node Control/Rebirth`` = true, encoded by protobuf, sent by ``mosquitto_pub``."""
    cmd = classes()["Payload"](timestamp=int(time.time() * 1000))
    cmd.metrics.add(name="Node Control/Rebirth", datatype=11, boolean_value=True)
    f = tmp / "rebirth.bin"
    f.write_bytes(cmd.SerializeToString())
    subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(port), "-q", "0",
                    "-t", f"spBv1.0/{group}/NCMD/{edge}", "-f", str(f)], check=True, timeout=10)


def certificates(tmp: Path) -> dict[str, Path]:
    """A CA of the test's own (``openssl``), a server certificate for 127.0.0.1 and a
    client certificate, both signed by it; PEM files in ``tmp``."""
    openssl = need("openssl")
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    files = {k: tmp / f"{k}.pem" for k in ("ca", "ca_key", "server", "server_key", "client", "client_key")}

    def run(*args: str) -> None:
        subprocess.run([openssl, *args], check=True, capture_output=True, timeout=30)

    run("req", "-x509", *ec, "-keyout", str(files["ca_key"]), "-out", str(files["ca"]), "-days", "1",
        "-subj", "/CN=eskin test CA")
    ext = tmp / "san.ext"
    ext.write_text("subjectAltName = IP:127.0.0.1\n")
    for who, cn in (("server", "127.0.0.1"), ("client", "cell7")):
        csr = tmp / f"{who}.csr"
        run("req", *ec, "-keyout", str(files[f"{who}_key"]), "-out", str(csr), "-subj", f"/CN={cn}")
        run("x509", "-req", "-in", str(csr), "-CA", str(files["ca"]), "-CAkey", str(files["ca_key"]),
            "-CAcreateserial", "-out", str(files[who]), "-days", "1", *(["-extfile", str(ext)] if who == "server" else []))
    return files


def password_file(tmp: Path, users: dict[str, str]) -> Path:
    """A mosquitto password file made by ``mosquitto_passwd``."""
    f = tmp / "mosquitto.passwd"
    for i, (user, pw) in enumerate(users.items()):
        subprocess.run([need("mosquitto_passwd"), "-b", *(["-c"] if i == 0 else []), str(f), user, pw], check=True,
                       capture_output=True, timeout=10)
    return f


TCK_IDS = Path(__file__).with_name("sparkplug_tck_ids.txt")


def tck_ids() -> dict[str, str]:
    """Every tck-id of Sparkplug 3.0.0 -> the requirement words of its statement
    (``MUST``, ``MUST NOT``, ``SHOULD``, ``SHOULD NOT``, ``MAY``, comma-separated)."""
    out = {}
    for line in TCK_IDS.read_text().splitlines():
        if line and not line.startswith("#"):
            tck, _, words = line.partition(" ")
            out[tck] = words
    return out
