"""A cell broker bridged to a plant broker by mosquitto's own bridge configuration, end
to end: the edge node publishes to its cell's broker; SCADA (``mosquitto_sub``)
watches the plant broker and writes a DCMD there; a killed bridge's NDEATH (the will,
delivered by the cell broker) reaches the plant."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from tests.helpers import sparkplug as spb
from tests.helpers.bridge import wait_for
from tests.helpers.modbus import need
from tests.helpers.paths import PROFILES
from tests.helpers.sparkplug import state_home  # noqa: F401  (autouse: a state folder of its own)


@pytest.mark.slow
def test_cell_broker_bridged_to_the_plant_broker(tmp_path):
    plant = spb.Broker(tmp_path)
    cell = spb.Broker(tmp_path, conf_lines=(
        "allow_anonymous true\n"
        f"connection plant\naddress 127.0.0.1:{plant.port}\n"
        "topic spBv1.0/+/+/+ both 1\ntopic spBv1.0/+/+/+/+ both 1\n"   # up: births, data, deaths; down: commands
        "cleansession true\nstart_type automatic\nrestart_timeout 1\n"))
    cap = spb.Capture(plant.port, tmp_path / "plant.txt")
    proc = None
    try:
        wait_for(lambda: _bridged(plant.port, tmp_path), timeout_s=10, what="the cell broker's bridge up")
        proc = subprocess.Popen([sys.executable, "-m", "eskin_industrial", "bridge", "-p",
                                 str(PROFILES / "paper-5x5.toml"), "--source", "scene:hold", "--sparkplug",
                                 f"mqtt://127.0.0.1:{cell.port}", "--group-id", "plant1", "--edge-node-id", "cell7"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                env={**os.environ, "PYTHONPATH": os.getcwd()})
        cap.wait(lambda m: any(t == "spBv1.0/plant1/DDATA/cell7/node" for t, _ in m), timeout_s=15)
        # SCADA, on the plant broker, disables detection on the cell's device
        cmd = spb.Payload(timestamp=int(time.time() * 1000))
        cmd.metrics.add(name="Device Control/Enable", datatype=11, boolean_value=False)
        f = tmp_path / "dcmd.bin"
        f.write_bytes(cmd.SerializeToString())
        subprocess.run([need("mosquitto_pub"), "-h", "127.0.0.1", "-p", str(plant.port), "-q", "1",
                        "-t", "spBv1.0/plant1/DCMD/cell7/node", "-f", str(f)], check=True, timeout=10)
        msgs = cap.wait(lambda m: False in _values(m, "Enabled"), timeout_s=10)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        msgs = cap.wait(lambda m: any(t == "spBv1.0/plant1/NDEATH/cell7" for t, _ in m), timeout_s=15)
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait(5)
        cap.close()
        cell.kill()
        plant.kill()
    ours = [(t, spb.parse(p)) for t, p in msgs if "/DCMD/" not in t]
    kinds = [t.split("/")[2] for t, _ in ours]
    assert kinds[:2] == ["NBIRTH", "DBIRTH"] and kinds[-1] == "NDEATH"
    seqs = [p.seq for t, p in ours if "/NDEATH/" not in t]
    assert seqs == [s % 256 for s in range(len(seqs))], "no message lost or reordered on the way"
    assert spb.metric_value(ours[-1][1], "bdSeq") == spb.metric_value(ours[0][1], "bdSeq")
    assert _values(msgs, "Enabled")[-1] is False


def _values(msgs, name):
    aliases = {m.alias: m.name for t, p in msgs if "/DBIRTH/" in t for m in spb.parse(p).metrics}
    return [spb.value(m) for t, p in msgs if "/DDATA/" in t for m in spb.parse(p).metrics
            if aliases.get(m.alias) == name]


def _bridged(port: int, tmp_path) -> bool:
    """The cell broker's bridge client is connected to the plant broker ($SYS notice)."""
    out = subprocess.run([need("mosquitto_sub"), "-h", "127.0.0.1", "-p", str(port), "-t",
                          "$SYS/broker/connection/+/state", "-C", "1", "-W", "1"], capture_output=True, text=True,
                         timeout=10)
    return out.stdout.strip() == "1"
