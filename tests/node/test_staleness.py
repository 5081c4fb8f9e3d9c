"""Staleness that tracks the sensor, not the host's scheduling: a healthy 100 Hz
sensor whose scans reach the loop 40 ms apart now and then (a loaded host) stops
reading SENSOR_STALE after the first such gap, while a silent one is still flagged
within ``[output] stale_max_s`` (node/staleness.py)."""

from __future__ import annotations

import time

import numpy as np

from eskin_industrial.bridge.loop import NodeLoop
from eskin_industrial.bus.source import Source
from eskin_industrial.frames import RawScan
from eskin_industrial.node import NodeSnapshot
from eskin_industrial.node.staleness import Staleness
from eskin_industrial.outputs.base import Sink
from eskin_industrial.profile import load_profile
from tests.helpers.bridge import PAPER, hold_raw


def test_the_limit_learns_the_arrivals_and_stays_bounded():
    s = Staleness(0.025, 0.1)
    rx = 0.0
    for k in range(1, 300):
        rx += 0.040 if k % 50 == 0 else 0.010  # a 40 ms gap every half second
        s.observe(rx)
    assert 0.059 < s.limit_s <= 0.060  # 1.5 x the longest gap lately: 40 ms is no longer stale
    s.observe(rx + 0.5)  # a silence of half a second teaches nothing
    assert 0.058 < s.limit_s <= 0.060
    t = rx + 0.5
    for _ in range(100 * 200):  # 200 s of regular arrivals: the learnt gap decays away
        t += 0.010
        s.observe(t)
    assert s.limit_s == 0.025
    fixed = Staleness(0.025, 0.025)  # stale_max_s = stale_s: the fixed limit
    for k in range(100):
        fixed.observe(k * 0.04)
    assert fixed.limit_s == 0.025


class Hiccups(Source[None]):
    """100 Hz scans with a 40 ms gap every ``every`` scans, silent after ``silent_after``."""

    kind = "hiccups"

    def __init__(self, raw: np.ndarray, every: int, silent_after: int) -> None:
        super().__init__()
        self.raw, self.every, self.silent_after = raw, every, silent_after
        self.k = 0
        self.next = time.monotonic()
        self.sent: list[float] = []

    def _poll(self, timeout_s: float | None) -> RawScan | None:
        if self.k >= self.silent_after:
            time.sleep(min(timeout_s or 0.01, 0.01))
            return None
        wait = self.next - time.monotonic()
        if wait > (timeout_s if timeout_s is not None else 1.0):
            time.sleep(max(timeout_s or 0.0, 0.0))
            return None
        time.sleep(max(wait, 0.0))
        k = self.k
        self.k += 1
        self.next += 0.040 if (k + 1) % self.every == 0 else 0.010
        now = time.monotonic()
        self.sent.append(now)
        return RawScan(k, k * 0.01, self.raw[k % len(self.raw)], 0, now)


class Keep(Sink):
    def __init__(self) -> None:
        super().__init__()
        self.seen: list[tuple[float, NodeSnapshot]] = []

    def _publish(self, snapshot: NodeSnapshot) -> None:
        self.seen.append((time.monotonic(), snapshot))


def test_a_healthy_sensor_with_gaps_is_not_stale_and_a_silent_one_is():
    profile = load_profile(PAPER)
    source, keep = Hiccups(hold_raw(profile, 400), every=30, silent_after=400), Keep()
    loop = NodeLoop(profile, source, [keep])
    end = time.monotonic() + 5.5
    while time.monotonic() < end:
        loop.step()
    first_gap = source.sent[30]  # after the first 40 ms gap the limit has learnt it
    last = source.sent[-1]
    healthy = [s for t, s in keep.seen if first_gap < t < last]
    stale = [s for s in healthy if s.stale]
    assert len(healthy) > 50 and len(stale) <= 1, f"{len(stale)} stale publications of {len(healthy)}"
    flagged = next(t for t, s in keep.seen if t > last and s.stale)
    assert flagged - last <= profile.stale_max_s + 0.02, flagged - last
