"""The leak check every test runs under (tests/helpers/leaks.py): a test that leaves a
thread, a socket or a virtual CAN bus open fails, naming it; one that cleans up passes.

The cases run in one pytest of their own (a subprocess), so what they leak stays there."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import pytest

from tests.helpers.paths import ROOT

CASES = '''
import socket
import threading
import time

import can
import pytest

stop = threading.Event()
kept = []


@pytest.fixture(scope="module")
def server():
    with socket.create_server(("127.0.0.1", 0)) as srv:
        yield srv


def test_leaks_a_thread():
    threading.Thread(target=stop.wait, name="forgotten-worker", daemon=True).start()


def test_leaks_a_server_and_a_connection():
    srv = socket.create_server(("127.0.0.1", 0))
    kept.extend([srv, socket.create_connection(srv.getsockname())])


def test_leaks_a_bus():
    kept.append(can.Bus(interface="virtual", channel="left-open-7"))


def test_closes_its_sockets():
    with socket.create_server(("127.0.0.1", 0)) as srv:
        with socket.create_connection(srv.getsockname()):
            conn, _ = srv.accept()
            conn.close()


def test_shuts_its_bus_down():
    with can.Bus(interface="virtual", channel="closed-8") as bus:
        bus.send(can.Message(arbitration_id=1, data=b"x"))


def test_a_thread_that_ends_soon_after():
    threading.Thread(target=time.sleep, args=(0.1,), name="winding-down").start()


def test_a_joined_thread():
    t = threading.Thread(target=lambda: None)
    t.start()
    t.join()


def test_a_module_server_is_not_this_tests_leak(server):
    assert server.getsockname()[1] > 0


@pytest.mark.allow_leaks("the thread is the point of this test")
def test_deliberate():
    threading.Thread(target=stop.wait, name="on-purpose", daemon=True).start()


@pytest.mark.allow_leaks()
def test_no_reason():
    pass
'''


@dataclass(frozen=True)
class Outcome:
    status: str  # passed, failed, error
    message: str


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory) -> dict[str, Outcome]:
    tmp = tmp_path_factory.mktemp("leaks")
    (tmp / "conftest.py").write_text("from tests.helpers.leaks import no_leaks  # noqa: F401\n")
    (tmp / "test_cases.py").write_text(textwrap.dedent(CASES))
    (tmp / "pytest.ini").write_text("[pytest]\naddopts = --strict-markers\nfilterwarnings = error\n"
                                    "markers =\n    allow_leaks(reason): deliberate\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "ESKIN_TEST_LEAK_GRACE_S": "0.5"}
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          f"--junitxml={tmp / 'junit.xml'}", str(tmp)],
                         cwd=tmp, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 1, res.stdout + res.stderr  # some cases fail, by design
    out: dict[str, Outcome] = {}
    for case in ET.parse(tmp / "junit.xml").getroot().iter("testcase"):
        bad = case.find("failure")
        if bad is None:
            bad = case.find("error")
        if bad is None:
            out[case.get("name", "")] = Outcome("passed", "")
        else:
            out[case.get("name", "")] = Outcome(bad.tag, bad.text or bad.get("message") or "")
    assert len(out) == 10, res.stdout
    return out


def test_a_leaked_thread_fails_the_test_and_is_named(outcomes):
    case = outcomes["test_leaks_a_thread"]
    assert case.status == "error", case
    assert "thread 'forgotten-worker' (daemon) running threading.Event.wait" in case.message
    assert "still there 0.5 s later" in case.message


def test_a_leaked_listening_socket_and_connection_fail_the_test_with_their_addresses(outcomes):
    case = outcomes["test_leaks_a_server_and_a_connection"]
    assert case.status == "error", case
    assert "(listening)" in case.message and "tcp 127.0.0.1:" in case.message
    assert "ESTABLISHED" in case.message
    # the server's end was never accepted: the test holds two descriptors, not three
    assert case.message.count("socket fd ") == 2, case.message
    assert "thread" not in case.message  # nothing leaked from the earlier case is blamed here


def test_a_virtual_bus_left_open_fails_the_test_with_its_channel(outcomes):
    case = outcomes["test_leaks_a_bus"]
    assert case.status == "error", case
    assert "python-can virtual bus on channel 'left-open-7' not shut down" in case.message
    assert "socket" not in case.message


@pytest.mark.parametrize("name", ["test_closes_its_sockets", "test_shuts_its_bus_down",
                                  "test_a_thread_that_ends_soon_after", "test_a_joined_thread",
                                  "test_a_module_server_is_not_this_tests_leak"])
def test_what_is_closed_ends_in_the_grace_period_or_was_open_before_passes(outcomes, name):
    assert outcomes[name] == Outcome("passed", "")


def test_allow_leaks_lets_a_deliberate_leak_pass_and_needs_a_reason(outcomes):
    assert outcomes["test_deliberate"] == Outcome("passed", "")
    case = outcomes["test_no_reason"]
    assert case.status == "error" and "allow_leaks needs a reason" in case.message, case
