"""`LearnedController`: an exported policy (`PolicyFile`) run in numpy at its policy rate (50 Hz).

Every tick: the policy observation from `RobotState` (IMU quaternion and gyro, joint encoders) and the operator's
command, exactly as the training env builds it (`wbc.learned.policy.observations`); the deterministic action; the motor
command ``q* = default_q + action_scale * action`` with the PD gains the policy was trained with (zero target
velocity and feed-forward torque), which the motor drivers (or MuJoCo's actuators) track between ticks. Nothing from
the simulator's truth is read. A policy that observes the RMA extrinsics z gets them from the file's adaptation
module (RMA phase 2) over the last H normalised observations (`ObsHistory`, filled with the first observation after a
reset, as in training); a file with extrinsics and no adaptation module is refused at construction.

A composite policy file (`wbc.learned.policy.composite_policy`, the decoupled baseline: pi2's legs plus an arm policy)
runs through the same path: every part gets its own view of the observation and, if it estimates extrinsics, its own
history; each part's actions go to its joints, and ``last_action`` holds the whole robot's, as in training.

The registry's ``learned``, ``learned-locked`` and ``learned-noarm`` run the weights shipped in
``wbc/learned/weights/<robot>-<arm mode>.npz`` (pi3, pi2 and pi1 of the robot's task, `shipped_weights`);
``learned-crouched``, ``learned-locked-crouched`` and ``learned-noarm-crouched`` run
``<robot>-<arm mode>-crouched.npz``, the same stages as first trained, without the posture term (they crouch about
12 cm below the nominal trunk height).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wbc.errors import ConfigError
from wbc.learned.policy.compiled_tick import policy_tick
from wbc.learned.policy.composite_policy import CompositePolicyFile, load_composite
from wbc.learned.policy.numpy_composite import NumpyComposite
from wbc.learned.policy.obs_history import ObsHistory
from wbc.learned.policy.observations import ObsLayout, ObsScales, policy_observation
from wbc.learned.policy.policy_file import PolicyFileError
from wbc.learned.policy.shipped import shipped_weights
from wbc.robots.description import RobotDescription
from wbc.types import MotorCommand, RobotState, VelocityCommand

__all__ = ["LearnedController"]


def _takes_state(state: RobotState, n: int) -> bool:
    """Whether `policy_tick` takes the state's arrays as they are: float64 vectors of the robot's sizes.

    Anything else takes the numpy path, which converts what it can and raises numpy's error on what it cannot: the
    compiled tick does not check its indices. Arrays that are read-only or not contiguous take it too, with the same
    result: the compiled tick would load another version of itself for them at their first tick.
    """
    arrays = (state.gyro_in_body, state.imu_quat, state.q, state.dq)
    return all(isinstance(a, np.ndarray) and a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable
               for a in arrays) and \
        (state.gyro_in_body.shape, state.imu_quat.shape, state.q.shape, state.dq.shape) == ((3,), (4,), (n,), (n,))


class LearnedController:
    """Runs an exported policy.

    Args:
        desc: the robot it drives (checked against the policy file).
        policy_path: the policy file (default: `shipped_weights(desc, posture)`).
        policy: the file's content, already read from `policy_path` (`load_composite`), so that a run that builds
            one controller per trial reads the file once.
        posture: None (the shipped weights) or a posture variant of them (`POSTURES`: ``"crouched"``); only without
            `policy_path`.

    Raises:
        PolicyFileError: the file is missing or malformed, was trained for another robot or arm mode, or needs
            extrinsics without an adaptation module.
    """

    def __init__(self, desc: RobotDescription, policy_path: str | Path | None = None, *,
                 policy: CompositePolicyFile | None = None, posture: str | None = None) -> None:
        if policy_path is not None and posture is not None:
            raise ConfigError(f"LearnedController: a policy file ({policy_path}) or a posture of the shipped "
                              f"weights ({posture}), not both")
        path = Path(policy_path) if policy_path is not None else shipped_weights(desc, posture)
        if policy_path is None and not path.exists():
            raise PolicyFileError(path, None, f"no shipped weights for {desc.name} with arm {desc.arm_mode!r}"
                                  + (f" and posture {posture!r}" if posture else "") + " yet; "
                                  "train them (wbc train --task push --stage 1|2|3) and copy the run's policy.npz "
                                  f"and policy.json to {path.with_suffix('')}.npz/.json")
        pf = load_composite(path) if policy is None else policy
        pf.check_robot(desc, path)
        prefix = "" if len(pf.parts) == 1 else "{}/"
        for part in pf.parts:
            if part.policy.meta.get("extrinsics") is not None and part.policy.meta.get("adaptation") is None:
                raise PolicyFileError(path, prefix.format(part.name) + "extrinsics", "the policy observes the RMA "
                                      "extrinsics z, which a robot cannot measure, and the file has no adaptation "
                                      "module to estimate z (RMA phase 2)")
        meta = pf.meta
        layout = ObsLayout(pf.num_actions)
        if [list(p) for p in meta["obs_layout"]] != layout.as_list():
            raise PolicyFileError(path, "obs_layout", f"{meta['obs_layout']} is not this version's layout "
                                  f"{layout.as_list()}")
        self.policy = NumpyComposite(pf)
        self.path = path
        self.rate_hz = 1.0 / float(meta["policy_dt"])
        sc = meta["obs_scales"]
        self.scales = ObsScales(ang_vel=sc["ang_vel"], dof_pos=sc["dof_pos"], dof_vel=sc["dof_vel"],
                                command=tuple(sc["command"]))
        self.default_q = np.asarray(meta["default_q"], dtype=np.float64)
        self.action_scale = float(meta["action_scale"])
        self.clip = float(meta["clip_actions"])
        self.kp = np.asarray(meta["kp"], dtype=np.float64)
        self.kd = np.asarray(meta["kd"], dtype=np.float64)
        n = pf.num_actions
        self._zeros = np.zeros(n)
        self.last_action = np.zeros(n)
        # each adapting part's window of its own normalised observations, by part name
        self.histories = {part.name: ObsHistory(1, part.policy.history, part.obs_index.size)
                          for part in self.policy.parts if part.policy.history}
        self._fresh = True
        # one part that observes the whole observation and drives every joint (every file but a composite): `step`
        # skips the parts' bookkeeping and normalises the observation once, to the same bits
        only = self.policy.parts[0]
        self._whole = only if len(self.policy.parts) == 1 and np.array_equal(only.joints, np.arange(n)) and \
            np.array_equal(only.obs_index, np.arange(layout.size)) else None
        # the command's rows: q is written each tick, dq and tau stay zero, the gains are the file's (checked above)
        self._rows = np.zeros((5, n))
        self._rows[2], self._rows[3] = self.kp, self.kd
        self._gains_ok = bool(np.isfinite(self._rows).all() and (self._rows[2:4] >= 0.0).all())
        self._tick = self._compiled_constants()
        if self._tick is not None:
            self._load_compiled()

    def reset(self) -> None:
        """Forget the previous action and the observation history."""
        self.last_action = np.zeros_like(self.last_action)
        self._fresh = True

    def observation(self, state: RobotState, command: VelocityCommand) -> np.ndarray:
        """The policy observation, shape (obs_size,)."""
        return policy_observation(
            gyro_in_body=state.gyro_in_body[None], imu_quat=state.imu_quat[None], command=command.as_array()[None],
            q=state.q[None], dq=state.dq[None], last_action=self.last_action[None], default_q=self.default_q,
            scales=self.scales,
        )[0]

    def observation_terms(self, state: RobotState, command: VelocityCommand) -> list[tuple[str, np.ndarray]]:
        """This tick's observation frame as (term name, values) in the network's order (`ObsLayout.term_slices`).

        What `act` would feed the network for this state and command, split into its terms; nothing changes (the
        previous action is read, not replaced). ``wbc check-controller --replay`` compares it with a recording.
        """
        obs = self.observation(state, command)
        return [(name, obs[start:stop]) for name, start, stop in ObsLayout(self.last_action.size).term_slices()]

    def _compiled_constants(self) -> tuple | None:
        """`policy_tick`'s arguments that do not change, or None where it does not serve the policy.

        It serves a policy of one part on the whole observation (`_whole`) whose activation the compiled layers have
        (ELU or identity).
        """
        part = self._whole
        if part is None:
            return None
        policy = part.policy
        if policy.activation not in ("elu", "identity"):
            return None
        actor = policy._layers
        remembers = bool(policy.history)
        adaptation = policy._adaptation if remembers else actor
        window = self.histories[part.name].buf[0] if remembers else np.zeros((1, 1), dtype=np.float32)
        sc = self.scales
        return (window, self.default_q, np.asarray(sc.command, dtype=np.float64), float(sc.ang_vel), float(sc.dof_pos),
                float(sc.dof_vel), policy._obs_mean, policy._obs_scale, adaptation.weights, adaptation.biases,
                actor.weights, actor.biases, policy.activation == "elu", remembers, self.clip, self.action_scale,
                self.kp, self.kd)

    def act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """One policy step."""
        if self._tick is not None and _takes_state(state, self.last_action.size):
            return self._compiled_act(state, command)
        action = self.step(self.observation(state, command))
        target = self.default_q + self.action_scale * action
        if self._gains_ok and np.isfinite(target).all():  # what the constructor checks, on the one row that changes
            rows = self._rows.copy()
            rows[0] = target
            return MotorCommand.trusted(rows)
        return MotorCommand(q=target, dq=self._zeros, kp=self.kp, kd=self.kd, tau=self._zeros)

    def _load_compiled(self) -> None:
        """Play one compiled tick on a synthetic standing state, on copies of the window: nothing of it survives.

        The compiled tick loads at its first call in a process (compiles at the first on a new machine): here, when
        the controller is made, not at the first tick of a robot that waits for its command.
        """
        window, *constants = self._tick
        n = self.last_action.size
        policy_tick(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]), 0.0, 0.0, 0.0, self.default_q.copy(), np.zeros(n),
                    np.zeros(n), True, window.copy(), np.empty(n), np.empty((5, n)), *constants)

    def _compiled_act(self, state: RobotState, command: VelocityCommand) -> MotorCommand:
        """`act` in one compiled call (`policy_tick`): the same operations, the same bits."""
        window, *constants = self._tick
        n = self.last_action.size
        action = np.empty(n)
        rows = np.empty((5, n))  # a new array each tick: it becomes the command's (immutable) storage
        valid = policy_tick(state.gyro_in_body, state.imu_quat, float(command.vx), float(command.vy),
                            float(command.yaw_rate), state.q, state.dq, self.last_action, self._fresh, window, action,
                            rows, *constants)
        self._fresh = False
        self.last_action = action
        # a command that fails the check is refused by the constructor, which names the fault
        return MotorCommand.trusted(rows) if valid else MotorCommand.from_rows(rows)

    def step(self, observation: np.ndarray) -> np.ndarray:
        """The clipped action for this tick's policy observation (`observation`), which joins the history.

        What `act` does short of the motor command: a caller that builds the observation itself (DAgger's collection,
        whose previous action is the driver's) gets the same action, and the previous action becomes this one.
        """
        obs = np.asarray(observation, dtype=np.float64)[None]
        if self._whole is not None:
            return self._step_whole(obs)
        z = {}
        for part in self.policy.parts:
            history = self.histories.get(part.name)
            if history is None:
                continue
            normalised = part.policy.normalise(obs[:, part.obs_index]).astype(np.float32)
            if self._fresh:
                history.fill(np.zeros(1, dtype=int), normalised)
            else:
                history.push(normalised)
            z[part.name] = part.policy.adaptation(history.flat())
        self._fresh = False
        action = np.clip(self.policy(obs, z)[0], -self.clip, self.clip)
        self.last_action = action
        return action

    def _step_whole(self, obs: np.ndarray) -> np.ndarray:
        """`step` for a policy of one part on the whole observation: the same operations, without the parts' loop."""
        policy = self._whole.policy
        x = policy.normalise(obs)
        z = None
        if policy.history:
            history = self.histories[self._whole.name]
            if self._fresh:
                history.fill(np.zeros(1, dtype=int), x.astype(np.float32))
            else:
                history.push(x.astype(np.float32))
            z = policy.adaptation(history.flat())
        self._fresh = False
        action = np.clip(policy.normalised(x, z)[0], -self.clip, self.clip)
        self.last_action = action
        return action

    def counters(self) -> dict[str, int]:
        """No events."""
        return {}
