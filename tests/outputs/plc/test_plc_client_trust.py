"""Client mode takes nothing on trust: an answer acknowledges a write only if it is a
write's answer, and a COMMAND or ENABLE value the bridge refuses is counted, logged
and answered (COMMAND reads CMD_REFUSED, never 0, "done")."""

from __future__ import annotations

import time

from eskin_industrial.outputs.plc.client import PlcWriter
from eskin_industrial.outputs.plc.image import CMD_REFUSED, REG, STATUS_COUNT
from tests.helpers.plc_standin import PlcStandIn

COMMAND, ENABLE = REG["COMMAND"].offset, REG["ENABLE"].offset


def wait_for(cond, timeout_s: float = 5.0, what: str = "condition") -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        assert time.monotonic() < deadline, f"{what}: not met within {timeout_s} s"
        time.sleep(0.005)


def events_of(writer: PlcWriter) -> list[tuple[str, str, dict]]:
    out: list[tuple[str, str, dict]] = []
    writer.on_events(lambda name, level, fields: out.append((name, level, fields)))
    return out


def test_a_read_shaped_answer_to_a_write_is_no_acknowledgement(paper_profile):
    with PlcStandIn("wrong-fc") as plc:
        writer = PlcWriter(paper_profile.modbus.plc, "127.0.0.1", plc.port).start()
        events = events_of(writer)
        try:
            writer.offer([1] * STATUS_COUNT, urgent=True)
            wait_for(lambda: len(plc.seen.writes) >= 1, what="a write sent")
            wait_for(lambda: writer.stats.failures >= 1, what="a failure counted")
            assert writer.stats.writes == 0 and writer.in_outage and not writer.health().connected
            unreachable = [f for n, _, f in events if n == "plc_unreachable"]
            assert unreachable and "answered function 3 to a function 16 request" in unreachable[0]["error"]
            # The PLC comes right: the image is written and acknowledged.
            plc.mode = "ok"
            wait_for(lambda: writer.stats.writes >= 1, timeout_s=10, what="acknowledged once the PLC answers")
            assert plc.regs[:STATUS_COUNT] == [1] * STATUS_COUNT
        finally:
            writer.stop()


def test_refused_command_and_enable_values_are_counted_logged_and_answered(paper_profile):
    with PlcStandIn("ok") as plc:
        writer = PlcWriter(paper_profile.modbus.plc, "127.0.0.1", plc.port).start()
        events = events_of(writer)
        try:
            writer.offer([0] * STATUS_COUNT)
            wait_for(lambda: writer.stats.writes >= 1)
            writer.take_commands()
            plc.regs[COMMAND] = 0x0041  # an unknown bit (6) beside the acknowledge
            wait_for(lambda: plc.regs[COMMAND] != 0x0041, what="COMMAND answered")
            assert plc.regs[COMMAND] == CMD_REFUSED  # not 0: the handshake must not read "done"
            assert writer.stats.command_values_refused == 1
            assert [c.name for c in writer.take_commands() if c.name == "ack"] == []  # nothing of it done
            time.sleep(0.2)  # our refusal standing in COMMAND is nothing new: not refused again
            assert writer.stats.command_values_refused == 1 and plc.regs[COMMAND] == CMD_REFUSED
            plc.regs[COMMAND] = 1  # the PLC writes its next command over the refusal
            wait_for(lambda: plc.regs[COMMAND] == 0, what="a good COMMAND done")
            assert "ack" in [c.name for c in writer.take_commands()]

            plc.regs[ENABLE] = 7
            wait_for(lambda: writer.stats.enable_values_refused >= 3, what="ENABLE = 7 refused")
            assert not [c for c in writer.take_commands() if c.name in ("enable", "disable")]
            plc.regs[COMMAND] = 1  # a good COMMAND is still done while ENABLE is wrong
            wait_for(lambda: plc.regs[COMMAND] == 0, what="COMMAND done beside a bad ENABLE")
            counters = writer.counters()
            assert counters["plc_command_values_refused"] == 1 and counters["plc_enable_values_refused"] >= 3
            logged = [(n, f) for n, _, f in events if n in ("plc_command_refused", "plc_enable_refused")]
            # Once per kind within the log interval, not once per read.
            assert [n for n, _ in logged] == ["plc_command_refused", "plc_enable_refused"]
            assert logged[0][1]["value"] == 0x0041 and logged[1][1]["value"] == 7
        finally:
            writer.stop()
