"""Reference T-poses, world-space retargeting between humanoid rigs, and the bridge of the human models."""

from pathlib import Path

import numpy as np
import pytest
from conftest import DATA

from keyfill import io
from keyfill.characters.retarget import canonical_axes, make_rig, quat_between, retarget
from keyfill.kinematics import fk
from keyfill.learn.rig_bridge import mapped_joints, model_frames, model_times, resampled
from keyfill.motion import Motion

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "bvh_fixtures"
BANDAI = SHARED / "dataset-1_walk_normal_002.bvh"
MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"
needs_bandai = pytest.mark.skipif(not BANDAI.is_file(), reason="needs ../shared/data (Bandai-Namco fixture)")


def _world(motion: Motion) -> np.ndarray:
    return fk(motion.rotations, motion.positions, motion.skeleton.parents)[1]


def test_quat_between_turns_one_direction_onto_another():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    from keyfill import rotations as R

    turned = R.quat_rotate(quat_between(a, b), a)
    np.testing.assert_allclose(turned / np.linalg.norm(turned, axis=-1, keepdims=True),
                               b / np.linalg.norm(b, axis=-1, keepdims=True), atol=1e-12)
    np.testing.assert_allclose(R.quat_rotate(quat_between(a[:1], -a[:1]), a[:1]), -a[:1], atol=1e-12)


@pytest.mark.parametrize("path", [MIXAMO, CMU, pytest.param(BANDAI, marks=needs_bandai)])
def test_the_reference_pose_is_a_t_pose(path):
    rig = make_rig(io.load(path).skeleton)
    left, up, forward = canonical_axes(rig.skeleton.up_axis)
    p = fk(rig.reference, rig.skeleton.offsets, rig.skeleton.parents)[1]
    roles = rig.roles

    def direction(a, b):
        v = p[roles.joint(b)] - p[roles.joint(a)]
        return v / np.linalg.norm(v)

    for side, sign in (("l", 1), ("r", -1)):
        np.testing.assert_allclose(direction(f"upper_arm_{side}", f"forearm_{side}"), sign * left, atol=1e-9)
        np.testing.assert_allclose(direction(f"forearm_{side}", f"hand_{side}"), sign * left, atol=1e-9)
        np.testing.assert_allclose(direction(f"thigh_{side}", f"shin_{side}"), -up, atol=1e-9)
        np.testing.assert_allclose(direction(f"shin_{side}", f"foot_{side}"), -up, atol=1e-9)
        np.testing.assert_allclose(direction(f"foot_{side}", f"toe_{side}"), forward, atol=1e-9)
    assert direction("hips", "head") @ up > 0.99  # each spine bone points up; the hips' own offset leans as at rest
    assert direction("thigh_r", "thigh_l") @ left > 0.999  # the hips frame: up first, then the side
    assert rig.hip_height > 0


def test_a_t_pose_stays_a_t_pose_on_another_rig():
    cmu = io.load(CMU)  # frame 0 of the cgspeed CMU conversion is a T-pose
    source, target = make_rig(cmu.skeleton), make_rig(io.load(MIXAMO).skeleton)
    out = _world(retarget(cmu.frames([0]), source, target))[0]
    h = out[target.roles.hips]
    left_hand = out[target.roles.joint("hand_l")] - h
    assert left_hand[0] > 0.6 * target.hip_height and abs(left_hand[1] - 0.5 * target.hip_height) < 0.2 * target.hip_height
    foot = out[target.roles.joint("foot_l")] - h
    assert foot[1] < -0.9 * target.hip_height


@pytest.mark.parametrize("via", [MIXAMO, CMU])
def test_round_trips_keep_mapped_joints_within_one_percent_of_the_height(via):
    clip = io.load(MIXAMO)
    home, other = make_rig(clip.skeleton), make_rig(io.load(via).skeleton)
    back = retarget(retarget(clip, home, other), other, home)
    p0, p1 = _world(clip), _world(back)
    height = np.ptp(p0[..., 1])
    err = np.linalg.norm(p1 - p0, axis=-1)[:, mapped_joints(home)].max()
    assert err < 0.01 * height


@needs_bandai
def test_bandai_clips_round_trip_through_the_mixamo_rig():
    clip = io.load(BANDAI)
    home, other = make_rig(clip.skeleton), make_rig(io.load(MIXAMO).skeleton)
    there = retarget(clip, home, other)
    assert there.skeleton is other.skeleton and there.fps == clip.fps
    back = retarget(there, other, home)
    p0, p1 = _world(clip), _world(back)
    err = np.linalg.norm(p1 - p0, axis=-1)[:, mapped_joints(home)].max()
    assert err < 0.01 * np.ptp(p0[..., 1])
    # the hips travel as far, in the other rig's proportion
    travel = np.linalg.norm(p0[-1, home.roles.hips, [0, 2]] - p0[0, home.roles.hips, [0, 2]])
    there_travel = np.linalg.norm(np.diff(_world(there)[[0, -1], other.roles.hips][:, [0, 2]], axis=0))
    np.testing.assert_allclose(there_travel, travel * other.hip_height / home.hip_height, rtol=1e-9)


def test_model_frames_put_every_key_on_the_model_grid():
    np.testing.assert_array_equal(model_frames(np.array([0, 60, 120, 121, 300]), 120.0, 30.0), [0, 15, 30, 31, 76])
    np.testing.assert_array_equal(model_frames(np.array([5, 15, 45]), 30.0, 30.0), [0, 10, 40])


def test_resampling_to_the_input_grid_hits_the_keys_and_holds_outside():
    clip = io.load(MIXAMO)
    keys = np.array([4, 20, 60])
    grid = model_frames(keys, 120.0, 30.0)  # as if the clip were at 120 fps
    coarse = clip.frames(list(range(int(grid[-1]) + 1)))
    blocks = list(resampled(coarse, model_times(grid, keys, 66)))
    fine = clip.replace(rotations=np.concatenate([b[2] for b in blocks]), positions=np.concatenate([b[3] for b in blocks]))
    assert fine.num_frames == 66
    for key, g in zip(keys, grid):
        np.testing.assert_allclose(fine.positions[key], coarse.positions[g], atol=1e-12)
    np.testing.assert_allclose(fine.positions[:4], np.broadcast_to(coarse.positions[0], (4, *coarse.positions.shape[1:])))
    np.testing.assert_allclose(fine.positions[61:], np.broadcast_to(coarse.positions[grid[-1]], (5, *coarse.positions.shape[1:])))


def test_the_bridge_makes_each_rig_once_and_keeps_the_callers_skeleton(monkeypatch):
    from keyfill.learn import rig_bridge

    motion, cmu = io.load(MIXAMO), io.load(CMU)
    served = rig_bridge.Served(cmu.skeleton, 30.0, False)
    fresh = make_rig(motion.skeleton)
    monkeypatch.setattr(rig_bridge, "_RIGS", {})
    calls = []
    monkeypatch.setattr(rig_bridge, "make_rig", lambda *a, **k: calls.append(a) or make_rig(*a, **k))
    for _ in range(3):
        rig, model_rig = rig_bridge.rigs(motion, served, None, 0, "")
        assert rig.skeleton is motion.skeleton and model_rig.skeleton is cmu.skeleton  # end sites and all
        assert rig.roles == fresh.roles and rig.hip_height == fresh.hip_height
        np.testing.assert_array_equal(rig.reference, fresh.reference)
    assert len(calls) == 2  # one per skeleton
    rig_bridge.rigs(motion, served, {"hand_l": "mixamorig:LeftHand"}, 0, "")
    assert len(calls) == 3  # a rig map is part of what a rig is made from
