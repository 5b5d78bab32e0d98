"""VLR kinematics (Eq. 1-3): hand-computed cases, generic N and K."""

import math

import numpy as np
import pytest

from vlr.kinematics import (
    Chain,
    HandModel,
    angles_from_normals,
    contact_points,
    joint_positions,
    normals_from_angles,
    plane_rotation,
    pom_from_contacts,
    virtual_links,
)
from vlr.spec import load_hand


@pytest.fixture(scope="module")
def modelo() -> HandModel:
    return HandModel.from_spec(load_hand("modelo"))


def _chain(k: int, lengths=None) -> Chain:
    return Chain(lengths=tuple(lengths or [0.05] * (k - 1)), pad_center=(0.0, 0.003, 0.03),
                 pad_radius=0.01, pulley_radii=(0.008,) * k, stiffness=(0.04,) * k,
                 rest_angles=(-0.7,) * k, limits=((-0.3, 1.7),) * k, link_masses=(0.015,) * k,
                 link_coms=((0.0, 0.0, 0.02),) * k)


def test_plane_rotation_flexes_towards_plus_y():
    r = plane_rotation(np.array(0.3))
    z = r @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(z, [0.0, math.sin(0.3), math.cos(0.3)])


def test_straight_finger_hand_computed(modelo):
    theta = np.zeros((3, 2))
    normals = np.tile([0.0, 1.0, 0.0], (3, 1))
    c = contact_points(modelo, theta, normals)
    # thumb: base (0, -0.034, 0.012), y_F = +y_P; contact = base + (0, 0.003 + 0.012,
    # 0.062 + 0.032) in F.
    np.testing.assert_allclose(c[0], [0.0, -0.034 + 0.015, 0.012 + 0.094], atol=1e-8)
    # left: base (-0.027, 0.034, 0.012), y_F = -y_P.
    np.testing.assert_allclose(c[1], [-0.027, 0.034 - 0.015, 0.106], atol=1e-8)


def test_flexed_thumb_hand_computed(modelo):
    tp, td = 0.4, 0.5
    theta = np.array([[tp, td], [0, 0], [0, 0]])
    q = joint_positions(modelo, theta)
    np.testing.assert_allclose(q[0, 1], [0.0, -0.034 + 0.062 * math.sin(tp),
                                         0.012 + 0.062 * math.cos(tp)], atol=1e-8)
    n = np.tile([0.0, 0.0, 1.0], (3, 1))  # pad top: contact at (0, 0.003, 0.044) in D
    c = contact_points(modelo, theta, n)
    phi = tp + td
    y = q[0, 1, 1] + 0.003 * math.cos(phi) + 0.044 * math.sin(phi)
    z = q[0, 1, 2] - 0.003 * math.sin(phi) + 0.044 * math.cos(phi)
    np.testing.assert_allclose(c[0], [0.0, y, z], atol=1e-8)


def test_batched_shapes(modelo):
    theta = np.zeros((7, 3, 2))
    normals = np.tile([0.0, 1.0, 0.0], (7, 3, 1))
    assert contact_points(modelo, theta, normals).shape == (7, 3, 3)
    assert joint_positions(modelo, theta).shape == (7, 3, 2, 3)


def test_three_joint_chain_and_two_fingers():
    model = HandModel.from_chains(("a", "b"), (_chain(3), _chain(3)),
                                  positions=[[0, -0.03, 0], [0, 0.03, 0]],
                                  yaws=[math.pi / 2, -math.pi / 2], tendon_stiffness=2e4)
    assert model.n_joints == 3 and model.n_fingers == 2
    theta = np.array([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]])
    q = joint_positions(model, theta)
    # finger a: joints at 0.05 steps along cumulative angles 0.1, 0.3
    y = 0.05 * math.sin(0.1) + 0.05 * math.sin(0.3)
    z = 0.05 * math.cos(0.1) + 0.05 * math.cos(0.3)
    np.testing.assert_allclose(q[0, 2], [0.0, -0.03 + y, z], atol=1e-8)
    n = np.tile([0.0, 1.0, 0.0], (2, 1))
    c = contact_points(model, theta, n)
    np.testing.assert_allclose(c[1], [0.0, 0.03 - 0.013, 0.13], atol=1e-8)
    assert model.joint_index("middle") == 1


def test_normals_round_trip():
    a, b = np.array([0.3, -0.2]), np.array([0.1, 0.05])
    a2, b2 = angles_from_normals(normals_from_angles(a, b))
    np.testing.assert_allclose(a2, a)
    np.testing.assert_allclose(b2, b)


def test_pom_from_contacts_recovers_pose():
    rng = np.random.default_rng(0)
    anchors = rng.normal(0, 0.03, (4, 3))
    w = np.array([0.1, -0.2, 0.3])
    from vlr.motion import rotvec_to_matrix

    rot = rotvec_to_matrix(w)
    pos = np.array([0.01, 0.02, 0.08])
    pos2, rot2 = pom_from_contacts(pos + anchors @ rot.T, anchors)
    np.testing.assert_allclose(pos2, pos, atol=1e-8)
    np.testing.assert_allclose(rot2, rot, atol=1e-8)


def test_virtual_link_of_straight_distal(modelo):
    n = np.tile([0.0, 1.0, 0.0], (3, 1))
    length, angle = virtual_links(modelo, np.zeros((3, 2)), n)
    np.testing.assert_allclose(length, math.hypot(0.015, 0.032))
    np.testing.assert_allclose(angle, math.atan2(0.015, 0.032))
