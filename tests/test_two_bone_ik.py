"""Analytic two-bone IK: random chains, reachable and unreachable targets, exact bone lengths, the knee plane."""

import numpy as np

from keyfill import rotations as R
from keyfill.kinematics import fk, two_bone_ik


def _chains(rng, n):
    a = rng.normal(size=(n, 3))
    b = a + rng.normal(size=(n, 3))
    c = b + rng.normal(size=(n, 3))
    return a, b, c


def _apply(a, b, c, qa, qb):
    b2 = a + R.quat_rotate(qa, b - a)
    return b2, b2 + R.quat_rotate(R.quat_mul(qb, qa), c - b)


def test_reachable_targets_are_met_with_exact_bones_and_the_knee_in_the_pole_plane():
    rng = np.random.default_rng(0)
    a, b, c = _chains(rng, 4000)
    l1, l2 = np.linalg.norm(b - a, axis=-1), np.linalg.norm(c - b, axis=-1)
    # targets at a random fraction of the reachable range
    lo, hi = np.abs(l1 - l2), l1 + l2
    dirs = R.quat_rotate(R.quat_normalize(rng.normal(size=(4000, 4))), np.array([1.0, 0, 0]))
    t = a + dirs * (lo + (hi - lo) * rng.uniform(0.001, 0.999, 4000))[:, None]
    pole = rng.normal(size=(4000, 3))
    qa, qb = two_bone_ik(a, b, c, t, pole)
    assert qa.shape == qb.shape == (4000, 4)
    np.testing.assert_allclose(np.linalg.norm(qa, axis=-1), 1, atol=1e-12)
    b2, c2 = _apply(a, b, c, qa, qb)
    np.testing.assert_allclose(np.linalg.norm(b2 - a, axis=-1), l1, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(c2 - b2, axis=-1), l2, rtol=0, atol=1e-9)
    np.testing.assert_allclose(c2, t, atol=1e-9)
    normal = np.cross(t - a, pole)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    assert np.abs(np.sum((b2 - a) * normal, axis=-1)).max() < 1e-9  # knee in the plane of a, target, pole
    u = (t - a) / np.linalg.norm(t - a, axis=-1, keepdims=True)
    side = pole - u * np.sum(pole * u, axis=-1, keepdims=True)
    assert np.all(np.sum((b2 - a) * side, axis=-1) >= -1e-9)  # ... and on the pole's side of the line


def test_unreachable_targets_get_a_straight_leg_pointing_at_them():
    rng = np.random.default_rng(1)
    a, b, c = _chains(rng, 1000)
    l1, l2 = np.linalg.norm(b - a, axis=-1), np.linalg.norm(c - b, axis=-1)
    dirs = rng.normal(size=(1000, 3))
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    t = a + dirs * ((l1 + l2) * rng.uniform(1.01, 3.0, 1000))[:, None]
    qa, qb = two_bone_ik(a, b, c, t)
    b2, c2 = _apply(a, b, c, qa, qb)
    np.testing.assert_allclose(np.linalg.norm(b2 - a, axis=-1), l1, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(c2 - b2, axis=-1), l2, atol=1e-9)
    # fully extended, less a tiny slack, straight at the target
    np.testing.assert_allclose(np.linalg.norm(c2 - a, axis=-1), l1 + l2, rtol=1e-8)
    np.testing.assert_allclose((c2 - a) / np.linalg.norm(c2 - a, axis=-1, keepdims=True), dirs, atol=1e-9)


