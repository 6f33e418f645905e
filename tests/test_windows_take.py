"""A take's arrays made a block of frames at a time (:func:`keyfill.learn.windows.model_take` and
:func:`~keyfill.learn.windows.file_take`, and the rig bridge's way back, :mod:`keyfill.learn.rig_bridge`;
issue 44: long takes in bounded memory) hold the very numbers of the whole-take steps they replace: the keys'
interpolation, the model's hierarchy, continuous signs, and back; retargeting, resampling and the spline."""

import numpy as np
import pytest
from conftest import DATA
from synthetic_corpus import walker_motion, walker_skeleton
from test_long_takes import long_motion

from keyfill import interpolate, io
from keyfill import rotations as R
from keyfill.characters.retarget import make_rig, retarget
from keyfill.errors import ModelError
from keyfill.interpolate import linear, segment_coordinates
from keyfill.learn import rig_bridge, windows
from keyfill.learn.corpus import model_hierarchy
from keyfill.learn.windows import file_take, model_take
from keyfill.motion import Keys

KEYS = np.array([3, 9, 10, 21, 30, 41, 55, 60, 71, 86, 93])


def take(frames: int = 100, seed: int = 0, static_root: bool = True):
    """A walk (with a top joint above the hips: ``static_root``) whose top joint turns (so folding matters),
    whose translations wobble (so lerping them does), and whose rotations take random signs (so the
    continuity's sign changes do)."""
    rng = np.random.default_rng(seed)
    motion = walker_motion(walker_skeleton(static_root=static_root), frames, rng)
    rot = motion.rotations.copy()
    rot[:, 0] = R.quat_from_rotvec(rng.normal(scale=0.3, size=(frames, 3)))
    rot *= np.where(rng.random(rot.shape[:2]) < 0.3, -1.0, 1.0)[..., None]
    pos = motion.positions + rng.normal(scale=1e-3, size=motion.positions.shape)
    return motion.replace(rotations=rot, positions=pos)


def served(motion, folded):
    """The skeleton a model of ``motion``'s corpus serves (folded: the hips' offset in the top joint's)."""
    offsets = motion.skeleton.offsets.copy()
    if folded:
        offsets[1] = 0.0
    return motion.skeleton.replace(offsets=offsets)


def whole_take(motion, k, folded, slerped=None, continuous=False):
    """The steps model_take replaced, each over the whole take at once."""
    if slerped is None:
        lin = linear(motion, Keys(k))
        rot, pos = lin.rotations, lin.positions
    else:  # the gan's: only some joints slerped, the others the motion's own
        s, u = segment_coordinates(motion.num_frames, k)
        kp, kq = motion.positions[k], motion.rotations[k][:, slerped]
        pos = kp[s + 1] - kp[s]
        pos *= u[:, None, None]
        pos += kp[s]
        rot = motion.rotations.copy()
        rot[:, slerped] = R.quat_slerp(kq[s], kq[s + 1], np.broadcast_to(u[:, None], (len(u), len(slerped))))
        rot[k], pos[k] = motion.rotations[k], motion.positions[k]
    q, p = model_hierarchy(served(motion, folded), folded, motion.skeleton, rot, pos, int(k[0]))
    if continuous:
        q = R.quat_continuous_np(q, axis=0)
    return q, p, (rot[:, 0].copy(), pos[:, 0].copy())


@pytest.mark.parametrize("block", [1, 2, 7, 64, 4096])
@pytest.mark.parametrize(("folded", "slerped", "continuous"),
                         [(True, None, True), (False, None, True), (True, [0, 3, 5, 7], False), (False, [], False),
                          (False, [2, 4], True)])
def test_a_take_made_in_blocks_is_the_whole_take_made_at_once(monkeypatch, block, folded, slerped, continuous):
    motion = take(static_root=folded)
    want_q, want_p, want_top = whole_take(motion, KEYS, folded, slerped, continuous)
    monkeypatch.setattr(windows, "BLOCK", block)
    q, p, top = model_take(served(motion, folded), folded, motion, KEYS, slerped, continuous)
    assert np.array_equal(q, want_q) and np.array_equal(p, want_p)
    if folded:
        assert np.array_equal(top[0], want_top[0]) and np.array_equal(top[1], want_top[1])
    else:
        assert top is None
    if continuous:  # really continuous, and there were signs to change
        assert (np.sum(q[1:] * q[:-1], axis=-1) >= 0).all()


