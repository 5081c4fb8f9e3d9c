"""``eskin-bus demo``: the whole chain on the embedded default, nothing to start."""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from .common import open_profile

#: the shipped profiles, next to the package in a checkout
PROFILES = Path(__file__).resolve().parents[2] / "profiles"


@click.command()
@click.option("--scene", default="hand", show_default=True, help="Scene the node plays (see `simulate --list`).")
@click.option("-p", "--profile", "profile_path", type=click.Path(dir_okay=False), default=None,
              help="Profile (default: the scene's, from profiles/).")
@click.option("--rate", "rate_hz", type=click.FloatRange(min=10.0, max=2000.0), default=100.0, show_default=True)
@click.option("--seed", type=int, default=7, show_default=True)
@click.option("--plain", is_flag=True, help="One line per state change (the default; the live view is not built yet).")
@click.option("--plc-log", is_flag=True, help="Also print the PLC stand-in's register changes and gripper actions.")
def demo(scene: str, profile_path: str | None, rate_hz: float, seed: int, plain: bool, plc_log: bool) -> None:
    """Play a scene as a CAN sensor node on python-can's virtual bus, run the bridge
    (decode, detect) and write the registers over Modbus TCP on loopback into a PLC
    stand-in; print each state change and a summary."""
    from ..demo import run_demo
    from ..scenes import render

    rec = render(scene, rate_hz, seed)
    prof = open_profile(profile_path or str(PROFILES / f"{rec.profile_name}.toml"))
    say = click.echo
    say(f"demo: scene {rec.name} ({rec.spec.scene.description}), {len(rec.t)} scans at {rate_hz:g} Hz on a "
        f"virtual CAN bus -> bridge ({prof.detector.method}) -> Modbus TCP -> PLC stand-in; "
        f"about {rec.t[-1]:.0f} s in real time")
    res = run_demo(prof, rec, say, (lambda line: say(f"    PLC {line}")) if plc_log else None)
    s, c = res.score, res.counters
    say("summary:")
    if s is not None:
        delays = ", ".join(f"{d * 1000:.0f} ms" for d in s.delays_s) or "-"
        say(f"  slip events {s.events}, found {s.found}, false alarms {s.false_alarms}; detection delay {delays}")
    if res.latencies_s:
        lat = np.asarray(res.latencies_s) * 1000
        say(f"  decision -> acknowledged PLC write: p50 {np.percentile(lat, 50):.2f} ms, "
            f"p99 {np.percentile(lat, 99):.2f} ms over {lat.size} urgent writes")
    say(f"  scans {c.get('scans', 0)}, lost {c.get('lost_scans', 0)}, torn {c.get('torn_scans', 0)}, "
        f"malformed {c.get('malformed_frames', 0)}, rx queue drops {c.get('rx_queue_drops', 0)}; "
        f"PLC status changes {res.plc_status_changes}, grip force raised {res.grip_raises} times")
