"""`ModelPool`: the compiled MuJoCo model variants the batched env steps (domain randomisation by model).

Every variant is the scene of `wbc.hardware.mujoco.scene` for the same (robot, arm mode), so physics and the motor
law are those of evaluation, plus the sensors of evaluation's fall rule (`wbc.hardware.mujoco.fall_rule`): one
``contact`` sensor per robot collision geom other than the foot spheres, reporting up to `FALL_SLOTS` ground contacts
with their positions, and one ``framepos`` sensor per foot sphere (the foot centres), all filled inside MuJoCo's step.
Each variant then gets its own payload, friction, motor strength and (on rough ground) terrain, written by the
functions `MujocoRobot` uses (`wbc.hardware.mujoco.physics`). `mujoco.rollout` takes one model per environment, so an
environment draws a variant at every reset at no cost; the pool's size bounds memory (a 401 x 401 heightfield is
1.3 MB per variant).

Motor law, as `MujocoRobot` writes it (`physics.set_motor_gains`): ``force = k (ctrl - kp q - kd dq)`` clamped to
``k`` times the torque limit, with ``ctrl = kp q*`` (zero target velocity and feed-forward) and ``k`` the variant's
motor strength; the gains are fixed per variant, so they are written once, here.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from wbc.hardware.mujoco.fall_rule import fall_geoms, foot_geoms
from wbc.hardware.mujoco.physics import (
    NominalModel,
    apply_domain,
    apply_terrain,
    base_body_id,
    foot_touch_adr,
    sensor_slices,
    set_motor_gains,
)
from wbc.hardware.mujoco.scene import TERRAIN_GEOM, scene_spec
from wbc.learned.env.env_config import EnvConfig
from wbc.robots.description import RobotDescription
from wbc.scenario.terrain import TerrainConfig

__all__ = ["FALL_SLOTS", "ModelPool", "Variant"]

FALL_SLOTS = 4
"""Ground contacts reported per fall geom (a box or cylinder on a plane makes at most 4; beyond that, on rough ground,
the extra contacts of a geom that already touches are not seen, which matters only if every seen one is a foot's)."""


@dataclass(frozen=True)
class Variant:
    """The randomised parameters of one model variant.

    Attributes:
        payload_kg: extra trunk mass [kg].
        friction: sliding friction.
        motor_strength: torque multiplier per actuated joint, shape (n,).
        ground_height: terrain height under the spawn point [m].
    """

    payload_kg: float
    friction: float
    motor_strength: np.ndarray
    ground_height: float


class ModelPool:
    """Compiled variants of one robot scene.

    Args:
        desc: the robot.
        terrain: ground shape (a fractal gets one seeded terrain per variant).
        config: gains, timestep and randomisation ranges.
        rng: draws the variants.
    """

    def __init__(self, desc: RobotDescription, terrain: TerrainConfig, config: EnvConfig,
                 rng: np.random.Generator) -> None:
        self.desc = desc
        spec = scene_spec(desc, terrain, timestep=config.timestep)
        spec.option.solver = {"newton": mujoco.mjtSolver.mjSOL_NEWTON, "cg": mujoco.mjtSolver.mjSOL_CG}[config.solver]
        for i, geom in enumerate(spec.geoms):  # sensors name their geom; the scene leaves the robot's unnamed
            if not geom.name:
                geom.name = f"geom{i}"
        probe = spec.compile()
        fall = [probe.geom(int(g)).name for g in fall_geoms(probe)]
        feet = [probe.geom(int(g)).name for g in foot_geoms(probe)]
        found_pos = 1 | 1 << 4  # mjCONDATA_FOUND | mjCONDATA_POS: per slot, (found, x, y, z)
        for name in fall:
            spec.add_sensor(name=f"{name}_ground", type=mujoco.mjtSensor.mjSENS_CONTACT,
                            objtype=mujoco.mjtObj.mjOBJ_GEOM, objname=name, reftype=mujoco.mjtObj.mjOBJ_GEOM,
                            refname=TERRAIN_GEOM, intprm=[found_pos, 0, FALL_SLOTS])
        for name in feet:
            spec.add_sensor(name=f"{name}_centre", type=mujoco.mjtSensor.mjSENS_FRAMEPOS,
                            objtype=mujoco.mjtObj.mjOBJ_GEOM, objname=name)
        base = spec.compile()
        self.base_body = base_body_id(base)
        self.sensor_slices = sensor_slices(base)
        self.touch_adr = foot_touch_adr(base)
        self.fall_geom_names = tuple(fall)
        slots = np.array([self.sensor_slices[f"{g}_ground"].start for g in fall])[:, None] + 4 * np.arange(FALL_SLOTS)
        self.fall_found_adr = slots.reshape(-1)  # sensordata index of each contact slot's "found"
        self.fall_pos_adr = self.fall_found_adr[:, None] + np.arange(1, 4)  # ... and of its position (x, y, z)
        self.foot_centre_adr = np.array([np.arange(self.sensor_slices[f"{g}_centre"].start,
                                                   self.sensor_slices[f"{g}_centre"].stop) for g in feet])
        n = desc.num_joints
        self.kp, self.kd = config.gains(n)
        dr = config.domain
        self.models: list[mujoco.MjModel] = []
        self.variants: list[Variant] = []
        nominal = NominalModel.of(base)  # before variant 0, which is `base` itself, changes it
        for _ in range(dr.num_variants):
            m = spec.compile() if self.models else base
            payload = float(rng.uniform(*dr.payload_kg))
            com = rng.uniform(-dr.payload_com_m, dr.payload_com_m, 3)
            friction = float(rng.uniform(*dr.friction))
            strength = rng.uniform(*dr.motor_strength, n)
            # flat ground takes no seed, and drawing one anyway would shift every later draw of the stream
            ground = apply_terrain(m, terrain, int(rng.integers(2**31)) if terrain.kind == "fractal" else 0)
            apply_domain(m, mujoco.MjData(m), nominal, payload_kg=payload, payload_com=com, friction=friction,
                         motor_strength=strength)
            set_motor_gains(m, strength, self.kp, self.kd)
            self.models.append(m)
            self.variants.append(Variant(payload_kg=payload, friction=friction, motor_strength=strength,
                                         ground_height=ground))
        self.payload_kg = np.array([v.payload_kg for v in self.variants])
        self.friction = np.array([v.friction for v in self.variants])
        self.strength = np.array([v.motor_strength.mean() for v in self.variants])
        self.ground_height = np.array([v.ground_height for v in self.variants])
        self.base_ipos = np.array([m.body_ipos[self.base_body] for m in self.models])

    @property
    def model(self) -> mujoco.MjModel:
        """The first variant (sizes and indices are shared by all)."""
        return self.models[0]
