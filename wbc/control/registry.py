"""The explicit registry of named controllers (the protocol they implement is `wbc.control.protocol.Controller`).

A controller sees only what a real robot gives it (`RobotState`) and the operator's `VelocityCommand`; it never sees
the scenario, the push schedule or simulator truth. Each registered controller names the arm mode it drives, so
``stand-noarm`` runs on the robot without its arm while ``stand`` holds an actuated arm.

Besides the registry's names, ``policy:PATH`` runs any exported policy file (``wbc train``'s ``policy.npz``, a
baseline's, a composite) through `LearnedController`; its robot and arm mode come from the file, so a run of your own
meets the shipped controllers on the same trials: ``wbc compare learned policy:runs/train/push-stage3-ppo/policy``.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass

from wbc.control.protocol import Controller
from wbc.control.stand import StandController
from wbc.errors import ConfigError, UnknownNameError
from wbc.learned.policy.composite_policy import load_composite
from wbc.learned.policy.controller import LearnedController
from wbc.mpc.controller import MpcController
from wbc.robots.description import RobotDescription, check_arm_mode

__all__ = ["ControllerSpec", "CONTROLLERS", "POLICY_PREFIX", "arm_variant", "get_controller"]

POLICY_PREFIX = "policy:"
"""``policy:PATH`` names the exported policy at PATH (the .npz, the .json or their stem)."""


@dataclass(frozen=True)
class ControllerSpec:
    """A registry entry.

    Attributes:
        name: registry name.
        arm_mode: arm mode of the robot this controller drives (``none``, ``locked``, ``actuated``).
        make: builds the controller for a robot description.
        summary: one line for ``--help`` and reports.
        robot: the only robot it can drive (a policy file's), or None for any robot.
    """

    name: str
    arm_mode: str
    make: Callable[[RobotDescription], Controller]
    summary: str
    robot: str | None = None

    def __post_init__(self) -> None:
        check_arm_mode(self.arm_mode)


CONTROLLERS: dict[str, ControllerSpec] = {
    "stand": ControllerSpec("stand", "actuated", StandController,
                            "PD hold of the nominal pose, arm actuated and held"),
    "stand-locked": ControllerSpec("stand-locked", "locked", StandController,
                                   "PD hold of the nominal pose, arm locked"),
    "stand-noarm": ControllerSpec("stand-noarm", "none", StandController,
                                  "PD hold of the nominal pose, robot without its arm"),
    "mpc": ControllerSpec("mpc", "actuated", MpcController,
                          "centroidal MPC with arm momentum terms; the optimiser may swing the arm"),
    "mpc-locked": ControllerSpec("mpc-locked", "locked", MpcController, "centroidal MPC, arm locked"),
    "mpc-noarm": ControllerSpec("mpc-noarm", "none", MpcController, "centroidal MPC, robot without its arm"),
    "learned": ControllerSpec("learned", "actuated", LearnedController,
                              "learned policy pi3 (PPO + BC, staged), arm actuated; shipped weights, numpy"),
    "learned-locked": ControllerSpec("learned-locked", "locked", LearnedController,
                                     "learned policy pi2, arm locked; shipped weights, numpy"),
    "learned-noarm": ControllerSpec("learned-noarm", "none", LearnedController,
                                    "learned policy pi1, robot without its arm; shipped weights, numpy"),
}


def get_controller(name: str) -> ControllerSpec:
    """Look a controller up by name, or read the policy file a ``policy:PATH`` name points to.

    Raises:
        UnknownNameError: an unknown name (the message lists the valid ones).
        PolicyFileError: a ``policy:`` file that is missing or malformed (the message names the file and field).
    """
    if name.startswith(POLICY_PREFIX):
        return _policy_spec(name)
    if name not in CONTROLLERS:
        raise UnknownNameError("controller", name, (*CONTROLLERS, f"{POLICY_PREFIX}PATH"))
    return CONTROLLERS[name]


def _policy_spec(name: str) -> ControllerSpec:
    path = name[len(POLICY_PREFIX):]
    policy = load_composite(path)  # the whole file is read and checked here, once, before any trial starts
    meta = policy.meta
    return ControllerSpec(name, meta["arm_mode"], functools.partial(LearnedController, policy_path=path, policy=policy),
                          f"policy file {path} ({meta['task']} task, stage {meta['stage']})", robot=meta["robot"])


def arm_variant(spec: ControllerSpec, arm_mode: str) -> ControllerSpec:
    """The registered controller that does what `spec` does on a robot with arm mode `arm_mode`.

    Variants are the entries built by the same factory (``stand``, ``stand-locked`` and ``stand-noarm`` are all the
    stand controller), so a hardware trial can name a controller as the arena does and play it on the arm the robot
    has: ``stand`` with the arm ``none`` is ``stand-noarm``.

    Raises:
        UnknownNameError: `arm_mode` is not an arm mode.
        ConfigError: `spec` has no variant for `arm_mode` (a policy file drives the arm mode it was trained on).
    """
    check_arm_mode(arm_mode)
    if spec.arm_mode == arm_mode:
        return spec
    variants = [s for s in CONTROLLERS.values() if s.make is spec.make]
    for variant in variants:
        if variant.arm_mode == arm_mode:
            return variant
    have = ", ".join(f"{s.name} ({s.arm_mode})" for s in variants) or f"{spec.name} ({spec.arm_mode})"
    raise ConfigError(f"controller {spec.name} drives the arm mode {spec.arm_mode}, and no variant of it drives "
                      f"{arm_mode!r} (variants: {have}); choose the arm mode it was made for, or another controller")
