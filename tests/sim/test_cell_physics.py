"""The closed loop's cell, its parts alone: Coulomb friction with the pads' velocity
strengthening, the drop and the crush, the gripper's drive, the task's timeline, the
frames rendered from the state, and the world's skipping ahead while nothing moves."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from eskin_industrial.scenes.physics import footprint_forces, sampled_forces
from eskin_industrial.sim.cell.actuator import Actuator, ActuatorSpec
from eskin_industrial.sim.cell.episodes import TUNING_SEEDS, episode
from eskin_industrial.sim.cell.objects import OBJECT, OBJECTS, Specimen
from eskin_industrial.sim.cell.physics import DROP_MM, Contact, Friction, G
from eskin_industrial.sim.cell.render import FrameRenderer
from eskin_industrial.sim.cell.world import TICK_S, CellWorld

DT = 0.001


def run(contact: Contact, seconds: float, grip_n: float, mass: float = 0.2, ax: float = 0.0, ay: float = 0.0,
        held: bool = True) -> None:
    for _ in range(int(round(seconds / DT))):
        contact.step(DT, grip_n, mass, ax, ay, held)


def test_static_friction_holds_up_to_its_limit_and_not_beyond():
    mass, mu_s = 0.2, 0.5
    need = mass * G / (2 * mu_s)  # two pads
    held = Contact(Friction(mu_s, 0.4))
    run(held, 1.0, need * 1.001, mass)
    assert held.slid_m == 0.0 and not held.slides
    slips = Contact(Friction(mu_s, 0.4))
    run(slips, 0.2, need * 0.999, mass)
    assert slips.slid_m > 0 and len(slips.slides) == 1 and slips.slides[0][0] == pytest.approx(DT)


def test_a_slide_under_a_steady_excess_reaches_the_speed_the_pads_velocity_strengthening_gives():
    # m dv/dt = L - N mu_k - N c v: v -> (L - N mu_k) / (N c) with time constant m / (N c)
    mass, mu_s, mu_k, c, grip = 0.3, 0.5, 0.4, 4.0, 2.5
    contact = Contact(Friction(mu_s, mu_k, c))
    load, normal = mass * G, 2 * grip
    assert load > mu_s * normal
    run(contact, 0.25, grip, mass)
    v_end = (load - normal * mu_k) / (normal * c)
    tau = mass / (normal * c)
    assert contact.vx == pytest.approx(v_end, rel=1e-3)
    x = v_end * (0.25 - tau * (1 - math.exp(-0.25 / tau)))
    assert x * 1000 < DROP_MM and contact.dropped_at is None
    assert contact.x == pytest.approx(x, rel=0.02)  # semi-implicit Euler at 1 ms
    assert contact.slid_mm == pytest.approx(contact.x * 1000, rel=1e-9)  # straight down


def test_a_slide_stops_once_kinetic_friction_takes_the_load_and_then_sticks():
    mass, mu_s, mu_k = 0.2, 0.5, 0.4
    contact = Contact(Friction(mu_s, mu_k))
    need = mass * G / (2 * mu_s)
    run(contact, 0.05, need * 0.9, mass)  # slides
    assert contact.sliding
    # between the kinetic and the static limit it goes on sliding (no new grip from friction)
    run(contact, 0.05, mass * G / (2 * mu_k) * 0.99, mass)
    assert contact.sliding
    before = contact.x
    run(contact, 0.2, need * 1.5, mass)  # the grip rises: it stops, and stays
    assert not contact.sliding and contact.vx == 0.0 and contact.slides[-1][1] is not None
    stopped = contact.x
    run(contact, 0.5, need * 1.5, mass)
    assert contact.x == stopped >= before


def test_the_object_drops_once_it_has_slid_off_the_contact():
    contact = Contact(Friction(0.5, 0.4))
    run(contact, 2.0, 0.2, 0.3)
    assert contact.dropped_at is not None
    assert math.hypot(*contact.displacement_mm) == pytest.approx(DROP_MM, abs=0.5)
    x = contact.x
    run(contact, 0.5, 0.2, 0.3)
    assert contact.x == x  # over: nothing moves any more


def test_a_grip_at_the_crush_force_breaks_the_object_and_the_table_carries_it_until_the_lift():
    fragile = Contact(Friction(0.5, 0.4), crush_n=10.0)
    run(fragile, 0.1, 9.99)
    assert fragile.crushed_at is None
    run(fragile, 0.1, 10.0)
    assert fragile.crushed_at is not None and fragile.over
    on_table = Contact(Friction(0.5, 0.4))
    run(on_table, 1.0, 0.0, held=False)  # no grip at all, and nothing moves
    assert on_table.slid_m == 0.0


def test_acceleration_loads_the_grip_and_a_horizontal_one_slides_it_sideways():
    mass, mu_s = 0.2, 0.5
    grip = mass * G / (2 * mu_s) * 1.2  # holds at rest with 20 % to spare
    lift = Contact(Friction(mu_s, 0.4))
    run(lift, 0.1, grip, mass, ax=-3.0)  # lifting at 3 m/s^2: m (g + a) > 1.2 m g
    assert lift.slid_m > 0 and lift.x > 0
    side = Contact(Friction(mu_s, 0.4))
    run(side, 0.1, grip, mass, ay=8.0)  # the arm speeds up along +y: the object lags along -y
    assert side.y < 0 < side.x


def test_the_drive_takes_a_request_after_its_dead_time_at_its_rate():
    act = Actuator(ActuatorSpec(rate_n_per_s=500.0, dead_s=0.010))
    act.command(0.0, 10.0)
    forces = {}
    for k in range(1, 41):
        forces[k] = act.step(k * DT, DT)
    assert forces[9] == 0.0 and forces[10] == pytest.approx(0.5)  # 10 ms dead, then 0.5 N a ms
    assert forces[29] == pytest.approx(10.0) and forces[40] == 10.0
    act.command(0.040, 4.0)
    for k in range(41, 80):
        f = act.step(k * DT, DT)
    assert f == 4.0 and act.settled


def test_the_task_loads_the_fingers_only_between_lift_and_place():
    ep = episode(TUNING_SEEDS[0])
    tab = ep.task.table(TICK_S, ep.specimen.mass_kg)
    held = np.asarray(tab.held)
    t = np.arange(len(tab)) * TICK_S
    assert not held[t < ep.task.lift_s - 1e-9].any() and held[(t >= ep.task.lift_s) & (t < ep.task.place_s)].all()
    assert min(tab.ax) < 0 < max(tab.ax)  # up, then slowing down
    if ep.task.pours:
        assert tab.mass[-1] == pytest.approx(ep.specimen.mass_kg + ep.specimen.pour_kg)


def test_specimens_stay_in_their_ranges_and_the_seed_decides_them():
    rng = np.random.default_rng(5)
    for kind in OBJECTS:
        for _ in range(50):
            s = Specimen.draw(kind, rng)
            assert kind.mass_kg.lo <= s.mass_kg <= kind.mass_kg.hi
            assert kind.mu_s.lo <= s.mu_s <= kind.mu_s.hi and s.mu_k < s.mu_s
            assert s.fragile == (kind.crush_n is not None)
    assert episode(8003) == episode(8003) and episode(8003) != episode(8008)


@pytest.mark.parametrize("name", ["glass", "part"])
def test_a_rectangle_is_rendered_as_the_scenes_render_it(name):
    kind = replace(OBJECT[name], sensor=replace(OBJECT[name].sensor, noise_n=0.0))
    r = FrameRenderer(kind, 100.0, 10, np.random.default_rng(0))
    got = r.frame(0, 0.0, 3.3, 1.7, -0.6)
    centre = np.asarray(kind.footprint.centre_mm)[None, :] + [[1.7, -0.6]]
    want = footprint_forces(kind.array, kind.footprint, centre, np.array([3.3]))[0]
    np.testing.assert_allclose(got, want, atol=1e-12)


@pytest.mark.parametrize("name", ["egg", "cup"])
def test_a_sampled_shape_is_interpolated_within_a_percent_of_its_force(name):
    kind = replace(OBJECT[name], sensor=replace(OBJECT[name].sensor, noise_n=0.0))
    r = FrameRenderer(kind, 100.0, 10, np.random.default_rng(0))
    rng = np.random.default_rng(1)
    foot = kind.footprint
    for _ in range(20):
        d = rng.uniform(-12.0, 12.0, 2)
        got = r.frame(0, 0.0, 5.0, d[0], d[1])
        want = sampled_forces(kind.array, foot, np.asarray(foot.centre_mm)[None, :] + d, np.array([foot.angle_deg]),
                              np.zeros((1, 2)), np.array([5.0]))[0]
        assert np.abs(got - want).max() <= 0.01 * 5.0


def test_a_frames_noise_is_its_own_whenever_it_is_rendered():
    kind = OBJECT["part"]
    a = FrameRenderer(kind, 100.0, 50, np.random.default_rng(9))
    b = FrameRenderer(kind, 100.0, 50, np.random.default_rng(9))
    first = [a.frame(k, k / 100, 20.0, 0.0, 0.0) for k in range(5)]
    b.frame(0, 0.0, 25.0, 3.0, 0.0)  # another state first: the same noise per frame
    again = b.frame(3, 0.03, 20.0, 0.0, 0.0)
    np.testing.assert_array_equal(first[3], again)
    assert not np.array_equal(first[3], first[4])


def test_the_world_skips_ahead_only_where_nothing_can_happen():
    # the same episode tick by tick (no skipping) and with the skip: identical physics
    ep = episode(8005)  # a glass: lift, transport, pour, bump
    spec = ActuatorSpec()
    fast, slow = CellWorld(ep, spec, 100.0), CellWorld(ep, spec, 100.0)
    for w in (fast, slow):
        w.command(0.2, 2.0)
        w.command(5.0, 3.0)
    for k in range(1, int(ep.task.end_s / TICK_S)):
        slow._skip = lambda target: None  # type: ignore[method-assign]
        slow.advance_to(k * TICK_S)
        if k % 10 == 0:
            fast.advance_to(k * TICK_S)
            assert fast.contact.x == slow.contact.x and fast.grip_n == slow.grip_n
    fast.advance_to(ep.task.end_s)
    assert fast.contact.slides == slow.contact.slides and fast.contact.slides
    assert fast.holding_s == pytest.approx(slow.holding_s) and fast.grip_ns == pytest.approx(slow.grip_ns)
