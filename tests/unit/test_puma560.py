"""PUMA 560 kinematics, inertias and URDF (sim/catching/puma560.py)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pybullet
import pytest
from pybullet_utils import bullet_client

from services.catching.robot import puma560 as K
from sim.catching import puma560 as P


def _random_q(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform(K.Q_MIN, K.Q_MAX, size=(n, 6))


@pytest.fixture
def pb(tmp_path):
    client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
    path = P.write_urdf(tmp_path / "puma560.urdf")
    body, joints, links = P.load(client, path)
    yield client, body, joints, links
    client.disconnect()


def test_the_dh_table_is_the_published_puma_560_table():
    assert DH_matches(K.DH_A, [0, 0.4318, 0.0203, 0, 0, 0])
    assert DH_matches(K.DH_D, [0, 0, 0.15005, 0.4318, 0, 0])
    assert DH_matches(K.DH_ALPHA, [math.pi / 2, 0, -math.pi / 2, math.pi / 2, -math.pi / 2, 0])
    assert DH_matches(np.degrees(K.Q_MIN), [-160, -45, -225, -110, -100, -266])
    assert DH_matches(np.degrees(K.Q_MAX), [160, 225, 45, 170, 100, 266])


def DH_matches(a, b) -> bool:
    return bool(np.allclose(a, b, atol=1e-12))


def test_fk_at_zero_puts_the_flange_at_the_known_ready_position():
    # Corke's toolbox gives p560.fkine(qz) translation (0.4521, -0.1500, 0.4318).
    t = K.fk(np.zeros(6))
    assert np.allclose(t[:3, 3], [0.4521, -0.15005, 0.4318], atol=1e-9)
    assert np.allclose(t[:3, :3], np.eye(3), atol=1e-12)


def test_fk_is_the_product_of_the_dh_rows():
    rng = np.random.default_rng(0)
    for q in _random_q(rng, 20):
        t = np.eye(4)
        for i in range(6):
            ct, st = math.cos(q[i]), math.sin(q[i])
            rz = np.array([[ct, -st, 0, 0], [st, ct, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
            tz = np.eye(4)
            tz[2, 3] = K.DH_D[i]
            tx = np.eye(4)
            tx[0, 3] = K.DH_A[i]
            ca, sa = math.cos(K.DH_ALPHA[i]), math.sin(K.DH_ALPHA[i])
            rx = np.array([[1, 0, 0, 0], [0, ca, -sa, 0], [0, sa, ca, 0], [0, 0, 0, 1.0]])
            t = t @ rz @ tz @ tx @ rx
        assert np.allclose(K.fk(q), t, atol=1e-12)


def test_fk_agrees_with_pybullet_link_frames_of_the_urdf(pb):
    client, body, joints, links = pb
    rng = np.random.default_rng(1)
    for q in _random_q(rng, 10):
        for j, qi in zip(joints, q):
            client.resetJointState(body, j, qi)
        frames = K.fk_all(q)
        for n in range(1, 7):
            state = client.getLinkState(body, links[f"link{n}"], computeForwardKinematics=True)
            rot = np.asarray(client.getMatrixFromQuaternion(state[5])).reshape(3, 3)
            assert np.allclose(state[4], frames[n][:3, 3], atol=1e-6)
            assert np.allclose(rot, frames[n][:3, :3], atol=1e-6)
        cup = client.getLinkState(body, links["cup"], computeForwardKinematics=True)
        assert np.allclose(cup[4], frames[6][:3, 3] + K.CUP_MOUNT * frames[6][:3, 2], atol=1e-6)


def test_ik_of_fk_returns_q_over_random_configurations_within_limits():
    rng = np.random.default_rng(2)
    checked = 0
    for q in _random_q(rng, 300):
        q_near = q + rng.normal(0.0, 0.05, 6)
        sol = K.ik(K.fk(q), q_near)
        assert np.allclose(K.fk(sol), K.fk(q), atol=1e-9)
        # Near the elbow or wrist singularities the angles are ill-conditioned; compare them elsewhere.
        if abs(np.linalg.det(K.jacobian(q))) > 1e-3:
            assert np.allclose(sol, q, atol=1e-7), (q, sol)
            checked += 1
    assert checked > 250


def test_ik_gives_up_to_eight_solutions_that_all_reach_the_pose():
    q = np.radians([10, 40, -150, 20, 50, 30])
    target = K.fk(q)
    sols = K.ik_all(target, q)
    assert 1 <= len(sols) <= 8
    assert np.allclose(sols[0], q, atol=1e-9)
    for s in sols:
        assert K.within_limits(s)
        assert np.allclose(K.fk(s), target, atol=1e-9)
    branches = {(round(s[0], 3), round(s[2], 3), round(s[4], 3)) for s in sols}
    assert len(branches) == len(sols)


def test_ik_picks_the_solution_nearest_to_the_current_configuration():
    q = np.radians([10, 40, -150, 20, 50, 30])
    target = K.fk(q)
    for s in K.ik_all(target, q):
        assert np.allclose(K.ik(target, s + 0.01), s, atol=1e-9)


def test_an_out_of_reach_target_raises_a_clear_error():
    target = np.eye(4)
    target[:3, 3] = (2.0, 0.0, 0.0)
    with pytest.raises(K.UnreachableError, match="not reachable"):
        K.ik(target)


def test_a_pose_reachable_only_outside_the_joint_limits_raises():
    # Reached by joint angles beyond the limits of joints 2 and 5, on every branch.
    target = K.fk([0.861, -1.446, -2.884, -3.038, 1.968, 2.593])
    assert K._raw_solutions(target, 0.0)  # geometrically reachable
    with pytest.raises(K.UnreachableError, match="joint limits"):
        K.ik(target)


def test_the_jacobian_matches_finite_differences_of_fk():
    q = np.radians([20, 30, -120, 40, 60, -30])
    jac = K.jacobian(q)
    eps = 1e-7
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = eps
        dp = (K.fk(q + dq)[:3, 3] - K.fk(q - dq)[:3, 3]) / (2 * eps)
        assert np.allclose(jac[:3, i], dp, atol=1e-6)


def test_every_link_inertia_satisfies_the_triangle_inequality():
    for moments in P.LINK_INERTIAS:
        a, b, c = moments
        assert a + b >= c and b + c >= a and a + c >= b
        assert np.all(moments > 0)
    assert np.all(P.LINK_MASSES > 0)


def test_the_published_link_3_inertia_is_fixed_by_raising_its_smallest_moment():
    published = P.PUBLISHED_INERTIAS[2]
    assert published[0] + published[2] < published[1]  # the published values violate it
    fixed = P.fix_triangle_inequality(published)
    assert fixed[0] == published[0] and fixed[1] == published[1]
    assert fixed[2] == pytest.approx(published[1] - published[0] + 0.0025)


def test_the_urdf_carries_limits_masses_cup_and_crossfire_link():
    root = ET.fromstring(P.urdf())
    joints = {j.get("name"): j for j in root.iter("joint")}
    for n in range(1, 7):
        lim = joints[f"joint{n}"].find("limit")
        assert lim is not None
        assert float(lim.get("lower")) == pytest.approx(K.Q_MIN[n - 1], abs=1e-5)
        assert float(lim.get("upper")) == pytest.approx(K.Q_MAX[n - 1], abs=1e-5)
        assert float(lim.get("velocity")) == pytest.approx(K.QD_MAX[n - 1])
    links = {lk.get("name"): lk for lk in root.iter("link")}
    assert P.CROSSFIRE_LINK in links and "cup" in links
    restitution = links["cup"].find("contact/restitution")
    assert restitution is not None and float(restitution.get("value")) == pytest.approx(0.05)
    assert "cup" not in {lk.get("name") for lk in ET.fromstring(P.urdf(cup=False)).iter("link")}


def test_a_ball_on_the_beam_blocks_it_and_a_ball_beside_it_does_not():
    pose = np.eye(4)
    a, b = P.crossfire_beam(pose)
    assert np.allclose(b - a, [2 * K.CUP_INNER_RADIUS, 0, 0])
    assert P.beam_blocked((0.01, 0.0, 0.015), 0.02, a, b)
    assert not P.beam_blocked((0.0, 0.0, 0.025), 0.02, a, b)


def test_a_ball_dropped_into_the_held_cup_comes_to_rest_across_the_beam(pb):
    client, body, joints, links = pb
    client.setGravity(0, 0, -9.81)
    client.setPhysicsEngineParameter(fixedTimeStep=0.001)
    for j, qi in zip(joints, K.Q_HOME):
        client.resetJointState(body, j, qi)
        client.setJointMotorControl2(body, j, client.POSITION_CONTROL, targetPosition=qi, force=500)
    rim = K.fk(K.Q_HOME)
    axis = rim[:3, 2]
    centre = rim[:3, 3] + (K.CUP_RIM_OFFSET + 0.03) * axis
    radius, mass = 0.02, 0.0027
    col = client.createCollisionShape(client.GEOM_SPHERE, radius=radius)
    ball = client.createMultiBody(mass, col, -1, list(centre))
    client.changeDynamics(ball, -1, localInertiaDiagonal=[2 / 3 * mass * radius**2] * 3, restitution=0.6)
    for _ in range(1500):
        client.stepSimulation()
    pos = np.asarray(client.getBasePositionAndOrientation(ball)[0])
    state = client.getLinkState(body, links[P.CROSSFIRE_LINK], computeForwardKinematics=True)
    pose = np.eye(4)
    pose[:3, :3] = np.asarray(client.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    pose[:3, 3] = state[4]
    assert P.beam_blocked(pos, radius, *P.crossfire_beam(pose))
