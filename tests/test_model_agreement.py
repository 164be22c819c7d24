"""MuJoCo and Pinocchio, built from one description, describe the same rigid-body system."""

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from wbc.hardware.mujoco.scene import build_scene
from wbc.robots import ARM_MODES, ROBOTS, get_robot, joint_table
from wbc.robots.pinocchio_model import build_pinocchio
from wbc.scenario.terrain import TerrainConfig

CASES = [(name, mode) for name in ROBOTS for mode in ARM_MODES]


def _random_state(model: mujoco.MjModel, rng: np.random.Generator, lower, upper):
    qpos = np.zeros(model.nq)
    qpos[:3] = rng.normal(size=3) * [0.5, 0.5, 0.1] + [0, 0, 0.3]
    quat = rng.normal(size=4)
    qpos[3:7] = quat / np.linalg.norm(quat)
    qpos[7:] = rng.uniform(lower, upper)
    qvel = rng.normal(size=model.nv)
    return qpos, qvel


def _mujoco_centroidal(model, data):
    """Mass, CoM, centroidal inertia and centroidal momentum matrix computed from MuJoCo's own quantities."""
    mujoco.mj_forward(model, data)
    mass = model.body_subtreemass[1]
    com = data.subtree_com[1].copy()
    inertia = np.zeros((3, 3))
    for b in range(1, model.nbody):
        rot = data.ximat[b].reshape(3, 3)
        r = data.xipos[b] - com
        inertia += rot @ np.diag(model.body_inertia[b]) @ rot.T
        inertia += model.body_mass[b] * (r @ r * np.eye(3) - np.outer(r, r))
    cmm = np.zeros((6, model.nv))
    qvel0 = data.qvel.copy()
    for j in range(model.nv):
        data.qvel[:] = 0
        data.qvel[j] = 1.0
        mujoco.mj_forward(model, data)
        mujoco.mj_subtreeVel(model, data)
        cmm[:3, j] = mass * data.subtree_linvel[1]
        cmm[3:, j] = data.subtree_angmom[1]
    data.qvel[:] = qvel0
    mujoco.mj_forward(model, data)
    return mass, com, inertia, cmm


@pytest.mark.parametrize(("name", "mode"), CASES)
def test_mujoco_and_pinocchio_agree(name, mode):
    desc = get_robot(name, mode)
    model = build_scene(desc, TerrainConfig())
    data = mujoco.MjData(model)
    pr = build_pinocchio(desc)
    table = joint_table(desc)
    rng = np.random.default_rng(7)
    assert model.nv == pr.model.nv
    assert pr.model.nv == 6 + desc.num_joints
    for _ in range(5):
        qpos, qvel = _random_state(model, rng, table.lower, table.upper)
        data.qpos[:] = qpos
        data.qvel[:] = qvel
        q, v = pr.joints.q_pin(qpos), pr.joints.v_pin(qpos, qvel)
        t = pr.joints.velocity_map(qpos)
        np.testing.assert_allclose(t @ qvel, v, atol=1e-12)

        mass, com, inertia, cmm = _mujoco_centroidal(model, data)
        assert mass == pytest.approx(pin.computeTotalMass(pr.model), rel=1e-9)
        np.testing.assert_allclose(com, pin.centerOfMass(pr.model, pr.data, q), atol=1e-9)

        a_g = pin.ccrba(pr.model, pr.data, q, v).copy()
        np.testing.assert_allclose(inertia, pr.data.Ig.inertia, atol=1e-9)
        np.testing.assert_allclose(cmm, a_g @ t, atol=1e-9)
        np.testing.assert_allclose(cmm @ qvel, pr.data.hg.vector, atol=1e-9)

        m_pin = pin.crba(pr.model, pr.data, q)
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        m_mj = np.zeros((model.nv, model.nv))
        mujoco.mj_fullM(model, data, m_mj)
        np.testing.assert_allclose(m_mj, t.T @ m_pin @ t, atol=1e-9)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_arm_modes_change_mass_and_dofs_as_documented(name):
    none, locked, actuated = (get_robot(name, m) for m in ARM_MODES)
    masses = [build_scene(d, TerrainConfig()).body_mass.sum() for d in (none, locked, actuated)]
    assert masses[1] == pytest.approx(masses[2])
    assert masses[1] - masses[0] == pytest.approx(actuated.arm.mass)
    assert (none.num_joints, locked.num_joints, actuated.num_joints) == (12, 12, 15)
    # a locked arm is rigid: no joint, no actuator, and it sits at its nominal pose
    m_locked = build_scene(locked, TerrainConfig())
    assert m_locked.nu == 12 and m_locked.njnt == 13


@pytest.mark.parametrize("name", list(ROBOTS))
def test_locked_arm_sits_where_the_actuated_arm_is_at_its_nominal_pose(name):
    com = {}
    for mode in ("locked", "actuated"):
        desc = get_robot(name, mode)
        pr = build_pinocchio(desc)
        qj = desc.nominal_q[pr.joints.pin_from_house]
        q = np.r_[0.0, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0, qj]
        com[mode] = pin.centerOfMass(pr.model, pr.data, q)
    np.testing.assert_allclose(com["locked"], com["actuated"], atol=1e-12)


def test_pinocchio_visual_model_carries_the_urdf_meshes_and_the_arm():
    pr = build_pinocchio(get_robot("a1-wx200"), with_visuals=True)
    names = [g.name for g in pr.visual_model.geometryObjects]
    meshes = [g.meshPath for g in pr.visual_model.geometryObjects if g.meshPath]
    assert any(p.endswith("trunk.dae") for p in meshes)
    assert any(n.startswith("arm_forearm_link") for n in names)
