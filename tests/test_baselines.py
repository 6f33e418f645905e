"""Spline baselines and the exact-keys correction."""

import numpy as np
import pytest
from conftest import DATA

from keyfill import rotations as R
from keyfill.interpolate import at_times, cubic, inverse_right_jacobian, linear, segment_coordinates
from keyfill.io import bvh
from keyfill.learn.exact_keys import snap_to_keys
from keyfill.motion import Keys


@pytest.fixture(scope="module")
def walk():
    return bvh.read(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")


@pytest.mark.parametrize("method", [linear, cubic])
def test_keys_are_bit_identical_and_other_frames_change(walk, method):
    keys = Keys([0, 10, 33, 60, 68])
    out = method(walk, keys)
    k = keys.frames
    assert np.array_equal(out.rotations[k], walk.rotations[k])
    assert np.array_equal(out.positions[k], walk.positions[k])
    assert out.keys is keys
    assert not np.allclose(out.positions[20], walk.positions[20])


def test_linear_is_lerp_and_slerp(walk):
    keys = Keys([0, 10])
    out = linear(walk, keys)
    np.testing.assert_allclose(out.positions[5], 0.5 * (walk.positions[0] + walk.positions[10]), atol=1e-12)
    half = R.quat_angle(walk.rotations[0], walk.rotations[10]) / 2
    np.testing.assert_allclose(R.quat_angle(walk.rotations[0], out.rotations[5]), half, atol=1e-9)


def test_frames_outside_the_keys_hold(walk):
    out = cubic(walk, Keys([5, 40]))
    assert np.array_equal(out.positions[:5], np.repeat(walk.positions[5:6], 5, axis=0))
    assert np.allclose(out.positions[41:], walk.positions[40])


def test_cubic_reproduces_a_cubic_position_curve(walk):
    """Hermite with Catmull-Rom tangents is exact for quadratics on even key spacing."""
    F = 41
    t = np.arange(F, dtype=float)
    pos = np.repeat(walk.positions[:1], F, axis=0)
    pos[:, 0, 0] = 0.05 * (t - 20) ** 2
    m = walk.replace(rotations=np.repeat(walk.rotations[:1], F, axis=0), positions=pos)
    out = cubic(m, Keys([0, 10, 20, 30, 40]))
    np.testing.assert_allclose(out.positions[10:31, 0, 0], pos[10:31, 0, 0], atol=1e-9)


def _dense(walk, key_frames, scale):
    """A motion with the walk's key poses placed at ``key_frames * scale`` (fine time steps)."""
    F = key_frames[-1] * scale + 1
    rot = np.repeat(walk.rotations[:1], F, axis=0)
    pos = np.repeat(walk.positions[:1], F, axis=0)
    rot[key_frames * scale] = walk.rotations[key_frames]
    pos[key_frames * scale] = walk.positions[key_frames]
    return walk.replace(rotations=rot, positions=pos), Keys(key_frames * scale)


def test_cubic_rotation_spline_is_c1_across_uneven_keys(walk):
    """Angular velocity is continuous at keys: the jump shrinks with the time step (C1), unlike slerp."""
    key_frames = np.array([0, 7, 30, 38, 68])
    jumps = {}
    for method in (cubic, linear):
        for scale in (20, 80):
            m, keys = _dense(walk, key_frames, scale)
            q = method(m, keys).rotations
            w = R.quat_to_rotvec(R.quat_mul(R.quat_conjugate(q[:-1]), q[1:])) * scale  # per original frame
            k = keys.frames[1:-1]
            jumps[method.__name__, scale] = np.abs(w[k] - w[k - 1]).max()
    assert jumps["cubic", 80] < jumps["cubic", 20] / 3  # O(dt): continuous velocity
    assert jumps["linear", 80] > 0.5 * jumps["linear", 20]  # slerp's kinks do not shrink
    assert jumps["cubic", 80] < 0.05 * jumps["linear", 80]


def test_inverse_right_jacobian_against_finite_differences():
    rng = np.random.default_rng(0)
    for _ in range(20):
        axis = rng.normal(size=3)
        phi = axis / np.linalg.norm(axis) * rng.uniform(0.01, 3.0)  # below pi: no wrap
        omega = rng.normal(size=3)
        eps = 1e-6
        q = R.quat_from_rotvec(phi)
        q2 = R.quat_mul(q, R.quat_from_rotvec(omega * eps))  # body-frame step
        numeric = (R.quat_to_rotvec(q2) - phi) / eps
        np.testing.assert_allclose(inverse_right_jacobian(phi) @ omega, numeric, atol=1e-4)


def test_at_times_is_the_linear_baseline_between_two_frames_and_exact_at_whole_times(walk):
    ends = [0, 10]
    rot, pos = at_times(walk.rotations[ends], walk.positions[ends], np.arange(11) / 10)
    lin = linear(walk, Keys(ends))
    np.testing.assert_allclose(rot, lin.rotations[:11], atol=1e-12)
    np.testing.assert_allclose(pos, lin.positions[:11], atol=1e-12)
    whole = np.array([0.0, 7.0, walk.num_frames - 1])
    rot, pos = at_times(walk.rotations, walk.positions, whole)
    assert np.array_equal(pos, walk.positions[[0, 7, -1]])
    np.testing.assert_allclose(rot, walk.rotations[[0, 7, -1]], atol=1e-15)  # renormalised: to rounding
    rot, pos = at_times(walk.rotations, walk.positions, [-2.0, walk.num_frames + 3.5])  # clipped to the ends
    assert np.array_equal(pos, walk.positions[[0, -1]])
    root_rot, root = at_times(walk.rotations[:, 0], walk.positions[:, 0], [2.25])  # one joint: (F, 4), (F, 3)
    assert root_rot.shape == (1, 4) and root.shape == (1, 3)
    np.testing.assert_allclose(root[0], 0.75 * walk.positions[2, 0] + 0.25 * walk.positions[3, 0], atol=1e-12)


def test_segment_coordinates():
    s, u = segment_coordinates(12, np.array([2, 5, 11]))
    assert s.tolist() == [0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 1]
    np.testing.assert_allclose(u[[0, 2, 3, 5, 8, 11]], [0, 0, 1 / 3, 0, 0.5, 1])


def test_snap_to_keys_is_exact_smooth_and_reports(walk):
    keys = Keys([0, 20, 45, 68])
    base = cubic(walk, keys)
    rng = np.random.default_rng(1)
    noisy = base.replace(
        rotations=R.quat_normalize(base.rotations + rng.normal(0, 0.01, base.rotations.shape)),
        positions=base.positions + rng.normal(0, 0.1, base.positions.shape),
    )
    fixed, report = snap_to_keys(noisy, walk, keys)
    k = keys.frames
    assert np.array_equal(fixed.rotations[k], walk.rotations[k])
    assert np.array_equal(fixed.positions[k], walk.positions[k])
    assert report["key_residual_position"] > 0.1 and report["key_residual_rotation_rad"] > 0.005
    # The correction is smooth: next to a key it nearly equals the key's residual.
    corr = fixed.positions - noisy.positions
    res = walk.positions[20] - noisy.positions[20]
    assert np.abs(corr[21] - res).max() < 0.02 * np.abs(res).max() + 1e-9


# --- one vocabulary: every baseline is a method of complete, evaluate and the protocols -------------------


@pytest.mark.parametrize("name", ["linear", "interpolation", "cubic", "velocity", "zero-velocity"])
def test_every_baseline_completes_a_motion_as_its_window_form_does(walk, name):
    from keyfill.learn import registry
    from keyfill.learn.protocols import lafan1

    keys = Keys([0, 10, 11, 33, 60, 68])
    out = registry.complete(walk, keys, name).motion
    _, windows = lafan1.resolve_method(name)
    q, r = windows(walk.skeleton, walk.rotations[None], walk.positions[None, :, 0], keys.frames)
    np.testing.assert_allclose(R.quat_mul(out.rotations, R.quat_conjugate(q[0]))[..., 0] ** 2, 1.0, atol=1e-9)
    np.testing.assert_allclose(out.positions[:, 0], r[0], atol=1e-9)
    assert np.array_equal(out.rotations[keys.frames], walk.rotations[keys.frames])


def test_hold_repeats_the_key_before_each_frame(walk):
    from keyfill.interpolate import hold

    out = hold(walk, Keys([5, 20, 68]))
    assert np.array_equal(out.rotations[:20], np.broadcast_to(walk.rotations[5], out.rotations[:20].shape))
    assert np.array_equal(out.positions[20:68], np.broadcast_to(walk.positions[20], out.positions[20:68].shape))


def test_complete_cli_takes_every_method_name_evaluate_takes(tmp_path):
    from keyfill.cli.main import main
    from keyfill.learn import registry

    names = [m.name for m in registry.METHODS.values() if not m.learned] + list(registry.ALIASES)
    for name in names:
        out = tmp_path / f"{name}.bvh"
        assert main(["-q", "complete", str(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"), "--key-every", "10",
                     "--method", name, "-o", str(out)]) == 0
        assert out.is_file()
