"""RC-FK (section 3.3): angles never leave their ranges, bone lengths are exact, the range rule."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from keyfill import rotations as R
from keyfill.learn.gan.ranges import (
    MIDDLE_LIMIT,
    JointRanges,
    angle_range,
    choose_order,
    driven_joints,
    estimate_ranges,
    inside,
    range_angles,
    snap_in_range,
)
from keyfill.learn.gan.rcfk import RCFK, binomial_lowpass, range_map, rotation_6d_to_matrix
from keyfill.motion import Skeleton

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def arm_skeleton() -> Skeleton:
    """Root, spine, neck (leaf-free chain), two arms with a hand leaf each."""
    names = ["root", "spine", "neck", "arm_l", "fore_l", "hand_l", "arm_r", "fore_r", "hand_r"]
    parents = [-1, 0, 1, 1, 3, 4, 1, 6, 7]
    offsets = [[0, 0, 0], [0, 10, 0], [0, 30, 0], [15, 25, 0], [25, 0, 0], [22, 0, 0], [-15, 25, 0], [-25, 0, 0],
               [-22, 0, 0]]
    return Skeleton(names, parents, offsets, [("Zrotation", "Xrotation", "Yrotation")] * 9)


def random_ranges(sk: Skeleton, rng) -> JointRanges:
    driven = driven_joints(sk)
    orders = tuple(rng.choice(R.EULER_ORDERS) for _ in driven)
    centre = rng.uniform(-1.5, 1.5, (len(driven), 3))
    width = rng.uniform(0, 2.0, (len(driven), 3))
    width[0, 2] = 0.0  # one fixed angle
    centre[:, 1] = np.clip(centre[:, 1], -0.4, 0.4)
    return JointRanges(driven, orders, centre - width / 2, centre + width / 2)


def test_driven_joints_are_those_that_move_a_position():
    sk = arm_skeleton()
    # hands are leaves: their rotation moves nothing; the neck has no child at all
    assert driven_joints(sk).tolist() == [1, 3, 4, 6, 7]


def test_range_map_is_eq3_as_meant():
    lo, hi = torch.tensor(-0.5), torch.tensor(1.5)
    v = torch.tensor([-1e9, -1.0, 0.0, 1.0, 1e9])
    u = range_map(v, lo, hi)
    assert u[0] == pytest.approx(-0.5) and u[-1] == pytest.approx(1.5)
    assert u[2] == pytest.approx(0.5)  # tanh 0 -> the middle of the range
    assert u[3] == pytest.approx(-0.5 + 2.0 * (np.tanh(1.0) + 1) / 2)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_outputs_never_leave_the_ranges_and_bones_keep_their_lengths(seed):
    rng = np.random.default_rng(seed)
    sk = arm_skeleton()
    ranges = random_ranges(sk, rng)
    layer = RCFK(sk.parents, sk.offsets, ranges)
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(3, layer.channels, 50, generator=g) * 10  # far into tanh's saturation too
    ang = layer.angles(v).double().numpy()
    assert np.all(ang >= ranges.lo - 1e-6) and np.all(ang <= ranges.hi + 1e-6)
    quats, pos = layer(v)
    q = quats.double().numpy()
    assert inside(ranges, q).all()
    assert np.allclose(np.linalg.norm(q, axis=-1), 1, atol=1e-5)
    p = pos.double().numpy()
    assert np.allclose(p[:, :, 0], 0)  # root-relative
    for j in range(1, sk.num_joints):
        length = np.linalg.norm(p[:, :, j] - p[:, :, sk.parents[j]], axis=-1)
        assert np.allclose(length, np.linalg.norm(sk.offsets[j]), rtol=1e-5, atol=1e-4)
    # a fixed angle stays at its value whatever the network says
    assert np.allclose(ang[..., 0, 2], ranges.lo[0, 2], atol=1e-6)


def test_rcfk_matches_numpy_fk_and_is_differentiable():
    rng = np.random.default_rng(3)
    sk = arm_skeleton()
    ranges = random_ranges(sk, rng)
    layer = RCFK(sk.parents, sk.offsets, ranges)
    v = torch.randn(2, layer.channels, 7, dtype=torch.float64, requires_grad=True)
    quats, pos = layer.double()(v)
    from keyfill.kinematics import fk

    off = np.array(sk.offsets)
    off[0] = 0
    _, ref = fk(quats.detach().numpy(), np.broadcast_to(off, quats.shape[:-1] + (3,)), sk.parents)
    assert np.allclose(pos.detach().numpy(), ref, atol=1e-9)
    pos.sum().backward()
    assert torch.isfinite(v.grad).all() and v.grad.abs().sum() > 0


def test_6d_gives_rotation_matrices():
    x = torch.randn(100, 6, dtype=torch.float64)
    m = rotation_6d_to_matrix(x)
    eye = torch.eye(3, dtype=torch.float64).expand(100, 3, 3)
    assert torch.allclose(m.transpose(-1, -2) @ m, eye, atol=1e-10)
    assert torch.allclose(torch.linalg.det(m), torch.ones(100, dtype=torch.float64), atol=1e-10)


def test_order_puts_the_narrowest_range_in_the_middle():
    rng = np.random.default_rng(0)
    n = 2000
    # wide swings about X and Z, a narrow twist about Y: Y belongs in the middle
    ang = np.stack([rng.uniform(-1.2, 1.2, n), rng.uniform(-0.1, 0.1, n), rng.uniform(-1.0, 1.0, n)], -1)
    q = R.euler_to_quat(ang, "XYZ")
    assert choose_order(q, "ZXY")[1] == "Y"


def test_range_rule_percentiles_margin_static_and_wrap():
    rng = np.random.default_rng(1)
    a = rng.uniform(-0.5, 0.5, 10_000)
    lo, hi = angle_range(a, middle=False)
    p_lo, p_hi = np.percentile(a, [0.5, 99.5])
    margin = 0.1 * (p_hi - p_lo) + np.radians(5)
    assert lo == pytest.approx(p_lo - margin, abs=2e-3) and hi == pytest.approx(p_hi + margin, abs=2e-3)
    assert angle_range(np.full(100, 0.3), middle=False) == pytest.approx((0.3, 0.3))
    # an angle around +-pi: the range is a narrow one across pi, not the whole circle
    w = np.pi + rng.uniform(-0.2, 0.2, 1000)
    w = (w + np.pi) % (2 * np.pi) - np.pi
    lo, hi = angle_range(w, middle=False)
    assert hi - lo < 1.0 and (lo < np.pi < hi or lo < -np.pi < hi)
    lo, hi = angle_range(rng.uniform(-1.5, 1.5, 1000), middle=True)
    assert lo >= -MIDDLE_LIMIT and hi <= MIDDLE_LIMIT


def test_estimated_ranges_hold_the_corpus_poses():
    rng = np.random.default_rng(2)
    sk = arm_skeleton()
    n = 3000
    q = np.zeros((n, sk.num_joints, 4))
    q[..., 0] = 1
    for j in (1, 3, 4, 6, 7):
        q[:, j] = R.euler_to_quat(rng.normal(0, [0.6, 0.2, 0.4], (n, 3)), "ZXY")
    ranges = estimate_ranges(sk, q)
    assert ranges.driven.tolist() == [1, 3, 4, 6, 7]
    assert inside(ranges, q).mean() > 0.99
    again = JointRanges.from_json(ranges.to_json())
    assert again.orders == ranges.orders and np.array_equal(again.lo, ranges.lo)


def test_binomial_lowpass_removes_period_two_and_keeps_constants():
    t = torch.arange(40, dtype=torch.float64)
    x = torch.stack([torch.full_like(t, 3.0), (-1.0) ** t, t]).reshape(1, 3, 40)
    y = binomial_lowpass(x, 4, dim=2)[0]
    assert torch.allclose(y[0], torch.full_like(t, 3.0))
    assert y[1, 2:-2].abs().max() < 1e-12  # [1, 4, 6, 4, 1] / 16 has zero gain at period 2
    assert torch.allclose(y[2, 2:-2], t[2:-2])  # symmetric weights keep a straight line
    assert binomial_lowpass(x, 0, dim=2) is x


@pytest.mark.parametrize("seed", [0, 1])
def test_smoothed_outputs_stay_in_their_ranges(seed):
    sk = arm_skeleton()
    ranges = random_ranges(sk, np.random.default_rng(seed))
    layer = RCFK(sk.parents, sk.offsets, ranges)
    v = torch.randn(2, layer.channels, 60, generator=torch.Generator().manual_seed(seed)) * 10
    q, _ = layer(v, smoothing=4)
    assert inside(ranges, q.double().numpy()).all()
    raw = layer.angles(v)
    smooth = range_angles(ranges, q.double().numpy())
    assert np.abs(np.diff(smooth, 2, axis=1)).mean() < np.abs(np.diff(raw.double().numpy(), 2, axis=1)).mean()


def test_snap_in_range_hits_keys_and_keeps_the_ranges_between_them():
    rng = np.random.default_rng(5)
    sk = arm_skeleton()
    ranges = random_ranges(sk, rng)
    layer = RCFK(sk.parents, sk.offsets, ranges)
    v = torch.randn(1, layer.channels, 61, generator=torch.Generator().manual_seed(5)) * 3
    gen = layer(v)[0][0].double().numpy()
    keys = np.array([0, 20, 60])
    key_q, _ = layer(torch.randn(1, layer.channels, 3, generator=torch.Generator().manual_seed(6)) * 3)
    key_q = key_q[0].double().numpy()
    out = snap_in_range(ranges, gen, keys, key_q)
    d = ranges.driven
    assert np.allclose(np.abs((out[keys][:, d] * key_q[:, d]).sum(-1)), 1, atol=1e-9)  # the keys' rotations
    assert inside(ranges, out).all()
    assert np.array_equal(out[:, 0], gen[:, 0])  # the root (6D, no range) is left to the shared correction
