"""The MuJoCo backend: standing, pushes, determinism, sensors, randomisation, terrain."""

import mujoco
import numpy as np
import pytest

from wbc.control.stand import stand_command
from wbc.errors import ConfigError, UnknownNameError
from wbc.hardware.mujoco import MujocoRobot, MujocoRobotConfig
from wbc.robots import ARM_MODES, ROBOTS
from wbc.scenario import DomainParams, Push, SensorNoise, TerrainConfig


@pytest.mark.parametrize("arm", ARM_MODES)
@pytest.mark.parametrize("name", list(ROBOTS))
def test_standing_pd_hold_stays_up_for_10_s(name, arm):
    terrain = TerrainConfig(kind="fractal" if arm == "actuated" else "flat")
    with MujocoRobot(MujocoRobotConfig(robot=name, arm_mode=arm, terrain=terrain)) as robot:
        robot.reset(seed=3)
        cmd = stand_command(robot.desc)
        start = robot.sim_truth().base_position_in_world.copy()
        for _ in range(200):
            robot.write(cmd)
            robot.advance(0.05)
            truth = robot.sim_truth()
            assert truth.ground_contact_bodies == ()
        assert truth.time == pytest.approx(10.0)
        assert truth.foot_contact.all()
        assert truth.base_position_in_world[2] > 0.2
        assert np.linalg.norm(truth.base_position_in_world[:2] - start[:2]) < 0.05
        state = robot.read()
        # the feet carry the robot's weight and the accelerometer reads gravity
        weight = robot.model.body_subtreemass[1] * 9.81
        assert state.foot_force.sum() == pytest.approx(weight, rel=0.1)
        assert state.accel_in_body[2] == pytest.approx(9.81, abs=0.2)


def _momentum(robot):
    m, d = robot.model, robot.data
    mujoco.mj_forward(m, d)
    mujoco.mj_subtreeVel(m, d)
    mass = m.body_subtreemass[1]
    return mass * d.subtree_linvel[1].copy(), d.subtree_angmom[1].copy(), d.subtree_com[1].copy()


@pytest.mark.parametrize("arm", ["none", "actuated"])
def test_push_delivers_its_impulse_where_and_when_asked(arm):
    """A robot in free fall: the momentum change is gravity's plus exactly the push's impulse and moment."""
    with MujocoRobot(MujocoRobotConfig(arm_mode=arm)) as robot:
        qpos = robot.data.qpos.copy()
        qpos[2] = 5.0  # far above the ground: no contact
        robot.reset(qpos=qpos)
        robot.write(stand_command(robot.desc))
        dt = robot.config.timestep
        mass = robot.model.body_subtreemass[1]
        gravity = robot.model.opt.gravity
        push = Push(force_in_world=np.array([120.0, -60.0, 30.0]), offset_in_base=np.array([0.1, 0.05, 0.0]),
                    start=0.1, duration=0.05)
        robot.apply_push(push)
        p0, _, _ = _momentum(robot)
        robot.advance(0.1 - dt)  # just before the start: no push yet
        p1, _, _ = _momentum(robot)
        np.testing.assert_allclose(p1 - p0, mass * gravity * (0.1 - dt), atol=1e-6)
        robot.advance(dt)
        assert not robot.sim_truth().external_force_in_world.any()
        p2, h2, _ = _momentum(robot)
        robot.advance(dt)
        truth = robot.sim_truth()
        np.testing.assert_allclose(truth.external_force_in_world, push.force_in_world)
        # the force acts at the requested point of the trunk
        point = truth.base_position_in_world + robot.base_rotation() @ push.offset_in_base
        np.testing.assert_allclose(truth.external_point_in_world, point, atol=2e-3)
        robot.advance(push.duration)
        p3, _, _ = _momentum(robot)
        # Semi-implicit Euler conserves momentum only to O(dt) while the body turns (~1e-3 N s here); one physics
        # step of push too many or too few would be off by |F| dt = 0.27 N s.
        np.testing.assert_allclose(p3 - p2, push.impulse + mass * gravity * (push.duration + dt), atol=0.02)
        assert not robot.sim_truth().external_force_in_world.any()
        # an offset push also turns the robot: angular momentum about the CoM changes by the push's moment
        _, h3, com = _momentum(robot)
        assert np.linalg.norm(h3 - h2) > 0.1


def test_every_scheduled_push_acts():
    """More pushes than the push table first allocates (8): each delivers its impulse, none is dropped."""
    with MujocoRobot(MujocoRobotConfig(arm_mode="none")) as robot:
        qpos = robot.data.qpos.copy()
        qpos[2] = 5.0  # far above the ground: no contact
        robot.reset(qpos=qpos)
        robot.write(stand_command(robot.desc))
        mass, gravity = robot.model.body_subtreemass[1], robot.model.opt.gravity
        pushes = [Push(force_in_world=np.array([50.0, 10.0 * k, 0.0]), offset_in_base=np.zeros(3), start=0.02 * k,
                       duration=0.01) for k in range(1, 13)]
        for push in pushes:
            robot.apply_push(push)
        p0, _, _ = _momentum(robot)
        robot.advance(0.3)
        p1, _, _ = _momentum(robot)
        impulse = sum(push.impulse for push in pushes)
        np.testing.assert_allclose(p1 - p0, impulse + mass * gravity * 0.3, atol=0.02)


