"""The OPC UA output's pure parts: the status code of each condition, a snapshot's
values, the slip alarm's states, the handover's bounds and order, the options'
security rules, the users file."""

from __future__ import annotations

import pytest

from eskin_industrial.detect.updates import Update
from eskin_industrial.node import Command, Health, NodeStatus, refusal
from eskin_industrial.outputs.opcua import model, status
from eskin_industrial.outputs.opcua.alarm import AlarmState
from eskin_industrial.outputs.opcua.handover import URGENT_MAX, Handover, Waker
from eskin_industrial.outputs.opcua.options import (
    POLICIES,
    SECURE_POLICIES,
    OpcuaOptions,
    is_loopback,
    parse_endpoint_url,
)
from eskin_industrial.outputs.opcua.users import (
    Directory,
    UserEntry,
    add_user,
    hash_password,
    parse_users_env,
    parse_users_file,
    verify_password,
)

S = status


def _status(state: int = 1, valid: bool = True, *, enabled: bool = True, seen: bool = True) -> NodeStatus:
    st = NodeStatus(stale_s=0.025, method="cof-track", method_code=7, score_names=("onset_score", "slow_score"))
    st.enabled = enabled
    if seen:
        st.observe(Update(1.0, 0.1, 0.2, state, valid, 5.0 if state else 0.0, 10.0, 10.0, 0, 0.3, 0.4))
    return st


def _snap(state: int = 1, valid: bool = True, *, age: float | None = 0.005, bus_fault: bool = False,
          enabled: bool = True, seen: bool = True, offline: bool = False):
    st = _status(state, valid, enabled=enabled, seen=seen)
    health = Health(frame_age_s=age, bus_fault=bus_fault)
    if offline:
        return st.offline_snapshot(health, scans=10, t_event=1.0, wall_time_s=1000.0)
    return st.snapshot(health, scans=10, t_event=1.0, wall_time_s=1000.0, urgent=False)


@pytest.mark.parametrize(("kwargs", "source", "want"), [
    ({}, "", (S.GOOD, S.GOOD, S.GOOD)),
    ({"valid": False}, "", (S.UNCERTAIN, S.GOOD, S.GOOD)),
    ({"enabled": False}, "", (S.BAD_OUT_OF_SERVICE, S.GOOD, S.GOOD)),
    ({"age": 0.2}, "", (S.UNCERTAIN_LAST_USABLE_VALUE,) * 2 + (S.GOOD,)),
    ({"age": 1.5}, "", (S.BAD_NO_COMMUNICATION,) * 2 + (S.GOOD,)),
    ({"age": float("nan")}, "", (S.BAD_NO_COMMUNICATION,) * 2 + (S.GOOD,)),
    ({"age": None, "seen": False}, "", (S.BAD_WAITING_FOR_INITIAL_DATA,) * 2 + (S.GOOD,)),
    ({"bus_fault": True}, "", (S.BAD_NO_COMMUNICATION,) * 2 + (S.GOOD,)),
    ({}, "ended", (S.BAD_OUT_OF_SERVICE,) * 2 + (S.GOOD,)),
    ({}, "failed", (S.BAD_DEVICE_FAILURE,) * 2 + (S.GOOD,)),
    ({"offline": True}, "", (S.BAD_OUT_OF_SERVICE,) * 3),
])
def test_the_status_of_each_condition(kwargs: dict, source: status.SourceEnd, want: tuple[int, int, int]) -> None:
    assert tuple(status.quality(_snap(**kwargs), source, bad_after_s=1.0)) == want


def test_a_bridge_that_is_not_deciding_never_reads_good() -> None:
    """Every condition but deciding leaves the decision group not Good."""
    for kwargs in ({"valid": False}, {"enabled": False}, {"age": 0.2}, {"bus_fault": True}, {"offline": True},
                   {"seen": False, "age": None}):
        assert status.quality(_snap(**kwargs)).decision != S.GOOD, kwargs
    assert status.quality(_snap(), "failed").decision != S.GOOD


def test_machinery_item_state_names() -> None:
    assert status.machinery_state(_snap()) == "Executing"
    assert status.machinery_state(_snap(enabled=False)) == "NotExecuting"
    assert status.machinery_state(_snap(seen=False, age=None)) == "NotExecuting"
    assert status.machinery_state(_snap(age=0.5)) == "OutOfService"
    assert status.machinery_state(_snap(bus_fault=True)) == "OutOfService"
    assert status.machinery_state(_snap(), "failed") == "OutOfService"
    assert status.machinery_state(_snap(offline=True)) == "NotAvailable"
    assert set(model.MACHINERY_STATES) == {"Executing", "NotExecuting", "OutOfService", "NotAvailable"}
    assert set(model.MACHINERY_STATES) == set(model.STATE_MACHINES["MachineryItemState"][1])