def test_the_current_pose_is_a_fixed_point_and_the_default_pole_keeps_the_knee_side():
    rng = np.random.default_rng(2)
    a, b, c = _chains(rng, 500)
    qa, qb = two_bone_ik(a, b, c, c)  # default pole: the current knee
    ident = np.array([1.0, 0, 0, 0])
    assert R.quat_angle(qa, ident).max() < 1e-9 and R.quat_angle(qb, ident).max() < 1e-9
    # a target a little off: the knee stays on its side of the hip-target line, in the plane with the old knee
    t = c + 0.05 * rng.normal(size=c.shape)
    b2, _ = _apply(a, b, c, *two_bone_ik(a, b, c, t))
    u = (c - a) / np.linalg.norm(c - a, axis=-1, keepdims=True)
    old_side = (b - a) - u * np.sum((b - a) * u, axis=-1, keepdims=True)
    u2 = (t - a) / np.linalg.norm(t - a, axis=-1, keepdims=True)
    new_side = (b2 - a) - u2 * np.sum((b2 - a) * u2, axis=-1, keepdims=True)
    reach = np.linalg.norm(t - a, axis=-1) < np.linalg.norm(b - a, axis=-1) + np.linalg.norm(c - b, axis=-1)
    assert np.all(np.sum(old_side * new_side, axis=-1)[reach] > 0)


def test_the_knee_turns_about_its_own_hinge_and_batches_broadcast():
    """The lower bone's turn is about the bending plane's normal, which the upper bone carries unchanged, so a
    knee that bends about its local hinge axis still does; leading batch shapes broadcast."""
    rng = np.random.default_rng(3)
    a, b, c = (x.reshape(4, 5, 3) for x in _chains(rng, 20))
    t = c + 0.1 * rng.normal(size=(4, 5, 3))
    qa, qb = two_bone_ik(a, b, c, t, pole=np.array([0.0, 0.0, 1.0]))
    assert qa.shape == (4, 5, 4)
    n_old = np.cross(b - a, c - b)
    n_old /= np.linalg.norm(n_old, axis=-1, keepdims=True)
    b2, c2 = _apply(a, b, c, qa, qb)
    n_new = np.cross(b2 - a, c2 - b2)
    n_new /= np.linalg.norm(n_new, axis=-1, keepdims=True)
    np.testing.assert_allclose(R.quat_rotate(qa, n_old), n_new, atol=1e-9)  # the hinge axis rides on the thigh
    rv = R.quat_to_rotvec(qb)
    assert np.abs(np.cross(rv, n_new)).max() < 1e-9  # qb: about the hinge alone


def test_a_straight_leg_bends_towards_the_pole():
    a = np.zeros(3)
    b = np.array([0.0, -1.0, 0.0])
    c = np.array([0.0, -2.0, 0.0])
    t = np.array([0.0, -1.5, 0.0])
    qa, qb = two_bone_ik(a, b, c, t, pole=np.array([0.0, 0.0, 1.0]))
    b2, c2 = _apply(a, b, c, qa, qb)
    np.testing.assert_allclose(c2, t, atol=1e-12)
    np.testing.assert_allclose(b2, [0.0, -0.75, np.sqrt(1 - 0.75**2)], atol=1e-12)


def test_deltas_applied_to_a_skeleton_through_fk():
    """Applied as world deltas (thigh ``qa W``, shin ``qb qa W``) and turned into local rotations, FK puts the
    ankle on the target."""
    rng = np.random.default_rng(4)
    parents = np.array([-1, 0, 1, 2])  # hips, thigh, shin, foot
    offsets = np.array([[0.0, 1.0, 0.0], [0.1, -0.1, 0.0], [0.0, -0.45, 0.02], [0.0, -0.42, 0.0]])
    local = R.quat_normalize(rng.normal(size=(8, 4, 4)) * [1, 0.2, 0.2, 0.2] + [3, 0, 0, 0])
    W, P = fk(local, offsets, parents)
    t = P[:, 1] + 0.9 * (P[:, 3] - P[:, 1]) + 0.03 * rng.normal(size=(8, 3))  # within reach
    qa, qb = two_bone_ik(P[:, 1], P[:, 2], P[:, 3], t)
    thigh = R.quat_mul(qa, W[:, 1])
    shin = R.quat_mul(R.quat_mul(qb, qa), W[:, 2])
    new = local.copy()
    new[:, 1] = R.quat_mul(R.quat_conjugate(W[:, 0]), thigh)
    new[:, 2] = R.quat_mul(R.quat_conjugate(thigh), shin)
    np.testing.assert_allclose(fk(new, offsets, parents)[1][:, 3], t, atol=1e-12)
