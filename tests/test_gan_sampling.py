"""Training data (section 3.7, Appendix C): key layouts over several clips, real crops, whole clips."""

from __future__ import annotations

import numpy as np
import pytest

from keyfill.learn.gan.poses import ClipPool, clip_pool, relative_positions, turn
from keyfill.learn.gan.sampling import clip_batch, crop_starts, real_crops, sample_keys
from keyfill.motion import Skeleton


def line_pool(lengths=(150, 140, 160, 130), fps=30.0) -> ClipPool:
    """Clips of a 3-joint body walking along +Z at 1 m/s, each pose tagged by its clip and frame."""
    rel, root = [], []
    for c, n in enumerate(lengths):
        t = np.arange(n)
        r = np.stack([np.full(n, c * 10.0), np.full(n, 0.9), t / fps], -1)
        p = np.zeros((n, 3, 3), dtype=np.float32)
        p[:, 1] = [0, 0.5, 0]
        p[:, 2] = np.stack([np.full(n, c), t / 1000, np.zeros(n)], -1)  # joint 2 encodes (clip, frame)
        rel.append(p)
        root.append(r)
    return ClipPool(tuple(rel), tuple(root), fps, "Y")


def test_keys_cover_the_sequence_with_bounded_gaps_and_are_seeded():
    pool = line_pool()
    a = sample_keys(pool, np.random.default_rng(5), 1024, 1, 600)
    b = sample_keys(pool, np.random.default_rng(5), 1024, 1, 600)
    assert np.array_equal(a.frames, b.frames) and np.array_equal(a.poses, b.poses)
    assert a.frames[0] == 0 and a.frames[-1] == 1023
    gaps = np.diff(a.frames)
    assert gaps.min() >= 1 and gaps.max() <= 600
    assert a.poses.shape == (len(a.frames), 3, 3)
    # re-centred: the keys' mean ground position of the root is the origin
    assert np.allclose(a.poses[:, 0, [0, 2]].mean(0), 0, atol=1e-9)


def test_short_gaps_stay_in_one_clip_and_keep_its_motion():
    pool = line_pool()
    checked = 0
    for seed in range(20):
        lay = sample_keys(pool, np.random.default_rng(seed), 512, 1, 600, short_gap_seconds=3.0)
        for i in range(len(lay.frames) - 1):
            g = lay.frames[i + 1] - lay.frames[i]
            if g <= 90 and lay.clips[i] == lay.clips[i + 1]:
                # joint 2's height tags the clip frame: it moved by exactly the gap; the root by the clip's 1 m/s
                assert (lay.poses[i + 1, 2, 1] - lay.poses[i, 2, 1]) * 1000 == pytest.approx(g, abs=1e-3)
                step = lay.poses[i + 1, 0, [0, 2]] - lay.poses[i, 0, [0, 2]]
                assert np.hypot(*step) == pytest.approx(g / 30.0)
                checked += 1
    assert checked > 20


def test_long_gaps_jump_to_other_clips_more_often_than_short_ones():
    pool = line_pool(lengths=(2000, 2000, 2000))  # long clips: only the probability decides
    jumps = {"short": [0, 0], "long": [0, 0]}
    for seed in range(200):
        lay = sample_keys(pool, np.random.default_rng(seed), 1024, 1, 600)
        for i in range(len(lay.frames) - 1):
            g = lay.frames[i + 1] - lay.frames[i]
            kind = "short" if g <= 90 else "long"
            jumps[kind][0] += lay.clips[i] != lay.clips[i + 1]
            jumps[kind][1] += 1
    # a short gap leaves its clip only when the clip ends and the sequence has no room for a longer gap
    assert jumps["short"][0] / jumps["short"][1] < 0.05
    assert 0.2 < jumps["long"][0] / jumps["long"][1] < 0.9


def test_short_clips_give_keys_from_several_clips():
    pool = line_pool(lengths=(150, 140, 160, 130, 120))
    used = [len(set(sample_keys(pool, np.random.default_rng(s), 1024, 1, 600).clips)) for s in range(10)]
    assert min(used) >= 2


def test_jump_distance_grows_with_the_gap():
    pool = line_pool(lengths=(2000, 2000, 2000))
    dist = {"short": [], "long": []}
    for seed in range(300):
        lay = sample_keys(pool, np.random.default_rng(seed), 1024, 91, 600, jump_speed=1.5)
        for i in range(len(lay.frames) - 1):
            if lay.clips[i] != lay.clips[i + 1]:
                g = lay.frames[i + 1] - lay.frames[i]
                d = np.hypot(*(lay.poses[i + 1, 0, [0, 2]] - lay.poses[i, 0, [0, 2]]))
                assert d <= 1.5 * g / 30.0 + 1e-9
                dist["short" if g < 300 else "long"].append(d)
    assert np.mean(dist["long"]) > np.mean(dist["short"])


def test_real_crops_clip_batches_and_crop_starts():
    pool = line_pool()
    rng = np.random.default_rng(0)
    crops = real_crops(pool, rng, 5, 128)
    assert crops.shape == (5, 128, 3, 3) and crops.dtype == np.float32
    # turned about the up axis only: heights and lengths stay
    assert np.allclose(crops[:, :, 1, 1], 0.5) and np.allclose(np.linalg.norm(crops[:, :, 1], axis=-1), 0.5)
    with pytest.raises(Exception, match="real_frames"):
        real_crops(pool, rng, 1, 512)
    rel, root, lengths = clip_batch(pool, rng, 6, max_frames=145)
    assert rel.shape[0] == 6 and rel.shape[1] == lengths.max() <= 145
    assert np.allclose(root[:, 0, [0, 2]], 0)
    for r, n in zip(root, lengths):  # 1 m/s, any heading
        assert np.hypot(*(r[n - 1, [0, 2]] - r[0, [0, 2]])) == pytest.approx((n - 1) / 30.0, rel=1e-5)
        assert np.allclose(r[n:], r[n - 1])
    s = crop_starts(rng, 3, 4, 1024, 128)
    assert s.shape == (3, 4) and s.min() >= 0 and s.max() <= 1024 - 128


def test_turn_and_relative_positions():
    from keyfill import rotations as R

    p = np.random.default_rng(0).normal(size=(4, 3))
    q = R.quat_from_rotvec(np.array([0, 0.3, 0.0]))
    assert np.allclose(turn(p, 0.3), R.quat_rotate(q, p))
    q = R.quat_from_rotvec(np.array([0, 0, 0.3]))
    assert np.allclose(turn(p, 0.3, "Z"), R.quat_rotate(q, p))
    sk = Skeleton(["a", "b", "c"], [-1, 0, 1], [[5, 5, 5], [0, 1, 0], [0, 1, 0]], [()] * 3)
    quats = np.zeros((1, 3, 4))
    quats[..., 0] = 1
    quats[0, 1] = R.quat_from_rotvec(np.array([0, 0, np.pi / 2]))
    rel = relative_positions(quats, sk.offsets, sk.parents)
    assert np.allclose(rel[0], [[0, 0, 0], [0, 1, 0], [-1, 1, 0]])


def test_clip_pool_is_in_metres(tmp_path):
    from gan_helpers import synthetic_corpus

    corpus = synthetic_corpus(tmp_path / "c", clips_per_style=1)
    pool = clip_pool(corpus)
    _, r = corpus.clip(0)
    assert np.allclose(pool.root[0], r * 0.01)
    # the walker's spine joint is 20 cm from the (folded) hips: 0.2 m
    assert np.allclose(np.linalg.norm(pool.relative[0][:, 2], axis=-1), 0.2, atol=1e-6)
