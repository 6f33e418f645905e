"""Partial keys: the ``Keys`` mask, the exact-key correction of only what is keyed, and the registry's refusal."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_corpus import walker_motion, walker_skeleton

from keyfill import rotations as R
from keyfill.errors import UsageError
from keyfill.interpolate import linear
from keyfill.learn.exact_keys import snap_to_keys
from keyfill.learn.registry import complete
from keyfill.motion import Keys


@pytest.fixture(scope="module")
def motion():
    return walker_motion(walker_skeleton(), 120, np.random.default_rng(5))


def perturbed(motion, rng):
    """A 'prediction' that misses every key: every rotation turned a little, every translation moved."""
    noise = R.quat_from_rotvec(0.2 * rng.normal(size=(motion.num_frames, motion.num_joints, 3)))
    return motion.replace(rotations=R.quat_normalize(R.quat_mul(noise, motion.rotations)),
                          positions=motion.positions + rng.normal(size=motion.positions.shape))


def test_full_keys_are_not_partial_and_masks_cover_everything(motion):
    keys = Keys(np.array([0, 40, 119]))
    assert not keys.partial
    assert not Keys(keys.frames, np.ones((3, motion.num_joints), bool)).partial
    rot, pos = keys.channel_masks(motion.skeleton)
    assert rot.all() and pos.all()


def test_masked_key_leaves_unkeyed_joints_free_and_keyed_joints_exact(motion):
    sk = motion.skeleton
    keys = Keys(np.array([0, 40, 119])).restrict(sk, ["joint_Root", "Hips", "Leg_L", "Foot_L"])
    assert keys.partial
    pred = perturbed(motion, np.random.default_rng(0))
    out, report = snap_to_keys(pred, motion, keys)
    k = keys.frames
    keyed = [sk.index(n) for n in ("joint_Root", "Hips", "Leg_L", "Foot_L")]
    free = [j for j in range(sk.num_joints) if j not in keyed]
    assert np.array_equal(out.rotations[k][:, keyed], motion.rotations[k][:, keyed])
    assert np.array_equal(out.positions[k][:, keyed], motion.positions[k][:, keyed])
    # unkeyed joints keep the prediction at the keys (no correction there), and it differs from the source
    assert np.allclose(out.rotations[k][:, free], pred.rotations[k][:, free])
    assert np.allclose(out.positions[k][:, free], pred.positions[k][:, free])
    assert not np.allclose(out.rotations[k][:, free], motion.rotations[k][:, free], atol=1e-3)
    assert report["key_residual_position"] > 0


def test_full_mask_gives_the_bytes_of_full_keys(motion):
    pred = perturbed(motion, np.random.default_rng(1))
    keys = Keys(np.array([0, 40, 119]))
    a, _ = snap_to_keys(pred, motion, keys)
    b, _ = snap_to_keys(pred, motion, Keys(keys.frames, np.ones((3, motion.num_joints), bool)))
    assert a.rotations.tobytes() == b.rotations.tobytes() and a.positions.tobytes() == b.positions.tobytes()


def test_root_positions_and_2d_keys_fix_only_the_given_root_coordinates(motion):
    sk = motion.skeleton
    pred = perturbed(motion, np.random.default_rng(2))
    k = np.array([0, 60, 119])
    spots = Keys(k).restrict(sk, ["Hips"], "position")  # the hips hold a position below the static joint_Root
    out, _ = snap_to_keys(pred, motion, spots)
    assert np.array_equal(out.positions[k, 1], motion.positions[k, 1])
    assert np.allclose(out.positions[k, 0], pred.positions[k, 0])
    assert np.allclose(out.rotations[k], pred.rotations[k])  # positions do not fix rotations
    flat = Keys(k, None, "xz")
    assert flat.given == "XZ"
    out, _ = snap_to_keys(pred, motion, flat)
    assert np.array_equal(out.positions[k, 0][:, [0, 2]], motion.positions[k, 0][:, [0, 2]])
    assert np.allclose(out.positions[k, 0, 1], pred.positions[k, 0, 1])
    assert flat.coordinate_mask(sk.num_joints)[..., 1].sum() == 0


def test_bad_partial_keys(motion):
    with pytest.raises(UsageError, match="unknown joint 'Tail'"):
        Keys(np.array([0, 10])).restrict(motion.skeleton, ["Tail"])
    with pytest.raises(UsageError, match="view plane"):
        Keys(np.array([0, 10]), None, "XW")
    with pytest.raises(UsageError, match="mask names 3 joints"):
        complete(motion, Keys(np.array([0, 10]), np.ones((2, 3), bool)), "gan")


@pytest.mark.parametrize("method", ["linear", "cubic", "transformer", "arnn"])
def test_methods_without_partial_keys_refuse_them_naming_those_that_accept(motion, method):
    keys = Keys(np.array([0, 60, 119])).restrict(motion.skeleton, ["Hips"])
    with pytest.raises(UsageError, match="partial keys .* accepted by: gan"):
        complete(motion, keys, method)


def test_frames_keeps_the_key_mask(motion):
    keys = Keys(np.array([0, 40, 119])).restrict(motion.skeleton, ["Hips"], "XY")
    cut = motion.replace(keys=keys).frames(slice(30, 120))
    assert cut.keys.to_list() == [10, 89] and cut.keys.given == "XY"
    assert cut.keys.mask.shape == (2, motion.num_joints) and cut.keys.mask[:, 1].all()
    assert linear(motion, Keys(np.array([0, 119]))).num_frames == 120


def test_usd_files_carry_the_key_mask(motion, tmp_path):
    pytest.importorskip("pxr")
    from keyfill import io

    keys = Keys(np.array([0, 40, 119])).restrict(motion.skeleton, ["Hips", "Leg_L"], "XY")
    io.save(motion.replace(keys=keys), tmp_path / "k.usda")
    back = io.load(tmp_path / "k.usda").keys
    assert back.to_list() == keys.to_list() and back.given == "XY" and np.array_equal(back.mask, keys.mask)
    io.save(motion.replace(keys=Keys(keys.frames)), tmp_path / "full.usda")
    full = io.load(tmp_path / "full.usda").keys
    assert full.mask is None and not full.partial
    assert "keyMask" not in (tmp_path / "full.usda").read_text()
