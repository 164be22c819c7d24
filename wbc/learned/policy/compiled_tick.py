"""`policy_tick`: a policy's whole control tick in one compiled call, to the bits of the numpy path.

`LearnedController.act` on a robot's state goes observation (`wbc.learned.policy.observations.policy_observation`),
normalisation, the adaptation module's history window, the networks, the clip and the motor command: a dozen numpy
calls on arrays of a few dozen entries, about half of a tick's CPU. `policy_tick` does the same operations in the
same order, element by element, in one call: the observation in float64 rounded to float32, ``(obs - mean) * scale``
in float64, the window in float32, each network through `wbc.learned.policy.numpy_policy`'s compiled layers (numpy's
pairwise order), the clip as ``np.clip`` (NaN stays NaN) and ``default_q + action_scale * action``. It serves a
policy of one part whose activation the compiled layers have (ELU or identity); every other file takes the numpy
path. A test plays both paths on the same ticks and compares their bits.
"""

from __future__ import annotations

import numba
import numpy as np

from wbc.learned.policy.numpy_policy import _mlp_rows

__all__ = ["policy_tick"]


@numba.njit(cache=True, nogil=True)
def policy_tick(gyro, quat, vx, vy, yaw_rate, q, dq, last_action, fresh, window, action, rows, default_q, cmd_scale,
                ang_scale, pos_scale, vel_scale, obs_mean, obs_scale, adapt_w, adapt_b, actor_w, actor_b, elu,
                remembers, clip, action_scale, kp, kd):  # pragma: no cover - compiled
    """One tick of a one-part policy into `action` (n,) and the motor command's `rows` (5, n); returns their validity.

    Args:
        gyro: body angular velocity (3,) [rad/s].
        quat: IMU quaternion (4,), w x y z, body to world.
        vx: commanded forward velocity [m/s].
        vy: commanded lateral velocity [m/s].
        yaw_rate: commanded yaw rate [rad/s].
        q: joint positions (n,) [rad].
        dq: joint velocities (n,) [rad/s].
        last_action: the previous action (n,), which the observation holds.
        fresh: the first tick after a reset: the window is filled with this observation instead of shifted.
        window: the adaptation module's window of normalised observations (H, D) float32, oldest first; updated.
        action: out, this tick's clipped action (n,).
        rows: out, the motor command's rows q, dq, kp, kd, tau (5, n).
        default_q: joint positions the actions are offsets from (n,) [rad].
        cmd_scale: the command's scales (3,).
        ang_scale: the body rates' scale.
        pos_scale: the joint positions' scale.
        vel_scale: the joint velocities' scale.
        obs_mean: the normaliser's mean (D,).
        obs_scale: the normaliser's 1 / (std + eps) (D,).
        adapt_w: the adaptation module's weights, transposed (in, out), read only when `remembers`.
        adapt_b: its biases.
        actor_w: the actor's weights, transposed (in, out).
        actor_b: its biases.
        elu: the hidden layers' activation is the ELU (else the identity).
        remembers: the policy reads its window through the adaptation module (its latent follows the observation).
        clip: the actions' bound.
        action_scale: radians per action unit.
        kp: the motors' position gains (n,).
        kd: the motors' damping gains (n,).

    Returns:
        Whether every entry of `rows` is finite and both gain rows are non-negative (`wbc.types.MotorCommand`'s
        check).
    """
    n = q.shape[0]
    size = 9 + 3 * n
    obs = np.empty(size, dtype=np.float32)
    for a in range(3):
        obs[a] = np.float32(gyro[a] * ang_scale)
    w, x, y, z = quat[0], quat[1], quat[2], quat[3]
    obs[3] = np.float32(-(2 * (x * z - w * y)))
    obs[4] = np.float32(-(2 * (y * z + w * x)))
    obs[5] = np.float32(-(1 - 2 * (x * x + y * y)))
    obs[6] = np.float32(vx * cmd_scale[0])
    obs[7] = np.float32(vy * cmd_scale[1])
    obs[8] = np.float32(yaw_rate * cmd_scale[2])
    for j in range(n):
        obs[9 + j] = np.float32((q[j] - default_q[j]) * pos_scale)
        obs[9 + n + j] = np.float32(dq[j] * vel_scale)
        obs[9 + 2 * n + j] = np.float32(last_action[j])
    zdim = actor_w[0].shape[0] - size
    x_in = np.empty((1, size + zdim))
    for i in range(size):
        x_in[0, i] = (np.float64(obs[i]) - obs_mean[i]) * obs_scale[i]
    if remembers:
        length = window.shape[0]
        if fresh:
            for h in range(length):
                for i in range(size):
                    window[h, i] = np.float32(x_in[0, i])
        else:
            for h in range(length - 1):
                for i in range(size):
                    window[h, i] = window[h + 1, i]
            for i in range(size):
                window[length - 1, i] = np.float32(x_in[0, i])
        flat = np.empty((1, length * size))
        for h in range(length):
            for i in range(size):
                flat[0, h * size + i] = np.float64(window[h, i])
        latent = _mlp_rows(flat, adapt_w, adapt_b, elu)
        for k in range(zdim):
            x_in[0, size + k] = latent[0, k]
    out = _mlp_rows(x_in, actor_w, actor_b, elu)
    valid = True
    for j in range(n):
        v = out[0, j]
        if v < -clip:
            v = -clip
        elif v > clip:
            v = clip
        action[j] = v
        target = default_q[j] + action_scale * v
        rows[0, j] = target
        rows[1, j] = 0.0
        rows[2, j] = kp[j]
        rows[3, j] = kd[j]
        rows[4, j] = 0.0
        if not (np.isfinite(target) and np.isfinite(kp[j]) and np.isfinite(kd[j]) and kp[j] >= 0.0 and kd[j] >= 0.0):
            valid = False
    return valid