def _trajectory(seed, noise):
    cfg = MujocoRobotConfig(terrain=TerrainConfig(kind="fractal"), noise=noise)
    with MujocoRobot(cfg) as robot:
        robot.reset(seed=seed, domain=DomainParams(payload_mass=0.5, friction=0.8, motor_strength=0.9))
        robot.apply_push(Push.horizontal(150.0, 1.0, (0.05, 0.0, 0.0), start=0.2, duration=0.1))
        cmd = stand_command(robot.desc)
        states, reads = [], []
        for _ in range(100):
            robot.write(cmd)
            robot.advance(0.01)
            states.append(np.concatenate([robot.data.qpos, robot.data.qvel]))
            reads.append(robot.read().q)
        return np.array(states), np.array(reads)


def test_same_seed_gives_a_bit_identical_trajectory():
    noise = SensorNoise(q=0.01, gyro=0.05)
    a, ra = _trajectory(4, noise)
    b, rb = _trajectory(4, noise)
    assert np.array_equal(a, b) and np.array_equal(ra, rb)
    c, _ = _trajectory(5, noise)
    assert not np.array_equal(a, c)


def test_fractal_terrain_is_seeded_and_bounded():
    from wbc.scenario.terrain import fractal_heights

    cfg = TerrainConfig(kind="fractal", half_extent=2.0)
    a, b, c = fractal_heights(cfg, 1), fractal_heights(cfg, 1), fractal_heights(cfg, 2)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.min() == 0.0 and a.max() == 1.0 and a.shape == (cfg.samples, cfg.samples)


def test_domain_randomisation_hooks():
    with MujocoRobot(MujocoRobotConfig(arm_mode="none")) as robot:
        m = robot.model
        mass0, range0 = m.body_subtreemass[1], m.actuator_forcerange.copy()
        robot.reset(domain=DomainParams(payload_mass=2.0, friction=0.4, motor_strength=0.5))
        assert m.body_subtreemass[1] == pytest.approx(mass0 + 2.0)
        np.testing.assert_allclose(m.actuator_forcerange, 0.5 * range0)
        assert np.all(m.geom_friction[:, 0] == 0.4)
        assert np.all(m.pair_friction[:, 0:2] == 0.4)  # the ground contact pairs decide
        robot.reset()
        assert np.all(m.pair_friction[:, 0:2] == 1.0)
        assert m.body_subtreemass[1] == pytest.approx(mass0)
        np.testing.assert_allclose(m.actuator_forcerange, range0)


def test_sensor_noise_is_added_only_when_asked():
    with MujocoRobot(MujocoRobotConfig(arm_mode="none", noise=SensorNoise(q=0.01))) as robot:
        assert not np.array_equal(robot.read().q, robot.data.qpos[7:])
    with MujocoRobot(MujocoRobotConfig(arm_mode="none")) as robot:
        assert np.array_equal(robot.read().q, robot.data.qpos[7:])


def test_bad_configuration_names_the_field():
    with pytest.raises(UnknownNameError, match="a1-wx200, go1-arm"):
        MujocoRobot(MujocoRobotConfig(robot="spot"))
    with pytest.raises(UnknownNameError, match="actuated, locked, none"):
        MujocoRobot(MujocoRobotConfig(arm_mode="floppy"))
    with pytest.raises(UnknownNameError, match="fractal"):
        TerrainConfig(kind="stairs")
    with pytest.raises(ConfigError, match="timestep"):
        MujocoRobotConfig(timestep=0.5)
    with pytest.raises(ConfigError, match="friction"):
        DomainParams(friction=-1.0)
    with pytest.raises(ConfigError, match="Push.duration"):
        Push(force_in_world=np.zeros(3), offset_in_base=np.zeros(3), start=0.0, duration=0.0)


def test_explicit_ground_pairs_simulate_exactly_as_contact_filtering():
    """The scene's explicit robot-ground contact pairs (which let MuJoCo skip its broad phase) change nothing."""
    from wbc.hardware.mujoco.scene import TERRAIN_GEOM, scene_spec

    with MujocoRobot(MujocoRobotConfig(arm_mode="actuated")) as robot:
        robot.reset(seed=2)
        robot.write(stand_command(robot.desc))
        m, d = robot.model, robot.data
        assert m.npair == 25 and not m.geom_contype.any() and not m.geom_conaffinity.any()
        # the twin: the same scene with MuJoCo's default filtering (robot geoms contype 1, ground conaffinity 1)
        spec = scene_spec(robot.desc, robot.config.terrain, timestep=robot.config.timestep)
        colliders = {pair.geomname2 for pair in spec.pairs}
        for pair in list(spec.pairs):
            spec.delete(pair)
        for geom in spec.geoms:
            if geom.name == TERRAIN_GEOM:
                geom.conaffinity = 1
            elif geom.name in colliders:
                geom.contype = 1
        twin = spec.compile()
        twin.actuator_biasprm[:] = m.actuator_biasprm
        tdata = mujoco.MjData(twin)
        which = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.empty(mujoco.mj_stateSize(m, which))
        mujoco.mj_getState(m, d, state, which)
        mujoco.mj_setState(twin, tdata, state, which)
        tdata.ctrl[:] = d.ctrl
        # a shove hard enough to knock the robot over, so trunk, thighs and arm meet the ground too
        touched = set()
        for k in range(1200):
            push = 400.0 if 100 <= k < 160 else 0.0
            d.xfrc_applied[1, 1] = tdata.xfrc_applied[1, 1] = push
            mujoco.mj_step(m, d)
            mujoco.mj_step(twin, tdata)
            assert np.array_equal(d.qpos, tdata.qpos), f"step {k}"
            touched |= {int(g) for g in d.contact.geom[: d.ncon, 1]}
        assert len(touched) > 4  # not only the feet
