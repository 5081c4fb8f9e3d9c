"""The OPC UA output end to end, as a SCADA engineer meets it: ``eskin-bus bridge
--opcua`` on the case-2 scene, and node-opcua (an independent stack, driven over
JSON lines) browsing the model, reading every variable with its status and unit,
subscribing to the slip, calling the methods, receiving and acknowledging the slip
alarm, and seeing Bad quality when the bridge stops.  The exported NodeSet2 loads
in node-opcua's own address space."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from eskin_industrial import __version__
from eskin_industrial.outputs.opcua import model
from eskin_industrial.outputs.opcua.companions import DI_URI, MACHINERY_URI
from tests.helpers.modbus import free_port
from tests.helpers.opcua import NAMESPACE_URI, by_path, node_peer, wait_listening
from tests.helpers.paths import PROFILES

pytestmark = pytest.mark.slow
_ENV = {**os.environ, "PYTHONPATH": os.getcwd()}
_DATATYPES = {"Boolean": "ns=0;i=1", "Double": "ns=0;i=11", "UInt16": "ns=0;i=5", "UInt32": "ns=0;i=7",
              "UInt64": "ns=0;i=9", "String": "ns=0;i=12"}


def _bridge(port: int, log: Path, *extra: str) -> subprocess.Popen[bytes]:
    with log.open("wb") as stderr:  # the child has its own copy
        return subprocess.Popen([sys.executable, "-m", "eskin_industrial", "bridge", "-p",
                                 str(PROFILES / "paper-5x5.toml"), "--source", "scene:case2", "--opcua",
                                 f"opc.tcp://127.0.0.1:{port}", "--log-format", "json", "--status-every", "0", *extra],
                                stdout=subprocess.DEVNULL, stderr=stderr, env=_ENV)


def _events(log: Path, name: str) -> list[dict]:
    out = []
    for line in log.read_text().splitlines():
        try:
            e = json.loads(line)
        except ValueError:
            continue
        if e.get("event") == name:
            out.append(e)
    return out


def test_a_scada_client_browses_subscribes_calls_and_sees_the_bridge_stop(tmp_path: Path) -> None:
    port = free_port()
    url = f"opc.tcp://127.0.0.1:{port}"
    log = tmp_path / "bridge.log"
    proc = _bridge(port, log)
    try:
        wait_listening(port)
        with node_peer() as peer:
            peer.ask("connect", url=url)
            ns = peer.ask("namespace", uri=NAMESPACE_URI)["index"]
            assert ns > 0

            # -- the model, as a browse sees it
            machinery = peer.ask("namespace", uri=MACHINERY_URI)["index"]
            nodes = by_path(peer.ask("browse", nodeId=f"ns={machinery};i=1001", timeout_s=60)["nodes"])  # Machines
            assert nodes["node"]["typeDefinition"] == f"ns={ns};i={model.TYPE_IDS['GraspSensorType']}"
            ident = {k.rpartition("/")[2]: v["value"] for k, v in nodes.items() if k.startswith("node/Identification/")}
            assert ident["Manufacturer"] == "eskin-industrial" and ident["Model"] == "paper-5x5"
            assert ident["SoftwareRevision"] == __version__ and ident["SerialNumber"] == "node"
            assert nodes["node/MachineryBuildingBlocks/MachineryItemState/CurrentState"]["value"] in \
                model.MACHINERY_STATES
            # each instance typed as OPC 40001-1 types it, as node-opcua sees it
            blocks = "node/MachineryBuildingBlocks"
            assert nodes["node/Identification"]["typeDefinition"] == f"ns={machinery};i=1012"  # MachineIdentificationType
            assert nodes[f"{blocks}/Identification"]["nodeId"] == nodes["node/Identification"]["nodeId"]  # one nameplate
            assert nodes[f"{blocks}/MachineryItemState"]["typeDefinition"] == f"ns={machinery};i=1002"
            assert nodes[f"{blocks}/MachineryOperationMode"]["typeDefinition"] == f"ns={machinery};i=1008"
            for machine in model.STATE_MACHINES:
                current = nodes[f"{blocks}/{machine}/CurrentState"]
                assert current["typeDefinition"] == "ns=0;i=2760", current  # FiniteStateVariableType
                state_id = nodes[f"{blocks}/{machine}/CurrentState/Id"]["value"]
                assert state_id == f"ns={machinery};i={model.STATE_MACHINES[machine][1][current['value']]}"
            for v in model.VARIABLES:
                n = nodes[f"node/{v.path}"]
                assert n["nodeClass"] == "Variable" and n["userAccessLevel"] == 1, n  # CurrentRead only
                assert n["status"] in ("Good", "Uncertain", "BadWaitingForInitialData"), n
                want = (f"ns={ns};i={model.TYPE_IDS['GraspStateEnumeration']}" if v.datatype == "GraspStateEnumeration"
                        else _DATATYPES[v.datatype])
                assert n["dataTypeId"] == want, n
                if v.datatype == "Boolean":  # a flag: TwoStateDiscreteType, what true and false read
                    assert n["typeDefinition"] == "ns=0;i=2373", n
                    states = (nodes[f"node/{v.path}/TrueState"]["value"], nodes[f"node/{v.path}/FalseState"]["value"])
                    assert states == model.FLAG_STATES[v.path], v.path
                if v.analog:
                    assert n["typeDefinition"] == "ns=0;i=2368", n  # AnalogItemType
                    unit = nodes[f"node/{v.path}/EngineeringUnits"]["value"]
                    assert (unit["displayName"]["text"], unit["unitId"]) == (v.unit, model.UNITS[v.unit][0])
                    rng = nodes[f"node/{v.path}/EURange"]["value"]
                    assert rng["high"] > rng["low"] >= 0
            assert nodes["node/Scores/ScoreA"]["displayName"] == "onset_score"  # as plc map names them
            assert nodes["node/Scores/ScoreB"]["displayName"] == "slow_score"
            assert "Taxels" not in [p.rpartition("/")[2] for p in nodes]  # the frame is off by default
            assert {"node/Tare", "node/AcknowledgeSlip", "node/Enable", "node/SlipAlarm"} <= set(nodes)
            # every instance node id a string from its browse path, the method's argument list too
            (args,) = peer.ask("read", nodeIds=[f"ns={ns};s=node.Enable.InputArguments"])["values"]
            assert args["status"] == "Good" and args["value"][0]["name"] == "Enabled", args
            assert all(n["nodeId"].startswith(f"ns={ns};s=node.") for p, n in nodes.items()
                       if p.startswith("node/") and not p.startswith("node/SlipAlarm/")), \
                [p for p, n in nodes.items() if p.startswith("node/") and ";s=node." not in n["nodeId"]]
            enum = peer.ask("readEnum", nodeId=f"ns={ns};i={model.TYPE_IDS['GraspStateEnumeration']}")
            assert [(f["name"], f["value"]) for f in enum["fields"]] == list(zip(model.STATE_NAMES, range(4)))

            # -- the slip, by subscription and as an alarm
            state, offline = f"ns={ns};s=node.GraspState", f"ns={ns};s=node.Health.Offline"
            peer.ask("subscribe", nodeIds=[state, offline], publishingInterval=20)
            peer.ask("events", refresh=True)
            slip = peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == state and e["value"] == 3,
                                   40, "the slip")
            assert slip["status"] == "Good"
            assert slip["sourceTimestamp"] <= slip["received"] + 1  # (ms; a scan's arrival, then the client)
            assert slip["received"] - slip["sourceTimestamp"] < 2000
            alarm = peer.wait_event(lambda e: e["event"] == "alarm" and e.get("ConditionName") == "SlipAlarm"
                                    and e["ActiveState.Id"] is True, 10, "the slip alarm")
            assert alarm["Severity"] == 800 and alarm["SourceName"] == "node" and alarm["Retain"] is True
            assert alarm["AckedState.Id"] is False and alarm["ScoreNames"] == "onset_score,slow_score"
            assert alarm["ScoreA"] >= 1.0  # cof-track's onset score is 1 at its slip threshold
            assert 0 <= alarm["Delay"] < 2 and alarm["ConditionId"] == f"ns={ns};s=node.SlipAlarm"
            assert alarm["EventType"] == f"ns={ns};i={model.TYPE_IDS['SlipAlarmType']}"

            # -- the methods, under the one refusal rule
            call = {"objectId": f"ns={ns};s=node"}
            tare = peer.ask("call", methodId=f"ns={ns};s=node.Tare", **call)
            assert tare["status"] == "BadInvalidState"  # something is held
            assert peer.ask("call", methodId=f"ns={ns};s=node.AcknowledgeSlip", **call)["status"] == "Good"
            missing = peer.ask("call", methodId=f"ns={ns};s=node.Enable", **call)
            assert missing["status"] == "BadArgumentsMissing"
            off = peer.ask("call", methodId=f"ns={ns};s=node.Enable", args=[{"type": "Boolean", "value": False}],
                           **call)
            assert off["status"] == "Good"
            disabled = peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == state
                                       and e["status"] == "BadOutOfService", 10, "the disabled state")
            assert disabled["value"] is None
            on = peer.ask("call", methodId=f"ns={ns};s=node.Enable", args=[{"type": "Boolean", "value": True}],
                          **call)
            assert on["status"] == "Good"
            peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == state and e["status"] == "Good",
                            10, "detection enabled again")
            wrong = peer.try_ask("write", nodeId=state, dataType="Int32", value=0)
            assert not wrong["ok"] or wrong["status"] != "Good"  # nothing is writable

            # -- the alarm acknowledged (once)
            acked = peer.ask("acknowledge", conditionId=alarm["ConditionId"], eventId=alarm["EventId"]["base64"],
                             comment="seen at the HMI")
            assert acked["status"] == "Good"
            event = peer.wait_event(lambda e: e["event"] == "alarm" and e.get("AckedState.Id") is True, 10,
                                    "the acknowledged alarm")
            assert event["Comment"] == "seen at the HMI"
            again = peer.ask("acknowledge", conditionId=alarm["ConditionId"], eventId=alarm["EventId"]["base64"])
            assert again["status"] in ("BadConditionBranchAlreadyAcked", "BadEventIdUnknown")

            # -- the bridge stops: Bad quality before the connection goes
            os.kill(proc.pid, signal.SIGTERM)
            stopped = peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == state
                                      and e["status"] == "BadOutOfService", 10, "BadOutOfService at the stop")
            assert stopped["value"] is None
            peer.wait_event(lambda e: e["event"] == "data" and e["nodeId"] == offline and e["value"] is True
                            and e["status"] == "Good", 10, "Offline = true")
        assert proc.wait(20) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(10)
    refused = _events(log, "opcua_command_refused")
    assert [(e["command"], e["reason"]) for e in refused] == [("tare", "in_contact")]
    assert [e["command"] for e in _events(log, "opcua_command")] == ["ack", "disable", "enable"]
    assert [e["transition"] for e in _events(log, "opcua_alarm")][:2] == ["raised", "acknowledged"]
    final = _events(log, "final")[0]
    assert final["opcua_commands"] == 3 and final["opcua_commands_refused"] == 1 and final["opcua_alarm_acks"] == 1
    assert final["opcua_logins"] >= 1 and final["opcua_stack_errors"] == 0


def test_the_nodeset_loads_in_an_independent_address_space(tmp_path: Path) -> None:
    out = tmp_path / "eskin-grasp.NodeSet2.xml"
    done = subprocess.run([sys.executable, "-m", "eskin_industrial", "opcua", "nodeset", "-o", str(out)],
                          capture_output=True, text=True, timeout=120, env=_ENV)
    assert done.returncode == 0, done.stderr
    with node_peer() as peer:  # with the companion specifications it requires, as node-opcua ships them
        loaded = peer.ask("nodeset", file=str(out), uri=NAMESPACE_URI, companions=["di", "ia", "machinery"],
                          timeout_s=120)
    assert loaded["namespace"] > 0
    assert {v.path.partition("/")[0] for v in model.VARIABLES} <= set(loaded["sensorComponents"])
    assert {"MachineryBuildingBlocks", "SlipAlarm", "Taxels"} <= set(loaded["sensorComponents"])
    # every instance declaration typed as OPC 40001-1 and OPC 10000-100 type it
    decl = loaded["declarations"]
    untyped = [path for path, d in decl.items() if d["nodeClass"] != "Method" and not d["type"]]
    assert not untyped and len(decl) > 100, untyped
    machinery = MACHINERY_URI + "#"
    assert decl["Identification"] == {"nodeClass": "Object", "type": machinery + "MachineIdentificationType",
                                      "browseNamespace": DI_URI, "rule": "Mandatory", "addIn": True}
    for name, _, _ in model.IDENTIFICATION:
        assert decl[f"Identification/{name}"]["browseNamespace"] == DI_URI, name
    for path in model.FLAG_STATES:
        assert decl[path]["type"] == "http://opcfoundation.org/UA/#TwoStateDiscreteType", path
        assert decl[f"{path}/TrueState"]["rule"] == decl[f"{path}/FalseState"]["rule"] == "Mandatory", path
    # the alarm's declaration has the children an instance of its type has
    for child in ("EnabledState", "EnabledState/Id", "ActiveState", "ActiveState/Id", "AckedState", "Retain",
                  "Severity", "Message", "ConditionName", *(name for name, _, _ in model.ALARM_FIELDS)):
        assert decl[f"SlipAlarm/{child}"]["rule"] == "Mandatory", child
    assert decl["SlipAlarm"]["type"] == f"{NAMESPACE_URI}#SlipAlarmType"
    assert decl["MachineryBuildingBlocks"]["browseNamespace"] == MACHINERY_URI
    assert decl["MachineryBuildingBlocks/Identification"]["addIn"] is True
    for name, type_name in (("MachineryItemState", "MachineryItemState_StateMachineType"),
                            ("MachineryOperationMode", "MachineryOperationModeStateMachineType")):
        path = f"MachineryBuildingBlocks/{name}"
        assert decl[path]["type"] == machinery + type_name and decl[path]["addIn"] is True, name
        assert decl[f"{path}/CurrentState"]["type"] == "http://opcfoundation.org/UA/#FiniteStateVariableType"
        assert decl[f"{path}/CurrentState/Id"]["rule"] == "Mandatory"
    assert set(loaded["sensorMethods"]) == {"Tare", "AcknowledgeSlip", "Enable"}
    assert loaded["alarmIsAlarmCondition"] is True
    assert {name for name, _, _ in model.ALARM_FIELDS} <= set(loaded["alarmProperties"])
    assert loaded["enumStrings"] == loaded["enumFields"] == list(model.STATE_NAMES)
    problems = [w for w in loaded["warnings"] if "error" in w.lower() or "cannot" in w.lower()]
    assert not problems, problems
    # the model header: ours, requiring the standard model, DI and Machinery
    ua_ns = "{http://opcfoundation.org/UA/2011/03/UANodeSet.xsd}"
    (ours,) = ET.parse(out).getroot().iter(ua_ns + "Model")
    assert ours.get("ModelUri") == NAMESPACE_URI and ours.get("Version") == __version__
    assert [r.get("ModelUri") for r in ours.iter(ua_ns + "RequiredModel")] == [
        "http://opcfoundation.org/UA/", DI_URI, MACHINERY_URI]
