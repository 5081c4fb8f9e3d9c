"""Client mode against PLCs that misbehave: one that accepts and resets, one that
refuses, one that never answers, one that answers late, one that answers with
exceptions.  The writer backs off (a delay that doubles, with jitter, that no urgent
offer wakes), counts what failed and how, logs every outage once at its start and
once at its end, and the PLC gets the newest image when it answers again."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

import pytest

from eskin_industrial.outputs.plc.client import JITTER, PlcWriter
from eskin_industrial.outputs.plc.image import REG, STATUS_COUNT, TAIL_AT, TAIL_COUNT, Status
from tests.helpers.modbus import free_port
from tests.helpers.plc_standin import PlcStandIn


def wait_for(cond, timeout_s: float = 5.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, f"{what}: not met within {timeout_s} s"
        time.sleep(0.005)


class Events:
    """The writer's own log events, as the bridge would get them."""

    def __init__(self, writer: PlcWriter) -> None:
        self.all: list[tuple[str, str, dict]] = []
        writer.on_events(lambda name, level, fields: self.all.append((name, level, fields)))

    def named(self, name: str) -> list[dict]:
        return [f for n, _, f in self.all if n == name]

    def names(self) -> list[str]:
        return [n for n, _, _ in self.all]


def image(n: int, status: Status = Status.DATA_VALID) -> list[int]:
    """A register image told apart by ``n`` (in its last register)."""
    return [int(status)] + [0] * (STATUS_COUNT - 2) + [n]


class Offering:
    """The bridge's loop, as the writer sees it: an image every ``period_s``, every
    ``urgent_every``-th one urgent (a state change), until stopped."""

    def __init__(self, writer: PlcWriter, period_s: float = 0.01, urgent_every: int = 3,
                 tail: tuple[int, ...] = ()) -> None:
        self.writer, self.period_s, self.urgent_every, self.tail = writer, period_s, urgent_every, tail
        self.n = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> Offering:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)

    def _run(self) -> None:
        while not self._stop.is_set():
            self.n += 1
            self.writer.offer(image(self.n), urgent=self.n % self.urgent_every == 0, t_event=time.perf_counter(),
                              tail=self.tail)
            time.sleep(self.period_s)


def most_attempts(span_s: float, backoff_s: float, backoff_max_s: float) -> int:
    """Connection attempts a doubling back-off allows in ``span_s``, with every wait
    as short as the jitter can make it (and one attempt more, for the first)."""
    n, t, d = 1, 0.0, backoff_s
    while True:
        t += d * (1 - JITTER)
        if t > span_s:
            return n
        n += 1
        d = min(2 * d, backoff_max_s)


def test_a_plc_that_accepts_then_resets_gets_a_doubling_back_off(paper_profile):
    settings = paper_profile.modbus.plc  # backoff 0.1 s doubling to 2 s
    with PlcStandIn("reset") as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port).start()
        events = Events(writer)
        try:
            with Offering(writer):
                time.sleep(4.0)
        finally:
            writer.stop(flush_s=0.0)
        time.sleep(0.1)  # the stand-in notes the last connection
        connects = list(plc.seen.connects)
    # The old writer reconnected at once after each reset: thousands in 4 s.
    assert 4 <= len(connects) <= most_attempts(4.0, settings.backoff_s, settings.backoff_max_s) + 1
    gaps = [b - a for a, b in zip(connects, connects[1:])]
    # Each wait doubles (jitter takes at most a quarter off): 0.1, 0.2, 0.4, 0.8 s...
    # (a loaded machine only makes them longer)
    for i, gap in enumerate(gaps[:4]):
        assert gap >= (1 - JITTER) * settings.backoff_s * 2 ** i - 0.005, gaps
    assert writer.stats.writes == 0 and writer.stats.connect_attempts == len(connects)
    # One outage, logged once, still going on.
    assert events.names() == ["plc_unreachable"]
    assert events.named("plc_unreachable")[0]["cause"] == "connection"
    assert writer.stats.outages == 1


def test_urgent_offers_do_not_wake_the_back_off_from_a_refused_connection(paper_profile):
    settings = paper_profile.modbus.plc
    port = free_port()  # nobody listens: every connection is refused at once
    writer = PlcWriter(settings, "127.0.0.1", port).start()
    events = Events(writer)
    try:
        with Offering(writer, period_s=0.005, urgent_every=1) as offering:  # 200 urgent offers a second
            time.sleep(3.0)
        attempts = writer.stats.connect_attempts
        assert offering.n > 300
    finally:
        writer.stop(flush_s=0.0)
    # The old writer retried every 50 ms when urgent offers came (60 in 3 s).
    assert 3 <= attempts <= most_attempts(3.0, settings.backoff_s, settings.backoff_max_s)
    assert writer.stats.failures == attempts and writer.stats.connects == 0
    assert writer.stats.superseded >= offering.n - 2  # each offer replaced the one before
    assert events.names() == ["plc_unreachable"]


