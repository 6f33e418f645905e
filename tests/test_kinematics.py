"""Forward kinematics: hand-checked chains, batch shapes, numpy/torch agreement."""

import numpy as np
import torch

from keyfill import rotations as R
from keyfill.kinematics import fk


def test_two_link_chain_by_hand():
    parents = [-1, 0, 1]
    pos = np.array([[1.0, 2.0, 3.0], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
    rot = R.quat_identity((3,))
    rot[0] = R.quat_from_rotvec(np.array([0, 0, np.pi / 2]))  # root turns 90 degrees about z
    rot[1] = R.quat_from_rotvec(np.array([0, 0, np.pi / 2]))  # then another 90
    wr, wp = fk(rot, pos, parents)
    np.testing.assert_allclose(wp[0], [1, 2, 3], atol=1e-12)
    np.testing.assert_allclose(wp[1], [0, 2, 3], atol=1e-12)  # (0,1,0) turned 90 deg -> (-1,0,0)
    np.testing.assert_allclose(wp[2], [0, 1, 3], atol=1e-12)  # (0,1,0) turned 180 deg -> (0,-1,0)
    assert R.quat_angle(wr[2], R.quat_from_rotvec(np.array([0, 0, np.pi]))) < 1e-12


def test_batch_shapes_and_multiple_roots():
    rng = np.random.default_rng(0)
    parents = np.array([-1, 0, 0, -1, 3])
    rot = R.quat_normalize(rng.normal(size=(2, 7, 5, 4)))
    pos = rng.normal(size=(2, 7, 5, 3))
    wr, wp = fk(rot, pos, parents)
    assert wr.shape == (2, 7, 5, 4) and wp.shape == (2, 7, 5, 3)
    single = fk(rot[1, 3], pos[1, 3], parents)[1]
    np.testing.assert_allclose(wp[1, 3], single, atol=1e-12)
    np.testing.assert_allclose(wp[..., 3, :], pos[..., 3, :])  # second root is at its own translation
    # constant offsets broadcast against the rotations; float32 in, float32 out
    wr32, wp32 = fk(rot.astype(np.float32), np.broadcast_to(pos[0, 0].astype(np.float32), (2, 7, 5, 3)), parents)
    assert wr32.dtype == wp32.dtype == np.float32 and wp32.shape == (2, 7, 5, 3)


def test_numpy_and_torch_fk_agree_and_backpropagate():
    rng = np.random.default_rng(1)
    parents = np.array([-1, 0, 1, 2, 1, 4])
    rot = R.quat_normalize(rng.normal(size=(10, 6, 4)))
    pos = rng.normal(size=(10, 6, 3))
    wr, wp = fk(rot, pos, parents)
    rot_t = torch.from_numpy(rot).requires_grad_()
    wr_t, wp_t = fk(rot_t, torch.from_numpy(pos), parents)
    # numpy goes depth by depth, torch joint by joint: the same products, so the same bits
    np.testing.assert_array_equal(wr_t.detach().numpy(), wr)
    np.testing.assert_array_equal(wp_t.detach().numpy(), wp)
    wp_t.sum().backward()
    assert torch.isfinite(rot_t.grad).all() and rot_t.grad.abs().sum() > 0
