"""Fixtures shared by several test modules."""

from __future__ import annotations

import sys
import textwrap
from dataclasses import dataclass

import pytest

from wbc.hardware.clock import ManualClock
from wbc.hardware.emulators import UnitreeEmulator
from wbc.hardware.hardware_robot import HardwareRobot, HardwareRobotConfig, build_hardware_robot

LIMP = '''
    """A controller that switches its motors off: the robot folds and falls within a second."""
    import numpy as np

    from wbc.types import MotorCommand


    class Limp:
        rate_hz = 50.0

        def __init__(self, desc):
            self.command = MotorCommand.damping(desc.num_joints, 0.0)

        def reset(self):
            pass

        def act(self, state, command):
            return self.command

        def counters(self):
            return {}


    def make(desc):
        return Limp(desc)
'''


@pytest.fixture
def limp(tmp_path, monkeypatch):
    root = tmp_path / "limproot"
    (root / "limppkg").mkdir(parents=True)
    (root / "limppkg" / "__init__.py").write_text('"""Test plug-ins."""\n')
    (root / "limppkg" / "limp.py").write_text(textwrap.dedent(LIMP).lstrip())
    monkeypatch.syspath_prepend(str(root))
    yield "limppkg.limp:make"
    for name in [m for m in sys.modules if m.startswith("limppkg")]:
        del sys.modules[name]


@dataclass
class Stepped:
    """An emulated robot in process, the clock it runs on, and the builder that puts a command's or a trial's robot
    on both (`from conftest import Stepped`)."""

    clock: ManualClock
    emu: UnitreeEmulator

    def build(self, config: HardwareRobotConfig) -> HardwareRobot:
        """The robot `config` names, its legs on the clock over the emulator's in-process channel."""
        return build_hardware_robot(config, clock=self.clock, legs_transport=self.emu.transport(self.clock))
