"""The cell's friction from pure Coulomb to strong velocity strengthening, a stick-slip
ripple only where the friction law weakens with speed, and a normal force lost at a
slide's onset: in the physics and in the frames the detector sees."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from eskin_industrial.cli.evaluate_closed_loop import setup_of
from eskin_industrial.sim.cell.actuator import ActuatorSpec
from eskin_industrial.sim.cell.objects import OBJECT, Specimen
from eskin_industrial.sim.cell.physics import DROP_MM, Contact, Friction, G
from eskin_industrial.sim.cell.task import Task
from eskin_industrial.sim.cell.world import TICK_S, CellWorld, Episode

DT = 0.001


def time_to_drop(friction: Friction, grip_n: float, mass: float) -> float:
    c = Contact(friction)
    for k in range(1, 5000):
        c.step(DT, grip_n, mass, 0.0, 0.0, True)
        if c.dropped_at is not None:
            return k * DT
    return math.inf


@pytest.mark.parametrize("ratio", [0.65, 0.85])
def test_pure_coulomb_slides_a_load_just_past_static_friction_off_the_pads_in_about_100_ms(ratio):
    mass, mu_s = 0.2, 0.6
    grip = mass * G / (2 * mu_s) / 1.01  # the load 1 % past what static friction holds
    coulomb = time_to_drop(Friction(mu_s, mu_s * ratio, viscous_s_per_m=0.0), grip, mass)
    accel = (mass * G - 2 * grip * mu_s * ratio) / mass
    assert coulomb == pytest.approx(math.sqrt(2 * DROP_MM / 1000 / accel), abs=0.002)  # free slide under kinetic friction
    assert 0.08 <= coulomb <= 0.16
    # the strong velocity strengthening the cell had before takes several times longer
    assert time_to_drop(Friction(mu_s, mu_s * ratio, viscous_s_per_m=4.0), grip, mass) > 3 * coulomb


def test_the_closed_loop_takes_pure_coulomb_friction_and_its_sweeps_go_down_to_it():
    from eskin_industrial.sim.cell.sweeps import SWEEPS

    setup = setup_of(100.0, 10.0, ("viscous=0", "stribeck=0", "force_drop=0"))
    assert setup.chain.viscous_s_per_m == 0.0
    assert SWEEPS["viscous"][1][0] == 0.0


def test_a_stribeck_law_weakens_only_below_the_speed_where_strengthening_takes_over():
    f = Friction(0.5, 0.4, viscous_s_per_m=1.0, stribeck_m_per_s=0.005)
    v = f.weakens_below_m_per_s
    assert v == pytest.approx(0.005 * math.log(0.1 / 0.005))  # mu'(v) = 0 there
    assert f.mu(0.5 * v) > f.mu(v) < f.mu(1.5 * v) and f.mu(1e-9) == pytest.approx(0.5)
    assert Friction(0.5, 0.4, viscous_s_per_m=0.0, stribeck_m_per_s=0.005).weakens_below_m_per_s == math.inf
    assert Friction(0.5, 0.4, viscous_s_per_m=40.0, stribeck_m_per_s=0.005).weakens_below_m_per_s == 0.0
    assert Friction(0.5, 0.4, viscous_s_per_m=0.0).weakens_below_m_per_s == 0.0  # Coulomb: no weakening once it slides


def slide_world(stribeck_m_per_s: float = 0.0, force_drop: float = 0.0, viscous: float = 0.0,
                rate_hz: float = 1000.0) -> tuple[CellWorld, float]:
    """A 0.5 kg oily part gripped too lightly: it slides off at the lift (0.5 s); noise-free."""
    kind = OBJECT["part"]
    kind = replace(kind, sensor=replace(kind.sensor, noise_n=0.0))
    spec = Specimen(kind, 0.5, 0.4, 0.3, 0.0, math.inf, stribeck_m_per_s, force_drop)
    ep = Episode(1, spec, Task(0.2, 0.5, 1.5, ()), render_seed=1)
    world = CellWorld(ep, ActuatorSpec(), rate_hz, viscous)
    grip = 0.9 * 0.5 * G / (2 * 0.4)
    world.command(0.2, grip)
    return world, grip


def frames_while_sliding(world: CellWorld, until_mm: float = 2.0) -> list[tuple[float, float, float]]:
    """(time since onset, total force, speed mm/s) of each frame while it slides, up to ``until_mm``."""
    out = []
    period = 1.0 / world.rate_hz
    j = 0
    while not world.done:
        t = j * period
        world.advance_to(t)
        c = world.contact
        if c.slides and math.hypot(*c.displacement_mm) >= until_mm:
            break
        total = float(world.frame(j, t).sum())
        if c.sliding:
            out.append((t - c.slides[-1][0], total, c.speed_mm_s))
        j += 1
    return out


def test_a_slide_of_a_friction_law_without_velocity_weakening_renders_with_no_ripple():
    for viscous in (0.0, 1.0, 4.0):
        world, grip = slide_world(viscous=viscous)
        frames = frames_while_sliding(world)
        assert len(frames) > 10
        totals = np.array([f for _, f, _ in frames])
        np.testing.assert_allclose(totals, grip, rtol=1e-9)  # the grip, frame after frame: no stick-slip tell
        assert world.contact.stick_slips == 0


def test_a_velocity_weakening_law_makes_the_stick_slip_and_the_frames_show_it():
    world, grip = slide_world(stribeck_m_per_s=0.005)
    frames = frames_while_sliding(world)
    totals = np.array([f for _, f, _ in frames]) / grip
    assert world.contact.stick_slips >= 5
    assert totals.std() > 0.01 and np.abs(totals - 1).max() <= OBJECT["part"].stick_slip_force + 1e-9
    # the same law with a strengthening strong enough to outweigh its weakening: smooth
    world, grip = slide_world(stribeck_m_per_s=0.005, viscous=40.0)
    assert world.contact.friction.weakens_below_m_per_s == 0.0
    frames = frames_while_sliding(world, until_mm=0.5)
    assert frames and world.contact.stick_slips == 0
    np.testing.assert_allclose([f for _, f, _ in frames], grip, rtol=1e-9)


def test_the_sensed_normal_force_drops_at_a_slides_onset_by_the_familys_share():
    world, grip = slide_world(force_drop=0.2)
    frames = frames_while_sliding(world)
    early = [f for dt, f, _ in frames if dt < 0.002]
    late = [f for dt, f, _ in frames if dt >= 0.02]
    assert early and late
    assert early[0] == pytest.approx(grip, rel=0.02)  # the onset: still the whole grip
    np.testing.assert_allclose(late, 0.8 * grip, rtol=1e-9)  # 20 ms on, a fifth of it gone
    # the physics' grip is unchanged: the drive holds its force, the sensed pad sees less
    assert world.grip_n == pytest.approx(grip)


def test_a_normal_force_lost_at_onset_comes_back_once_the_object_sticks_again():
    world, grip = slide_world(force_drop=0.3, rate_hz=100.0)
    world.advance_to(0.505)
    assert world.contact.sliding
    world.command(0.505, 3 * grip)  # the grip rises: it stops, the footprint still on the array
    world.advance_to(0.6)
    end = world.contact.slides[-1][1]
    assert end is not None and not world.contact.sliding
    assert world.frame(60, 0.6).sum() < 3 * grip * 0.95  # just after it stopped: still short
    world.advance_to(end + 0.15)
    k = int(round((end + 0.15) * 100))
    assert world.frame(k, k / 100).sum() == pytest.approx(3 * grip, rel=1e-9)
    assert TICK_S == DT