def test_machinery_operation_mode_names() -> None:
    assert status.operation_mode(_snap()) == "Processing"
    assert status.operation_mode(_snap(seen=False, age=None)) == "Processing"  # enabled, waiting for its first scan
    assert status.operation_mode(_snap(enabled=False)) == "Setup"
    assert status.operation_mode(_snap(offline=True)) == "None"
    assert set(model.OPERATION_MODES) <= set(model.STATE_MACHINES["MachineryOperationMode"][1])


def test_values_follow_the_variables_in_order() -> None:
    s = _snap(state=3)
    v = dict(zip((x.path for x in model.VARIABLES), model.values(s)))
    assert v["GraspState"] == 3 and v["GraspStateName"] == "slip" and v["Slip"] is True and v["Contact"] is True
    assert v["Method"] == "cof-track" and v["MethodCode"] == 7 and v["Counters/Scans"] == 10
    assert v["Health/Offline"] is False and v["StateValid"] is True
    assert len(model.values(s)) == len(model.VARIABLES) == len(model.GROUPS)
    stale = dict(zip((x.path for x in model.VARIABLES), model.values(_snap(state=3, age=0.2))))
    assert stale["GraspState"] is None and stale["Slip"] is None  # not claimed: the last value is kept
    assert stale["TotalForce"] is not None


def test_the_slip_alarm_is_raised_each_entry_cleared_and_acknowledged() -> None:
    a = AlarmState()
    assert a.observe(_snap(state=1)) is None
    slip = _snap(state=3)
    assert a.observe(slip) == "raised" and a.active and not a.acked and a.retain
    first = a.event_id
    assert a.observe(slip) is None  # the same slip
    assert a.acknowledge(b"not an id") == S.BAD_EVENT_ID_UNKNOWN
    assert a.observe(_snap(state=3, enabled=False)) is None and a.active  # not claimed: as it was
    assert a.observe(_snap(state=3, age=0.2)) is None and a.active
    assert a.observe(slip) is None  # the same slip claimed again: no new alarm
    assert a.observe(_snap(state=1)) == "cleared" and not a.active and a.retain  # over, still to acknowledge
    assert a.acknowledge(first) == S.GOOD and a.acked and not a.retain
    assert a.acknowledge(first) == S.BAD_CONDITION_BRANCH_ALREADY_ACKED
    again = slip._replace(slip_events=slip.slip_events + 1)
    assert a.observe(again) == "raised" and a.raised == 2  # a new slip: a new alarm
    assert a.acknowledge(first) == S.BAD_EVENT_ID_UNKNOWN  # the last slip's id is not this one's
    assert a.acknowledge(a.event_id) == S.GOOD and a.retain  # acknowledged while active: still retained
    assert a.observe(_snap(state=3, offline=True)) == "cleared" and not a.retain  # the bridge stopped


def test_handover_keeps_every_urgent_snapshot_in_order_and_the_newest_refresh() -> None:
    woken = []
    waker = Waker()
    waker.attach(lambda: woken.append(1))
    h = Handover(waker)
    base = _snap()
    h.put(base._replace(urgent=True, scans=1))
    h.put(base._replace(scans=2))
    h.put(base._replace(scans=3))
    h.put(base._replace(urgent=True, scans=4))
    h.put(base._replace(scans=5))
    assert len(woken) == 1  # woken once until the server looks
    waker.arm()
    assert [s.scans for s in h.take()] == [1, 4, 5]
    h.put(base._replace(scans=6))
    h.put(base._replace(urgent=True, scans=7))
    assert [s.scans for s in h.take()] == [7]  # the refresh before the urgent one is older: dropped
    assert len(woken) == 2
    for i in range(URGENT_MAX + 5):
        h.put(base._replace(urgent=True, scans=100 + i))
    taken = h.take()
    assert len(taken) == URGENT_MAX and h.dropped == 5 and taken[-1].scans == 100 + URGENT_MAX + 4
    assert h.take() == []


def test_a_waker_whose_loop_has_closed_counts_and_does_not_raise() -> None:
    waker = Waker()

    def closed() -> None:
        raise RuntimeError("Event loop is closed")

    waker.attach(closed)
    waker.wake()
    assert waker.failed == 1


def test_commands_are_refused_by_the_one_rule() -> None:
    in_contact = _snap(state=1)
    assert refusal(Command("tare"), in_contact) == "in_contact"
    assert refusal(Command("tare"), _snap(state=0)) is None
    assert refusal(Command("enable"), in_contact, read_only=True) == "read_only"