@pytest.mark.parametrize("code", [2, 4])
def test_exception_replies_are_counted_per_code_logged_once_and_backed_off(paper_profile, code):
    settings = paper_profile.modbus.plc
    with PlcStandIn("exception", code=code) as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port, poll_commands=False).start()
        events = Events(writer)
        try:
            with Offering(writer) as offering:
                time.sleep(3.0)
                refused = plc.seen.requests
                plc.mode = "ok"  # the PLC program is fixed: writes land again
                wait_for(lambda: events.named("plc_connected"), what="plc_connected")
                newest = offering.n
            wait_for(lambda: plc.regs[STATUS_COUNT - 1] >= newest, what="the newest image in the PLC")
        finally:
            writer.stop(flush_s=0.0)
    # The old writer wrote again at once after each exception: about 2,400 writes a second.
    assert 3 <= refused <= most_attempts(3.0, settings.backoff_s, settings.backoff_max_s) + 1
    c = writer.counters()
    assert c[f"plc_exception_{code:02d}"] >= refused and c["plc_exceptions"] == c[f"plc_exception_{code:02d}"]
    assert len(plc.seen.connects) == 1 and c["plc_connects"] == 1  # an exception is no reason to reconnect
    # Logged once at the start, once at the end.
    assert events.names() == ["plc_unreachable", "plc_connected"]
    start, end = events.named("plc_unreachable")[0], events.named("plc_connected")[0]
    assert start["cause"] == "exception" and start["exception"] == code and f"{code:02d}" in start["error"]
    assert 2.5 < end["outage_s"] < 6 and end["exceptions"] == f"{code:02d}:{c['plc_exceptions']}"
    assert end["superseded"] >= 100 and end["failures"] == c["plc_write_failures"]


def test_a_plc_that_never_answers_is_an_outage_logged_at_its_start_and_end(paper_profile):
    settings = replace(paper_profile.modbus.plc, timeout_s=0.2)
    with PlcStandIn("silent") as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port, poll_commands=False).start()
        events = Events(writer)
        try:
            with Offering(writer) as offering:
                # the first give-up (0.2 s + as long again) opens the outage at once
                wait_for(lambda: events.named("plc_unreachable"), timeout_s=1.5, what="plc_unreachable")
                time.sleep(3.0)
                assert writer.in_outage and not writer.health().connected
                requests, connects = plc.seen.requests, len(plc.seen.connects)
                plc.mode = "ok"
                wait_for(lambda: events.named("plc_connected"), timeout_s=4, what="plc_connected")
                newest = offering.n
            wait_for(lambda: plc.regs[STATUS_COUNT - 1] >= newest, what="the newest image in the PLC")
        finally:
            writer.stop(flush_s=0.0)
    # Each request waits 0.4 s, then a back-off: a handful of connections, one request each.
    assert 2 <= connects <= 7 and requests <= connects
    c = writer.counters()
    assert c["plc_write_timeouts"] >= 2 and c["plc_write_failures"] == c["plc_write_timeouts"]
    assert events.names() == ["plc_unreachable", "plc_connected"]
    start, end = events.named("plc_unreachable")[0], events.named("plc_connected")[0]
    assert start["cause"] == "timeout" and "no answer" in start["error"]
    assert 3.0 < end["outage_s"] < 7.5 and end["superseded"] >= 100 and end["attempts"] >= connects - 1


def test_a_plc_that_answers_late_gets_every_write_and_none_counts_as_failed(paper_profile):
    settings = paper_profile.modbus.plc  # timeout 0.5 s
    assert settings.timeout_s == 0.5
    with PlcStandIn("late", delay_s=0.6) as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port, poll_commands=False).start()
        events = Events(writer)
        try:
            with Offering(writer):
                wait_for(lambda: writer.stats.writes >= 3, timeout_s=5, what="three late writes")
        finally:
            writer.stop(flush_s=0.0)
    st = writer.stats
    assert st.failures == 0 and st.late_writes == st.writes >= 3
    assert len(plc.seen.connects) == 1  # no reconnection: the PLC is slow, not gone
    late = events.named("plc_late")
    assert len(late) == 1 and late[0]["answer_s"] > 0.5 and late[0]["timeout_s"] == 0.5
    assert "plc_unreachable" not in events.names()


