"""Run the vcan tests on a real SocketCAN stack.

- Inside the emulated machine (or wherever ``ESKIN_VCAN_CHANNEL`` names a ready
  channel): the tests run as they are.
- On a kernel with CAN: on a native ``vcan0`` (created when missing, as root).
- Otherwise: one emulated machine boots for the whole test run (``vm.py``), runs
  ``pytest tests/vcan`` inside, and each test here reports its outcome there.

A missing prerequisite skips the tests with the reason, and fails them when ``CI``
is set (CI must not pass by skipping).
"""
from __future__ import annotations

import fcntl
import functools
import json
import os
import shlex
import shutil
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest

from . import vm

#: The emulated machine runs without KVM: its tests take about 2 minutes on a quiet
#: host and were measured at 265 s (plus its boot) on a loaded one, past 300 s in all.
GUEST_TIMEOUT_S = 600.0


@dataclass(frozen=True)
class GuestOutcome:
    status: str  # passed, failed, skipped
    message: str = ""


@functools.cache
def _mode() -> tuple[str, str]:
    """("direct", channel), ("vm", ""), or ("missing", reason)."""
    channel = os.environ.get("ESKIN_VCAN_CHANNEL")
    if channel:
        return "direct", channel
    native = vm.native_vcan("vcan0")  # "" when ready, else why not
    if native == "":
        return "direct", "vcan0"
    missing = vm.missing_prerequisites()
    if missing:
        return "missing", (f"no native vcan0 ({native}) and the emulated machine needs: " + ", ".join(missing)
                           + " (scripts/setup installs them)")
    return "vm", ""


def _ci() -> bool:
    return os.environ.get("CI", "").lower() not in ("", "0", "false", "no")


@pytest.fixture(scope="session")
def vm_results(tmp_path_factory: pytest.TempPathFactory) -> dict[str, GuestOutcome]:
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    if worker is None:
        return _boot_and_run()
    # with workers (pytest-xdist), one machine for the run: the first worker to need it
    # boots it and writes the outcomes beside the workers' temporary folders (their
    # common parent is this run's own); the others wait on the lock and read them
    shared = tmp_path_factory.getbasetemp().parent / "vcan-outcomes.json"
    with open(shared.with_suffix(".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if shared.exists():
            return {k: GuestOutcome(*v) for k, v in json.loads(shared.read_text()).items()}
        results = _boot_and_run()
        shared.write_text(json.dumps({k: [v.status, v.message] for k, v in results.items()}))
        return results


def _boot_and_run() -> dict[str, GuestOutcome]:
    """Boot the machine, run ``pytest tests/vcan`` in it: each test's outcome by node id."""
    out = vm.CACHE / f"run-{os.getpid()}"
    run = vm.run_in_vm(
        f"{shlex.quote(sys.executable)} -m pytest -q -p no:cacheprovider -p no:hypothesispytest tests/vcan "
        "--junitxml=\"$ESKIN_VCAN_OUT/junit.xml\" -o junit_family=xunit1",
        out, timeout_s=GUEST_TIMEOUT_S)
    try:
        report = out / "junit.xml"
        if run.rc is None or not report.exists():
            tail = (run.console or run.boot_log)[-3000:]
            return {"*": GuestOutcome("failed", f"the emulated machine did not finish ({run.seconds:.0f} s): {tail}")}
        results: dict[str, GuestOutcome] = {}
        for case in ET.parse(report).getroot().iter("testcase"):
            key = case.get("classname", "").replace(".", "/") + ".py::" + case.get("name", "")
            failure = case.find("failure")
            if failure is None:
                failure = case.find("error")
            skipped = case.find("skipped")
            if failure is not None:
                results[key] = GuestOutcome("failed", (failure.get("message", "") + "\n" + (failure.text or ""))[-4000:])
            elif skipped is not None:
                results[key] = GuestOutcome("skipped", skipped.get("message", ""))
            else:
                results[key] = GuestOutcome("passed")
        return results
    finally:
        shutil.rmtree(out, ignore_errors=True)


@pytest.fixture
def vcan(request) -> str | GuestOutcome:
    """The channel to use, or (on the host, when the tests ran in the machine) the
    outcome there."""
    mode, detail = _mode()
    if mode == "direct":
        return detail
    if mode == "missing":
        if _ci():
            pytest.fail(f"vcan: {detail}", pytrace=False)
        pytest.skip(f"vcan: {detail}")
    results = request.getfixturevalue("vm_results")
    if "*" in results:
        return results["*"]
    nodeid = request.node.nodeid
    return results.get(nodeid, GuestOutcome("failed", f"{nodeid} did not run in the emulated machine"))


@pytest.hookimpl(tryfirst=True)
def pytest_pyfunc_call(pyfuncitem):
    outcome = pyfuncitem.funcargs.get("vcan")
    if not isinstance(outcome, GuestOutcome):
        return None
    if outcome.status == "passed":
        return True
    if outcome.status == "skipped":
        pytest.skip(f"in the emulated machine: {outcome.message}")
    pytest.fail(f"in the emulated machine: {outcome.message}", pytrace=False)


def pytest_collection_modifyitems(items):
    for item in items:
        if Path(str(item.fspath)).parent == Path(__file__).parent:
            item.add_marker(pytest.mark.vcan)
            item.add_marker(pytest.mark.slow)  # a machine boots for them, or they pace real traffic
