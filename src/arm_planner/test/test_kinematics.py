import mujoco
import numpy as np
from gantry import gantry_model

from arm_planner.kinematics import BodyKinematics
from arm_planner.twin import Twin


def _check_against_mujoco(model, body, point, rng, trials=5):
    kin = BodyKinematics(model, body, point)
    data = mujoco.MjData(model)
    qpos = []
    for _ in range(trials):
        q = model.qpos0.copy()
        for j in range(model.njnt):
            if model.jnt_type[j] in (mujoco.mjtJoint.mjJNT_HINGE, mujoco.mjtJoint.mjJNT_SLIDE):
                lo, hi = model.jnt_range[j] if model.jnt_limited[j] else (-1.0, 1.0)
                q[model.jnt_qposadr[j]] = rng.uniform(lo, hi)
        qpos.append(q)
    pos, rot = kin(np.array(qpos))
    body_id = model.body(body).id
    for q, p, r in zip(qpos, pos, rot, strict=True):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        expected_rot = data.xmat[body_id].reshape(3, 3)
        np.testing.assert_allclose(r, expected_rot, atol=1e-9)
        np.testing.assert_allclose(p, data.xpos[body_id] + expected_rot @ point, atol=1e-9)


def test_batched_fk_matches_mujoco_on_slide_and_hinge_chain():
    _check_against_mujoco(gantry_model(), "hand", np.array([0.0, 0.0, 0.06]), np.random.default_rng(0))


def test_batched_fk_matches_mujoco_on_the_panda_twin():
    twin = Twin([], 0.0, timestep_s=0.01)
    _check_against_mujoco(twin.model, "panda_hand", np.array([0.0, 0.0, 0.1034]), np.random.default_rng(1))


def test_fk_of_a_free_body_gives_its_pose():
    model = gantry_model()
    kin = BodyKinematics(model, "object_0")
    qpos = np.tile(model.qpos0, (2, 1))
    adr = model.jnt_qposadr[model.body("object_0").jntadr[0]]
    qpos[1, adr : adr + 7] = [0.1, 0.2, 0.3, np.cos(0.3), 0, 0, np.sin(0.3)]
    pos, rot = kin(qpos)
    np.testing.assert_allclose(pos[1], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(rot[1][:2, :2], [[np.cos(0.6), -np.sin(0.6)], [np.sin(0.6), np.cos(0.6)]], atol=1e-12)
