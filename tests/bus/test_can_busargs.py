"""python-can's conventions to the letter: the bit rate an adapter opens at does not
depend on how the interface was named, and it is the one python-can's own tools open
at, the profile's rate being only the default; --timing, --filter and --bus-kwargs in
python-can's syntax, on the command line and per node in bridge.toml."""

from __future__ import annotations

import argparse
from pathlib import Path

import can
import can.cli
import pytest
from click.testing import CliRunner

from eskin_industrial.bus.can.busargs import parse_bus_kwargs, parse_filters, parse_timing
from eskin_industrial.bus.can.reader import bus_kwargs, open_bus
from eskin_industrial.cli import main
from eskin_industrial.profile import load_profile
from tests.helpers import canrec

PROFILE = load_profile("paper-5x5")  # [can] bitrate_bps = 1000000 (the default)


@pytest.fixture
def opened(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> list[dict]:
    monkeypatch.setenv("HOME", str(tmp_path))  # python-can reads ~/can.conf, ~/.canrc
    return canrec.register(monkeypatch)


def _python_can_tool(argv: list[str]) -> dict:
    """What python-can's own command-line tools (can.logger, can.viewer) open."""
    parser = argparse.ArgumentParser()
    can.cli.add_bus_arguments(parser, filter_arg=True)
    ns = parser.parse_args(argv)
    before = len(canrec.RecordingBus.opened)
    can.cli.create_bus_from_namespace(ns).shutdown()
    return canrec.RecordingBus.opened[before]


def _ours(interface: str | None, bitrate: int | None = None, **kw) -> dict:
    before = len(canrec.RecordingBus.opened)
    open_bus(**bus_kwargs(PROFILE, interface, "cell7", bitrate, None, None, **kw)).shutdown()
    return canrec.RecordingBus.opened[before]


@pytest.mark.parametrize("named_by", ["option", "environment", "config file"])
def test_bitrate_from_python_cans_configuration_wins_over_the_profile(
        opened: list[dict], monkeypatch: pytest.MonkeyPatch, tmp_path: Path, named_by: str) -> None:
    monkeypatch.setenv("CAN_BITRATE", "500000")
    if named_by == "environment":
        monkeypatch.setenv("CAN_INTERFACE", "recording")
    elif named_by == "config file":
        (tmp_path / ".canrc").write_text("[default]\ninterface = recording\n")
    interface = "recording" if named_by == "option" else None
    theirs = _python_can_tool((["-i", "recording"] if interface else []) + ["-c", "cell7"])
    ours = _ours(interface)
    assert theirs["bitrate"] == ours["bitrate"] == 500000


@pytest.mark.parametrize("named_by", ["option", "environment", "config file"])
def test_the_profile_bitrate_is_the_default_whichever_way_the_interface_is_named(
        opened: list[dict], monkeypatch: pytest.MonkeyPatch, tmp_path: Path, named_by: str) -> None:
    if named_by == "environment":
        monkeypatch.setenv("CAN_INTERFACE", "recording")
    elif named_by == "config file":
        (tmp_path / ".canrc").write_text("[default]\ninterface = recording\n")
    ours = _ours("recording" if named_by == "option" else None)
    assert ours["bitrate"] == PROFILE.can.bitrate_bps == 1_000_000


def test_the_command_line_wins_over_everything(opened: list[dict], monkeypatch: pytest.MonkeyPatch,
                                               tmp_path: Path) -> None:
    monkeypatch.setenv("CAN_BITRATE", "500000")
    (tmp_path / ".canrc").write_text("[default]\ninterface = recording\nbitrate = 125000\n")
    assert _python_can_tool(["-c", "cell7", "-b", "250000"])["bitrate"] == 250000
    assert _ours(None, 250000)["bitrate"] == 250000
    monkeypatch.delenv("CAN_BITRATE")
    assert _ours(None)["bitrate"] == _python_can_tool(["-c", "cell7"])["bitrate"] == 125000  # the file's


def test_buses_that_take_no_bitrate_get_none(opened: list[dict]) -> None:
    kw = bus_kwargs(PROFILE, "virtual", "x", None, None, None)
    assert kw["bitrate"] is None and kw["data_bitrate"] is None


def test_timing_replaces_the_profile_bitrate_and_reaches_the_bus(opened: list[dict]) -> None:
    timing = parse_timing(["f_clock=8000000 brp=1 tseg1=5 tseg2=2 sjw=1 nof_samples=1"])
    ours = _ours("recording", timing=timing)
    assert "bitrate" not in ours
    assert isinstance(ours["timing"], can.BitTiming) and ours["timing"].bitrate == 1_000_000
    theirs = _python_can_tool(["-i", "recording", "-c", "cell7", "--timing", "f_clock=8000000", "brp=1",
                               "tseg1=5", "tseg2=2", "sjw=1", "nof_samples=1"])
    assert theirs["timing"] == ours["timing"]


def test_filters_and_bus_kwargs_parse_as_python_can_parses_them(opened: list[dict]) -> None:
    assert parse_filters(["200:7F0", "100:7FC"]) == [{"can_id": 0x200, "can_mask": 0x7F0},
                                                     {"can_id": 0x100, "can_mask": 0x7FC}]
    assert parse_bus_kwargs(["app_name=Cell7 serial=1234", "receive_own_messages=true"]) == {
        "app_name": "Cell7", "serial": 1234, "receive_own_messages": True}
    theirs = _python_can_tool(["-i", "recording", "-c", "c", "--bus-kwargs", "app_name=Cell7", "serial=1234"])
    ours = _ours("recording", extra=parse_bus_kwargs(["app_name=Cell7 serial=1234"]))
    assert {k: theirs[k] for k in ("app_name", "serial")} == {k: ours[k] for k in ("app_name", "serial")}
    for bad, parse in (("200", parse_filters), ("xyz:7F0", parse_filters), ("f_clock=8MHz", parse_timing),
                       ("brp=1", parse_timing), ("-x=1", parse_bus_kwargs)):
        with pytest.raises(ValueError):
            parse([bad])


def test_filter_keeps_other_ids_off_the_bus(opened: list[dict]) -> None:
    """A filter really filters (python-can applies it in software on the virtual bus)."""
    rx = open_bus(**bus_kwargs(PROFILE, "virtual", "filter-test", None, None, None, filters=["200:7F0"]))
    with rx, open_bus("virtual", "filter-test") as tx:
        tx.send(can.Message(arbitration_id=0x300, data=b"\x01", is_extended_id=False))
        tx.send(can.Message(arbitration_id=0x205, data=b"\x02", is_extended_id=False))
        got = rx.recv(1.0)
        assert got is not None and got.arbitration_id == 0x205
        assert rx.recv(0.05) is None


def test_cli_options_reach_the_bus_and_bad_ones_are_one_line(opened: list[dict]) -> None:
    runner = CliRunner()
    out = runner.invoke(main, ["receive", "-p", "paper-5x5", "-i", "recording", "-c", "cli", "--duration", "0.05",
                               "-q", "--bus-kwargs", "app_name=Cell7", "--filter", "200:7F0", "--timing",
                               "f_clock=8000000 brp=1 tseg1=5 tseg2=2 sjw=1 nof_samples=1"])
    assert out.exit_code == 0, out.output
    (kw,) = opened
    assert kw["app_name"] == "Cell7" and kw["can_filters"] == [{"can_id": 0x200, "can_mask": 0x7F0}]
    assert kw["timing"].bitrate == 1_000_000
    bad = runner.invoke(main, ["receive", "-p", "paper-5x5", "-i", "virtual", "--timing", "brp=x"])
    assert bad.exit_code == 2 and "--timing" in bad.output and "brp=x" in bad.output


def test_two_fd_adapters_set_up_differently_in_one_bridge(opened: list[dict], tmp_path: Path) -> None:
    (tmp_path / "bridge.toml").write_text('''
[plc]
mode = "server"
host = "127.0.0.1"
port = 1502

[[node]]
name = "left"
profile = "paper-5x5"
interface = "recording"
channel = "left-bus"
fd = true
bus_kwargs = { f_clock_mhz = 80, serial = 11 }
timing = { f_clock = 80000000, nom_brp = 1, nom_tseg1 = 119, nom_tseg2 = 40, nom_sjw = 40, data_brp = 1, data_tseg1 = 29, data_tseg2 = 10, data_sjw = 10 }

[[node]]
name = "right"
profile = "paper-5x5"
interface = "recording"
channel = "right-bus"
fd = true
bus_kwargs = { f_clock_mhz = 40, serial = 12 }
filter = ["200:7F0"]
[node.plc]
base_address = 100
''')
    from eskin_industrial.bridge.config import load_bridge_config, resolve
    from eskin_industrial.bus.can.source import CanSource

    nodes = resolve(load_bridge_config(str(tmp_path / "bridge.toml")))
    left, right = (bus_kwargs(n.profile, n.config.options.interface, n.config.options.channel,
                              n.config.options.bitrate_bps, n.config.options.fd, n.config.options.data_bitrate_bps,
                              timing=n.config.options.timing, filters=n.config.options.filter,
                              extra=n.config.options.bus_kwargs) for n in nodes)
    assert (left["serial"], left["f_clock_mhz"], right["serial"], right["f_clock_mhz"]) == (11, 80, 12, 40)
    assert isinstance(left["timing"], can.BitTimingFd) and left["timing"].data_bitrate == 2_000_000
    assert "timing" not in right and right["bitrate"] == 1_000_000 and right["data_bitrate"] == 5_000_000
    assert right["can_filters"] == [{"can_id": 0x200, "can_mask": 0x7F0}]
    assert CanSource.share_key(nodes[0]) != CanSource.share_key(nodes[1])


def test_bad_node_bus_keys_are_refused_at_load(tmp_path: Path) -> None:
    (tmp_path / "bridge.toml").write_text(
        '[plc]\nmode = "server"\nhost = "127.0.0.1"\nport = 1502\n'
        '[[node]]\nname = "left"\nprofile = "paper-5x5"\ninterface = "virtual"\nfilter = ["200/7F0"]\n')
    out = CliRunner().invoke(main, ["bridge", "--config", str(tmp_path / "bridge.toml"), "--check"])
    assert out.exit_code == 2
    assert "filter" in out.output and "200/7F0" in out.output and len(out.output.strip().splitlines()) == 1