def test_late_answers_end_when_the_plc_is_quick_again(paper_profile):
    settings = paper_profile.modbus.plc
    with PlcStandIn("late", delay_s=0.6) as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port, poll_commands=False).start()
        events = Events(writer)
        try:
            with Offering(writer):
                wait_for(lambda: writer.stats.late_writes >= 2, what="late writes")
                plc.mode = "ok"
                wait_for(lambda: events.named("plc_on_time"), what="plc_on_time")
        finally:
            writer.stop(flush_s=0.0)
    (back,) = events.named("plc_on_time")
    assert back["late_writes"] == writer.stats.late_writes >= 2 and back["late_s"] > 0.5
    assert writer.stats.failures == 0


def test_events_before_the_log_is_wired_are_held_for_it(paper_profile):
    writer = PlcWriter(paper_profile.modbus.plc, "127.0.0.1", free_port()).start()  # refused
    try:
        wait_for(lambda: writer.stats.failures >= 1, what="a refused connection")
        events = Events(writer)  # wired after the outage began
        assert events.names() == ["plc_unreachable"]
    finally:
        writer.stop(flush_s=0.0)


def test_a_stop_during_a_long_back_off_tries_the_offline_image_at_once(paper_profile):
    """The bridge's last image (BRIDGE_OFFLINE) is tried as soon as the writer is
    stopped, not after the back-off it was waiting out."""
    settings = replace(paper_profile.modbus.plc, backoff_s=5.0, backoff_max_s=5.0)
    port = free_port()
    writer = PlcWriter(settings, "127.0.0.1", port, poll_commands=False).start()
    try:
        wait_for(lambda: writer.stats.failures >= 1, what="a refused connection")  # now in a 5 s wait
        with PlcStandIn("ok", port=port) as plc:
            writer.offer(image(7, Status.BRIDGE_OFFLINE), urgent=True)
            time.sleep(0.3)
            assert not plc.seen.writes  # the urgent image did not end the wait
            t0 = time.monotonic()
            writer.stop(flush_s=1.0)
            assert time.monotonic() - t0 < 1.5 and writer.flushed
            assert plc.seen.writes and plc.seen.writes[-1][2][0] == int(Status.BRIDGE_OFFLINE)
    finally:
        writer.stop(flush_s=0.0)


def test_a_longer_timeout_takes_the_same_slow_plc_as_on_time(paper_profile):
    settings = replace(paper_profile.modbus.plc, timeout_s=1.0)
    with PlcStandIn("late", delay_s=0.6) as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port, poll_commands=False).start()
        events = Events(writer)
        try:
            writer.offer(image(1), urgent=True)
            wait_for(lambda: writer.stats.writes >= 1, what="a write")
        finally:
            writer.stop(flush_s=0.0)
    assert writer.stats.late_writes == 0 and writer.stats.failures == 0
    assert events.names() == ["plc_connected"]  # the first write, no outage before it


def test_the_slip_latch_reaches_a_plc_that_comes_back(paper_profile):
    """The PLC goes away; a slip is latched meanwhile, then the images go on (the
    latch stays set in each); the first write to the returned PLC carries it."""
    settings = paper_profile.modbus.plc
    plc = PlcStandIn("ok").start()
    writer = PlcWriter(settings, "127.0.0.1", plc.port, poll_commands=False).start()
    events = Events(writer)
    try:
        writer.offer(image(1))
        wait_for(lambda: plc.seen.writes, what="a first write")
        plc.go_down()
        writer.offer(image(2, Status.SLIP | Status.SLIP_LATCHED), urgent=True, t_event=time.perf_counter())
        for n in range(3, 50):
            writer.offer(image(n, Status.SLIP_LATCHED | Status.STABLE), urgent=n == 3)
            time.sleep(0.01)
        wait_for(lambda: events.named("plc_unreachable"), what="plc_unreachable")
        returned = PlcStandIn("ok", port=plc.port).start()
        try:
            wait_for(lambda: returned.seen.writes, timeout_s=settings.backoff_max_s + 2, what="a write after return")
            _, _, first = returned.seen.writes[0]
            assert first[0] & Status.SLIP_LATCHED and first[-1] == 49  # the newest image, latch and all
            wait_for(lambda: events.named("plc_connected")[1:], what="the end of the outage")
            end = events.named("plc_connected")[1]
            assert end["superseded"] >= 40 and end["cause"] == "connection"
        finally:
            returned.go_down()
    finally:
        writer.stop(flush_s=0.0)
        plc.go_down()