def test_endpoint_urls() -> None:
    assert parse_endpoint_url("opc.tcp://127.0.0.1:4841") == ("127.0.0.1", 4841)
    assert parse_endpoint_url("opc.tcp://[::1]:4840") == ("::1", 4840)
    assert parse_endpoint_url("opc.tcp://plc-gw") == ("plc-gw", 4840)
    for bad in ("http://x:1", "opc.tcp://:4840", "opc.tcp://x:0", "opc.tcp://x:99999", "opc.tcp://x:1/path",
                "opc.tcp://999.1.1.1:4840"):
        with pytest.raises(ValueError):
            parse_endpoint_url(bad)
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.10.5") and not is_loopback("gw.local")


def test_security_is_off_only_on_loopback() -> None:
    local = OpcuaOptions()
    assert local.policies() == ("None",) and local.anonymous and local.insecure() == []
    with_pki = OpcuaOptions(pki_dir="pki")
    assert with_pki.policies() == POLICIES
    remote = OpcuaOptions(endpoint="opc.tcp://0.0.0.0:4840", pki_dir="pki", users_file="users.toml")
    assert remote.policies() == SECURE_POLICIES and not remote.anonymous and remote.insecure() == []
    with pytest.raises(ValueError, match="^users_file: on 0.0.0.0, not loopback"):
        OpcuaOptions(endpoint="opc.tcp://0.0.0.0:4840", pki_dir="pki")
    with pytest.raises(ValueError, match=r"^security_policies: 'None' on 10.0.0.5, not loopback"):
        OpcuaOptions(endpoint="opc.tcp://10.0.0.5:4840", security_policies=("None",), users_file="u.toml")
    with pytest.raises(ValueError, match="^pki_dir: on 0.0.0.0, not loopback, the secure endpoints need"):
        OpcuaOptions(endpoint="opc.tcp://0.0.0.0:4840", users_file="u.toml")
    with pytest.raises(ValueError, match="^pki_dir: a secure policy needs"):
        OpcuaOptions(security_policies=("Basic256Sha256_Sign",))
    allowed = OpcuaOptions(endpoint="opc.tcp://0.0.0.0:4840", allow_insecure=True)
    assert allowed.policies() == ("None",)
    assert allowed.anonymous and allowed.insecure() == ["SecurityPolicy None", "anonymous sessions (operator)"]
    with pytest.raises(ValueError, match="^users_file: no anonymous sessions and no users"):
        OpcuaOptions(anonymous_role="none")


def test_users_file_and_environment(tmp_path) -> None:
    path = tmp_path / "users.toml"
    assert add_user(path, "scada", "reader", "s3cret:with colon") is False
    assert add_user(path, "op", "operator", "pw") is False
    assert add_user(path, "scada", "reader", "new") is True
    assert path.stat().st_mode & 0o777 == 0o600
    users = parse_users_file(path.read_text(), str(path))
    assert [(u.name, u.role) for u in users] == [("op", "operator"), ("scada", "reader")]
    assert all(u.password.startswith("scrypt$") and "new" not in u.password for u in users)
    d = Directory(users)
    assert d.login("scada", "new") == "reader" and d.login("scada", "new") == "reader"  # the second remembered
    assert d.login("scada", "s3cret:with colon") is None and d.login("nobody", "new") is None
    assert verify_password(hash_password("x"), "x") and not verify_password(hash_password("x"), "y")
    env = parse_users_env("hmi:reader:a:b\n\nplc:operator:pw\n", "ESKIN_OPCUA_USERS")
    assert [(u.name, u.role, u.password) for u in env] == [("hmi", "reader", "a:b"), ("plc", "operator", "pw")]
    assert Directory(env).login("hmi", "a:b") == "reader"
    for text, match in (('[[user]]\nname = "a"\nrole = "admin"\npassword = "x"\n', "role: expected one of"),
                        ('[[user]]\nname = "a"\nrole = "reader"\npassword = "plain"\n', "password: expected a hash"),
                        ('[[user]]\nname = "a"\nrole = "reader"\npasswd = "x"\n', "passwd: unknown key"),
                        ("[[user]\n", "not valid TOML")):
        with pytest.raises(ValueError, match=match):
            parse_users_file(text, "u.toml")
    with pytest.raises(ValueError, match=r"users_env: \$E line 1: expected NAME:ROLE:PASSWORD"):
        parse_users_env("nocolon", "E")
    with pytest.raises(ValueError, match="user 'a' is given twice"):
        parse_users_env("a:reader:x\na:operator:y", "E")
    assert UserEntry("a", "reader", "x").role == "reader"


def test_the_model_tree_names_every_variable() -> None:
    tree = "\n".join(model.model_tree())
    for v in model.VARIABLES:
        assert v.path.rpartition("/")[2] in tree
    for name, _, _ in model.IDENTIFICATION:
        assert name in tree
    assert "SlipAlarm" in tree and "Enable(Enabled: Boolean)" in tree
