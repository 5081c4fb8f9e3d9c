"""The closed loop's gripper classes: a drive grips no lighter than its minimum, sets
its force in steps, holds it off the setting by its error; each object's recipe keeps
within the class; ``--cell gripper=NAME`` chooses one."""
from __future__ import annotations

import pytest

from eskin_industrial.cli.evaluate_closed_loop import setup_of
from eskin_industrial.sim.cell.actuator import Actuator, ActuatorSpec
from eskin_industrial.sim.cell.episodes import episode
from eskin_industrial.sim.cell.grippers import GRIPPER_CLASS
from eskin_industrial.sim.cell.objects import OBJECT
from eskin_industrial.sim.cell.recipes import fixed_grip_n, policy_settings
from eskin_industrial.sim.cell.runner import Setup
from eskin_industrial.sim.cell.world import CellWorld

SMALL = GRIPPER_CLASS["small"].spec(ActuatorSpec())
COARSE = GRIPPER_CLASS["coarse"].spec(ActuatorSpec())


def held_force(spec: ActuatorSpec, request_n: float, error: float = 0.0) -> float:
    act = Actuator(spec, error)
    act.command(0.0, request_n)
    f = 0.0
    for k in range(1, 1001):
        f = act.step(k * 0.001, 0.001)
    return f


def test_a_small_gripper_clamps_to_its_range_and_sets_whole_newtons():
    assert held_force(SMALL, 1.2) == 3.0  # below its minimum: it grips with the minimum
    assert held_force(SMALL, 7.4) == 7.0 and held_force(SMALL, 7.6) == 8.0
    assert held_force(SMALL, 55.0) == 40.0
    assert held_force(SMALL, 0.0) == 0.0  # open is open
    assert held_force(ActuatorSpec(), 1.23) == pytest.approx(1.23)  # the cell's own drive: any force


def test_a_robotiq_class_gripper_grips_from_20_n_in_coarse_steps():
    assert held_force(COARSE, 2.0) == 20.0
    step = (235.0 - 20.0) / 255.0
    assert held_force(COARSE, 20.0 + 2.4 * step) == pytest.approx(20.0 + 2 * step)
    assert held_force(COARSE, 300.0) == 235.0


def test_the_drive_holds_its_setting_off_by_its_error_drawn_once_per_episode():
    assert held_force(SMALL, 10.0, 0.05) == pytest.approx(10.5)
    errors = set()
    for seed in range(9000, 9010):
        world = CellWorld(episode(seed), SMALL, 100.0)
        assert abs(world.actuator.error) <= 0.05
        assert world.actuator.error == CellWorld(episode(seed), SMALL, 100.0).actuator.error  # the seed's
        errors.add(world.actuator.error)
    assert len(errors) == 10
    assert CellWorld(episode(9000), ActuatorSpec(), 100.0).actuator.error == 0.0


def test_each_recipe_keeps_within_the_gripper_class():
    cup, part = OBJECT["cup"], OBJECT["part"]
    coarse = policy_settings(cup, drive=COARSE)
    assert coarse.light_n == 20.0 and coarse.fallback_n == 20.0  # a cup's 8 N cap is below its minimum
    assert policy_settings(OBJECT["egg"], drive=COARSE).step_n >= COARSE.step_n  # a raise moves the force
    assert fixed_grip_n(part, drive=SMALL) == 40.0 < fixed_grip_n(part)  # the heavy part: at its rated force
    small = policy_settings(cup, drive=SMALL)
    assert small.light_n == 3.0 and small.max_n <= 8.0


def test_the_cell_takes_a_gripper_class_by_name():
    setup = setup_of(100.0, 10.0, ("gripper=coarse",))
    assert setup.chain.actuator.min_n == 20.0 and setup.chain.actuator.rate_n_per_s == Setup().chain.actuator.rate_n_per_s
    with pytest.raises(Exception, match="gripper= one of ideal, small, coarse"):
        setup_of(100.0, 10.0, ("gripper=big",))