def test_a_plc_that_takes_writes_but_refuses_command_reads_is_no_outage(paper_profile):
    """A PLC whose map has no COMMAND/ENABLE: the image lands; the refused reads are
    counted per code, logged once, and backed off (not one every refresh_s)."""
    settings = paper_profile.modbus.plc  # refresh_s 0.05: 60 reads in 3 s without back-off
    with PlcStandIn("no-reads", code=2) as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port).start()
        events = Events(writer)
        try:
            with Offering(writer):
                time.sleep(3.0)
        finally:
            writer.stop(flush_s=0.0)
    c = writer.counters()
    assert 3 <= plc.seen.reads <= most_attempts(3.0, settings.backoff_s, settings.backoff_max_s)
    assert c["plc_command_reads_refused"] == plc.seen.reads and c["plc_exception_02"] == plc.seen.reads
    assert c["plc_writes"] >= 50 and c["plc_write_failures"] == 0 and c["plc_outages"] == 0
    assert sorted(events.names()) == ["plc_commands_refused", "plc_connected"]
    assert events.named("plc_commands_refused")[0]["exception"] == 2


def test_the_scores_are_written_after_the_command_registers_at_each_refresh(paper_profile):
    settings = paper_profile.modbus.plc
    with PlcStandIn("ok") as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port).start()
        try:
            writer.offer(image(1), tail=(1234, 56))
            wait_for(lambda: plc.regs[TAIL_AT:TAIL_AT + TAIL_COUNT] == [1234, 56], what="the scores in the PLC")
            assert plc.regs[:STATUS_COUNT] == image(1)
            writer.offer(image(2), urgent=True, tail=(7, 8))  # an urgent image: the scores follow at the refresh
            wait_for(lambda: plc.regs[TAIL_AT:TAIL_AT + TAIL_COUNT] == [7, 8], what="the newer scores")
        finally:
            writer.stop(flush_s=0.0)
    assert {a for _, a, _ in plc.seen.writes} <= {0, TAIL_AT, REG["COMMAND"].offset}
    assert writer.counters()["plc_score_writes"] >= 2


@pytest.mark.parametrize("inline", [True, False])
def test_an_urgent_images_scores_follow_it_at_once_not_at_the_next_refresh(paper_profile, inline):
    """A PLC reacting to a state change reads the scores that made it: after an urgent
    image the scores are written at once (sent by the offering thread or by the
    writer), not refresh_s later (30 s here: only the urgent path can write them)."""
    settings = paper_profile.modbus.plc
    with PlcStandIn("ok") as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port, refresh_s=30.0)
        writer._inline = inline  # (False: the writer thread sends it, as over RTU)
        writer.start()
        try:
            writer.offer(image(1), urgent=True, tail=(1234, 56))
            wait_for(lambda: plc.regs[TAIL_AT:TAIL_AT + TAIL_COUNT] == [1234, 56], timeout_s=3.0,
                     what="the first urgent image's scores")
            writer.offer(image(2), urgent=True, tail=(7, 8))
            wait_for(lambda: plc.regs[TAIL_AT:TAIL_AT + TAIL_COUNT] == [7, 8], timeout_s=3.0,
                     what="the urgent image's scores")
            assert plc.regs[:STATUS_COUNT] == image(2)
            writer.offer(image(3), tail=(9, 10))  # not urgent: its scores wait for the refresh
            time.sleep(0.5)
            assert plc.regs[:STATUS_COUNT] == image(2) and plc.regs[TAIL_AT:TAIL_AT + TAIL_COUNT] == [7, 8]
        finally:
            writer.stop(flush_s=0.0)
    assert writer.counters()["plc_score_writes"] == 2


def test_a_plc_whose_map_ends_at_enable_takes_the_image_and_refuses_the_scores_without_an_outage(paper_profile):
    """A PLC program written for the 22-register image: the scores' write is refused
    (exception 02), counted, logged once and backed off; the image and the commands
    go on."""
    settings = paper_profile.modbus.plc
    with PlcStandIn("ok", map_size=TAIL_AT) as plc:
        writer = PlcWriter(settings, "127.0.0.1", plc.port).start()
        events = Events(writer)
        try:
            with Offering(writer, tail=(3, 4)):
                time.sleep(2.0)
        finally:
            writer.stop(flush_s=0.0)
    c = writer.counters()
    tried = [v for _, a, v in plc.seen.writes if a == TAIL_AT]
    assert 2 <= len(tried) <= most_attempts(2.0, settings.backoff_s, settings.backoff_max_s)
    assert c["plc_score_writes_refused"] == len(tried) and c["plc_score_writes"] == 0
    assert c["plc_writes"] >= 50 and c["plc_write_failures"] == 0 and c["plc_outages"] == 0
    assert plc.seen.reads >= 10  # the commands are still read every refresh
    assert sorted(events.names()) == ["plc_connected", "plc_scores_refused"]