@pytest.mark.parametrize("block", [1, 7, 4096])
def test_a_take_goes_back_to_the_files_hierarchy_in_blocks_as_at_once(monkeypatch, block):
    motion = take(seed=1)
    q, p, top = model_take(served(motion, True), True, motion, KEYS, continuous=True)
    q *= 1.5  # not unit: the way back normalises
    want_q, want_p = q.copy(), p.copy()
    inv = R.quat_conjugate(top[0])
    want_q[:, 1] = R.quat_mul(inv, want_q[:, 0])
    want_p[:, 1] = R.quat_rotate(inv, want_p[:, 0] - top[1])
    want_q[:, 0], want_p[:, 0] = top
    want_q /= np.sqrt(np.sum(want_q * want_q, axis=-1, keepdims=True))
    monkeypatch.setattr(windows, "BLOCK", block)
    file_take(q, p, top, motion.skeleton)
    assert np.array_equal(q, want_q) and np.array_equal(p, want_p)
    # the take's frames outside the motion's keys are no longer the motion's, but its key frames are back
    assert np.allclose(q[KEYS], motion.rotations[KEYS] * np.sign(np.sum(q[KEYS] * motion.rotations[KEYS], -1))[..., None])
    assert np.allclose(p[KEYS], motion.positions[KEYS])


def test_a_take_is_checked_against_the_model_before_any_work():
    motion = take()
    other = walker_skeleton(leg_length=60.0)
    with pytest.raises(ModelError, match="another skeleton than the model.*; train one$"):
        model_take(other, True, motion, KEYS, hint="; train one")


@pytest.mark.parametrize("block", [1, 5, 64, 4096])
@pytest.mark.parametrize(("fps", "back"), [(120.0, True), (30.0, True), (24.0, False)])
def test_the_bridge_back_onto_the_rig_in_blocks_is_the_whole_take_at_once(monkeypatch, block, fps, back):
    """A model's take (20 whole turns of the root: many sign changes) retargeted onto another rig and resampled
    at the motion's frames: in blocks as the whole take retargeted (its signs continuous along all of it), then
    resampled."""
    keys = np.array([2, 40, 41, 97, 160, 171, 250, 299]) if fps != 30.0 else np.array([0, 30, 60, 299])
    grid = rig_bridge.model_frames(keys, fps, 30.0)
    filled = long_motion(int(grid[-1]) + 1)
    flip = np.where(np.random.default_rng(1).random(filled.rotations.shape[:2]) < 0.3, -1.0, 1.0)
    filled = filled.replace(rotations=filled.rotations * flip[..., None])  # signs for retargeting to make continuous
    times = rig_bridge.model_times(grid, keys, 320)
    rigs = (make_rig(filled.skeleton), make_rig(io.load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh").skeleton))
    whole = retarget(filled, *rigs) if back else filled
    want_r, want_p = interpolate.at_times(whole.rotations, whole.positions, times)
    monkeypatch.setattr(interpolate, "BLOCK", block)
    blocks = list(rig_bridge.resampled(filled, times, rigs if back else None))
    assert [b[0] for b in blocks] == list(range(0, 320, block))
    assert np.array_equal(np.concatenate([b[2] for b in blocks]), want_r)
    assert np.array_equal(np.concatenate([b[3] for b in blocks]), want_p)


@pytest.mark.parametrize("block", [1, 6, 64, 4096])
def test_the_bridges_spline_in_blocks_is_the_whole_spline(block):
    motion = long_motion(200, seed=3)
    k = np.array([5, 9, 30, 31, 77, 120, 121, 150, 190])
    want = interpolate.cubic(motion, Keys(k))
    signs = R.quat_continuous_np(motion.rotations[k], axis=0)
    parts = [interpolate.cubic_span(motion, k, signs, a, min(a + block, 200)) for a in range(0, 200, block)]
    assert np.array_equal(np.concatenate([p[0] for p in parts]), want.rotations)
    assert np.array_equal(np.concatenate([p[1] for p in parts]), want.positions)
