"""Rotation maths: all six Euler orders, conversions, and numpy/torch agreement."""

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from keyfill import rotations as R

ORDERS = R.EULER_ORDERS


def _axis_matrix(axis: str, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return {
        "X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


def random_quats(rng, n):
    return R.quat_normalize(rng.normal(size=(n, 4)))


@pytest.mark.parametrize("order", ORDERS)
def test_euler_is_intrinsic_in_channel_order(order):
    """Angles (a, b, c) in order "ZXY" mean Rz(a) @ Rx(b) @ Ry(c): the BVH convention."""
    rng = np.random.default_rng(0)
    for a, b, c in rng.uniform(-3, 3, size=(20, 3)):
        expected = _axis_matrix(order[0], a) @ _axis_matrix(order[1], b) @ _axis_matrix(order[2], c)
        got = R.euler_to_matrix(np.array([a, b, c]), order)
        np.testing.assert_allclose(got, expected, atol=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_euler_round_trip_all_orders(order):
    rng = np.random.default_rng(1)
    q = random_quats(rng, 2000)
    e = R.quat_to_euler(q, order)
    np.testing.assert_array_equal(e, R.matrix_to_euler(R.quat_to_matrix(q), order))  # only fewer entries computed
    assert np.all(np.abs(e[:, 1]) <= np.pi / 2 + 1e-12)
    back = R.euler_to_quat(e, order)
    assert R.quat_angle(q, back).max() < 1e-12


@pytest.mark.parametrize("order", ORDERS)
def test_euler_at_gimbal_lock(order):
    angles = np.array([[0.3, np.pi / 2, -0.2], [1.0, -np.pi / 2, 0.4], [0.0, np.pi / 2 - 1e-10, 2.0]])
    q = R.euler_to_quat(angles, order)
    back = R.euler_to_quat(R.quat_to_euler(q, order), order)
    assert R.quat_angle(q, back).max() < 1e-7


def test_quaternion_matrix_round_trip_including_half_turns():
    rng = np.random.default_rng(2)
    q = random_quats(rng, 1000)
    half_turns = np.concatenate([np.zeros((3, 1)), np.eye(3)], axis=1)  # 180 degrees about x, y, z
    q = np.concatenate([q, half_turns])
    back = R.quat_from_matrix(R.quat_to_matrix(q))
    assert R.quat_angle(q, back).max() < 1e-12
    assert np.all(back[:, 0] >= 0)


def test_hamilton_product_composes_like_matrices():
    rng = np.random.default_rng(3)
    a, b = random_quats(rng, 100), random_quats(rng, 100)
    np.testing.assert_allclose(
        R.quat_to_matrix(R.quat_mul(a, b)), R.quat_to_matrix(a) @ R.quat_to_matrix(b), atol=1e-12
    )
    v = rng.normal(size=(100, 3))
    np.testing.assert_allclose(R.quat_rotate(a, v), np.einsum("nij,nj->ni", R.quat_to_matrix(a), v), atol=1e-12)


def test_rotvec_round_trip_and_small_angles():
    rng = np.random.default_rng(4)
    r = rng.normal(size=(500, 3))
    r = r / np.linalg.norm(r, axis=1, keepdims=True) * rng.uniform(0, np.pi - 1e-6, size=(500, 1))
    np.testing.assert_allclose(R.quat_to_rotvec(R.quat_from_rotvec(r)), r, atol=1e-10)
    tiny = np.array([[1e-12, -2e-12, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(R.quat_to_rotvec(R.quat_from_rotvec(tiny)), tiny, atol=1e-20)


def test_slerp_ends_midpoint_and_shortest_path():
    rng = np.random.default_rng(5)
    a, b = random_quats(rng, 50), random_quats(rng, 50)
    assert R.quat_angle(R.quat_slerp(a, b, np.zeros(50)), a).max() < 1e-12
    assert R.quat_angle(R.quat_slerp(a, b, np.ones(50)), b).max() < 1e-12
    mid = R.quat_slerp(a, -b, np.full(50, 0.5))  # sign of b must not matter
    np.testing.assert_allclose(R.quat_angle(a, mid), R.quat_angle(a, b) / 2, atol=1e-12)
    np.testing.assert_allclose(R.quat_angle(mid, b), R.quat_angle(a, b) / 2, atol=1e-12)


def test_slerp_matches_the_log_map_form_at_every_angle():
    """The one-pass weights agree with q0 exp(t log(q0* q1)) from tiny angles to half a turn, both signs."""
    rng = np.random.default_rng(6)
    a = random_quats(rng, 600)
    angles = np.concatenate([np.geomspace(1e-14, 1e-6, 200), rng.uniform(0, np.pi, 350), np.pi - np.geomspace(1e-9, 1e-3, 50)])
    axis = rng.normal(size=(600, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    b = R.quat_mul(a, R.quat_from_rotvec(axis * angles[:, None])) * rng.choice([-1.0, 1.0], size=(600, 1))
    t = rng.uniform(-0.2, 1.2, size=600)
    d = R.quat_mul(R.quat_conjugate(a), b)
    d = np.where(d[:, :1] < 0, -d, d)
    expected = R.quat_mul(a, R.quat_from_rotvec(R.quat_to_rotvec(d) * t[:, None]))
    got = R.quat_slerp(a, b, t)
    assert R.quat_angle(got, expected).max() < 1e-7  # near a half turn the shorter way is ill-conditioned
    small = angles < 1e-6
    assert R.quat_angle(got[small], expected[small]).max() < 1e-14
    assert np.array_equal(R.quat_slerp(a, b, np.zeros(600)), R.quat_normalize(a))  # exactly q0 at t = 0


def _nearest_representation_distance(prev, cur):
    """L1 distance from ``prev`` to the nearest Euler representation of ``cur``'s rotation."""
    alt = np.array([cur[0] + np.pi, np.pi - cur[1], cur[2] + np.pi])
    best = np.inf
    for cand in (cur, alt):
        d = (cand - prev + np.pi) % (2 * np.pi) - np.pi  # nearest whole-turn shift per angle
        best = min(best, np.abs(d).sum())
    return best


@settings(max_examples=60, deadline=None)
@given(
    order=st.sampled_from(ORDERS),
    seed=st.integers(0, 2**31 - 1),
    speed=st.floats(0.01, 0.5),
)
def test_euler_continuity_picks_the_nearest_representation(order, seed, speed):
    """Each frame's angles are the representation of its rotation nearest to the previous frame's.

    So there are no 360-degree jumps and no flips between the two Euler
    solutions, and the rotations themselves are unchanged.
    """
    rng = np.random.default_rng(seed)
    steps = R.quat_from_rotvec(rng.normal(size=(200, 3)) * speed / np.sqrt(3))
    q = np.empty((200, 4))
    q[0] = random_quats(rng, 1)[0]
    for i in range(1, 200):
        q[i] = R.quat_mul(q[i - 1], steps[i])
    e = R.euler_continuous_np(R.quat_to_euler(q, order))
    assert R.quat_angle(R.euler_to_quat(e, order), q).max() < 1e-9
    for t in range(1, len(e)):
        assert np.abs(e[t] - e[t - 1]).sum() <= _nearest_representation_distance(e[t - 1], e[t]) + 1e-9


FUNCS_1 = [
    ("quat_normalize", lambda x: R.quat_normalize(x)),
    ("quat_to_matrix", lambda x: R.quat_to_matrix(R.quat_normalize(x))),
    ("quat_to_rotvec", lambda x: R.quat_to_rotvec(R.quat_normalize(x))),
    ("quat_from_matrix", lambda x: R.quat_from_matrix(R.quat_to_matrix(R.quat_normalize(x)))),
    ("quat_conjugate", lambda x: R.quat_conjugate(x)),
]


@pytest.mark.parametrize("name,fn", FUNCS_1)
def test_numpy_and_torch_agree(name, fn):
    rng = np.random.default_rng(6)
    x = rng.normal(size=(7, 5, 4))
    out_np = fn(x)
    out_t = fn(torch.from_numpy(x))
    assert isinstance(out_t, torch.Tensor)
    np.testing.assert_allclose(out_t.numpy(), out_np, atol=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_numpy_and_torch_agree_on_euler_and_products(order):
    rng = np.random.default_rng(7)
    e = rng.uniform(-3, 3, size=(6, 3, 3))
    q_np = R.euler_to_quat(e, order)
    q_t = R.euler_to_quat(torch.from_numpy(e), order)
    np.testing.assert_allclose(q_t.numpy(), q_np, atol=1e-12)
    np.testing.assert_allclose(R.quat_to_euler(q_t, order).numpy(), R.quat_to_euler(q_np, order), atol=1e-10)
    b = random_quats(rng, 18).reshape(6, 3, 4)
    np.testing.assert_allclose(R.quat_mul(q_t, torch.from_numpy(b)).numpy(), R.quat_mul(q_np, b), atol=1e-12)
    v = rng.normal(size=(6, 3, 3))
    np.testing.assert_allclose(R.quat_rotate(q_t, torch.from_numpy(v)).numpy(), R.quat_rotate(q_np, v), atol=1e-12)
    r = rng.normal(size=(6, 3, 3))
    np.testing.assert_allclose(R.quat_from_rotvec(torch.from_numpy(r)).numpy(), R.quat_from_rotvec(r), atol=1e-12)


def test_torch_path_is_differentiable_and_finite_at_identity():
    r = torch.zeros(4, 3, dtype=torch.float64, requires_grad=True)
    q = R.quat_from_rotvec(r)
    loss = (R.quat_to_rotvec(q) ** 2).sum() + q[..., 0].sum()
    loss.backward()
    assert torch.isfinite(r.grad).all()
    e = torch.tensor([[0.1, 0.2, 0.3]], dtype=torch.float64, requires_grad=True)
    R.quat_to_rotvec(R.euler_to_quat(e, "ZXY")).sum().backward()
    assert torch.isfinite(e.grad).all() and e.grad.abs().sum() > 0


def test_quat_continuous_between_keeps_the_anchors_and_chains_from_them():
    # a turn about Z past 180 degrees with a sign convention flipping it halfway (w >= 0), 2 tracks
    angles = np.linspace(0.0, 1.6 * np.pi, 9)
    smooth = R.quat_continuous_np(R.quat_from_rotvec(np.stack([np.zeros(9), np.zeros(9), angles], -1)))
    q = np.where(smooth[:, :1] < 0, -smooth, smooth)  # w >= 0: the track jumps sign where w crosses 0
    qq = np.stack([q, q], 1)
    qq[6, 0] = smooth[6]  # track 0's anchors on the smooth track's hemisphere
    qq[6, 1] = -smooth[6]  # track 1's anchor 6 on the other: it stays there
    out = R.quat_continuous_between(qq, [0, 6])
    assert np.array_equal(out[[0, 6]], qq[[0, 6]])
    d = np.sum(out[1:] * out[:-1], -1)
    assert (d[:, 0] > 0).all() and np.allclose(out[:, 0], smooth)  # track 0: one chain through the anchors
    assert (d[:5, 1] > 0).all() and d[5, 1] < 0 and (d[6:, 1] > 0).all()  # track 1 restarts at its anchor 6
    assert np.allclose(np.abs(np.sum(out * qq, -1)), 1.0)  # the same rotations
