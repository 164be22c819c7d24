"""The robot registry: each factory takes the arm mode and the keyword options `get_robot` passes, and returns a
description named by its key in `ROBOTS`."""

import functools

import pytest

from wbc.errors import ConfigError
from wbc.robots import ARM_MODES, ROBOTS, get_robot
from wbc.robots.a1_wx200 import a1_wx200


@pytest.mark.parametrize("name", list(ROBOTS))
def test_every_robot_is_named_by_its_key_and_takes_the_arm_mass_scale(name):
    for mode in ARM_MODES:
        assert get_robot(name, mode).name == name
    heavy = get_robot(name, "actuated", arm_mass_scale=1.5)
    assert heavy.name == name and heavy.arm != get_robot(name, "actuated").arm


def test_a_variant_that_keeps_another_robots_name_is_refused(monkeypatch):
    """A variant registered as a copy of a1_wx200 played as a1-wx200: controllers claimed it with that robot's
    weights, and its results were recorded under the other name."""
    monkeypatch.setitem(ROBOTS, "a1-wx200-heavy", functools.partial(a1_wx200, arm_mass_scale=1.5))
    with pytest.raises(ConfigError, match=r"robot 'a1-wx200-heavy': its factory .* returned a description named "
                       r"'a1-wx200'; a description's name must be its key in ROBOTS \(wbc/robots/registry.py\)"):
        get_robot("a1-wx200-heavy")
