"""Folders of BVH files as arrays: discovery, folding, windows, skeleton checks, cache."""

from pathlib import Path

import numpy as np
import pytest
from synthetic_corpus import walker_motion, walker_skeleton, write_corpus

from keyfill import io
from keyfill.errors import DataError
from keyfill.kinematics import fk
from keyfill.learn import corpus as C


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))


def test_no_bvh_files_is_a_clear_error(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "notes.txt").write_text("x")
    with pytest.raises(DataError, match="no BVH files in .*empty"):
        C.load_corpus([tmp_path / "empty"])
    with pytest.raises(DataError, match="no such file or folder"):
        C.load_corpus([tmp_path / "missing"])


def test_pattern_selects_files(tmp_path):
    write_corpus(tmp_path, styles=("happy", "tired"), clips_per_style=2)
    assert [f.name for f in C.bvh_files([tmp_path], "*_tired_*")] == ["walk_tired_000.bvh", "walk_tired_001.bvh"]
    with pytest.raises(DataError, match="matches 'x\\*'"):
        C.bvh_files([tmp_path], "x*")


def test_folding_keeps_the_global_transforms(tmp_path):
    skel = walker_skeleton()
    m = walker_motion(skel, 40, np.random.default_rng(3))
    assert C.top_joint_is_static(m)
    q, p = C.fold_root(m.rotations, m.positions, skel.parents)
    g0, p0 = fk(m.rotations, m.positions, skel.parents)
    g1, p1 = fk(q, p, skel.parents)
    # joints 1.. keep their global transforms; joint 0 now carries the hips' one
    np.testing.assert_allclose(p1[:, 1:], p0[:, 1:], atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(g1[:, 1:] * g0[:, 1:], -1)), 1.0, atol=1e-9)
    np.testing.assert_allclose(p1[:, 0], p0[:, 1], atol=1e-9)
    np.testing.assert_array_equal(q[:, 1], [[1, 0, 0, 0]] * 40)
    np.testing.assert_array_equal(p[:, 1], 0.0)


def test_corpus_arrays_and_windows(tmp_path):
    paths = write_corpus(tmp_path, styles=("a",), clips_per_style=3, frames=(70, 70))
    io.save(walker_motion(walker_skeleton(), 30, np.random.default_rng(9)), tmp_path / "walk_short_000.bvh")
    c = C.load_corpus([tmp_path])
    assert c.folded and len(c) == 4 and c.skeleton.names[0] == "joint_Root"
    assert c.quats.shape == (3 * 70 + 30, 8, 4) and c.root.shape == (240, 3)
    np.testing.assert_array_equal(c.starts, [0, 70, 140, 210, 240])  # files sorted by name
    # quaternion signs are continuous along every clip
    for i in range(len(c)):
        q, _ = c.clip(i)
        assert np.all(np.sum(q[1:] * q[:-1], -1) >= 0)
    # windows as the reference cuts them: start + length < frames
    q, _r, clip_of, skipped = c.windows(50, 10)
    assert skipped == 1  # the 30-frame clip
    assert Path(c.files[3]).name == "walk_short_000.bvh"
    assert len(q) == 3 * 2  # starts 0 and 10 (20 + 50 = 70 is not < 70)
    a = c.starts[int(clip_of[1])]
    np.testing.assert_array_equal(q[1], c.quats[a + 10 : a + 60])
    assert [Path(f).name for f in c.files[:3]] == [p.name for p in paths]


def test_different_skeletons_are_refused_naming_the_difference(tmp_path):
    write_corpus(tmp_path, styles=("a",), clips_per_style=2)
    other = walker_skeleton(leg_length=55.0)
    io.save(walker_motion(other, 80, np.random.default_rng(1)), tmp_path / "walk_z_000.bvh")
    with pytest.raises(DataError, match="walk_z_000.bvh: another skeleton than .*walk_a_000.bvh: joint 'Foot_L'"):
        C.load_corpus([tmp_path])


def test_frame_rates_must_agree(tmp_path):
    write_corpus(tmp_path, styles=("a",), clips_per_style=1)
    m = walker_motion(walker_skeleton(), 80, np.random.default_rng(1), fps=60.0)
    io.save(m, tmp_path / "walk_b_000.bvh")
    with pytest.raises(DataError, match="60 fps"):
        C.load_corpus([tmp_path])


def test_cache_round_trip_and_invalidation(tmp_path, monkeypatch):
    monkeypatch.setattr(C, "CACHE_AFTER_S", 0.0)
    folder = tmp_path / "clips"
    write_corpus(folder, styles=("a",), clips_per_style=2)
    first = C.load_corpus([folder])
    cached = list((tmp_path / "cache").glob("corpus-*.npz"))
    assert len(cached) == 1
    second = C.load_corpus([folder])
    np.testing.assert_array_equal(second.quats, first.quats)
    np.testing.assert_array_equal(second.skeleton.offsets, first.skeleton.offsets)
    assert second.skeleton.names == first.skeleton.names and second.files == first.files
    write_corpus(folder, styles=("b",), clips_per_style=1, seed=5)  # a new file: a new cache entry
    third = C.load_corpus([folder])
    assert len(third) == 3 and len(list((tmp_path / "cache").glob("corpus-*.npz"))) == 2


def test_subset_and_matching(tmp_path):
    write_corpus(tmp_path, styles=("happy", "calm"), clips_per_style=2)
    c = C.load_corpus([tmp_path])
    calm = c.matching("*_happy_*", invert=True)
    assert [Path(f).name for f in calm.files] == ["walk_calm_000.bvh", "walk_calm_001.bvh"]
    np.testing.assert_array_equal(calm.clip(1)[0], c.clip(1)[0])


def test_locate_explains_what_is_missing(tmp_path, monkeypatch):
    monkeypatch.setenv("KEYFILL_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("KEYFILL_SHARED_DATA", str(tmp_path / "shared"))
    with pytest.raises(DataError, match="is not unpacked .* archive .*does not exist"):
        C.locate("bandai1")
    with pytest.raises(DataError, match="unknown corpus"):
        C.locate("lafan1")


def test_mirror_pairs_by_name():
    names = ["joint_Root", "Hips", "Leg_L", "Leg_R", "LeftArm", "RightArm", "l_eye", "r_eye", "Spine"]
    assert C.mirror_pairs(names).tolist() == [0, 1, 3, 2, 5, 4, 7, 6, 8]
    assert C.mirror_pairs(["Hips", "Leg_L"]) is None  # no partner
    assert C.mirror_pairs(["Hips", "Spine"]) is None  # nothing to mirror


def test_mirrored_walk_is_the_reflected_walk(tmp_path):
    write_corpus(tmp_path, styles=("a",), clips_per_style=3)
    c = C.load_corpus([tmp_path])
    mirror = C.find_mirror(c.skeleton, c.quats)
    assert mirror is not None
    assert [c.skeleton.names[i] for i in mirror.perm[[4, 6]]] == ["Leg_R", "Leg_L"]
    q, r = c.clip(0)
    mq, mr = mirror(q, r)

    def world(q, r):
        pos = np.broadcast_to(c.skeleton.offsets, q.shape[:-1] + (3,)).copy()
        pos[:, 0] = r
        return fk(q, pos, c.skeleton.parents)[1]

    p, mp = world(q, r), world(mq, mr)
    np.testing.assert_allclose(mp[:, mirror.perm], p * [-1, 1, 1], atol=1e-9)
    qq, rr = mirror(mq, mr)
    np.testing.assert_allclose(np.abs(np.sum(qq * q, -1)), 1.0, atol=1e-12)
    np.testing.assert_allclose(rr, r)


def test_no_mirror_without_sides():
    from keyfill.motion import Skeleton

    s = Skeleton(["a", "b"], [-1, 0], [[0, 0, 0], [0, 1, 0]], [(), ()])
    assert C.find_mirror(s, np.tile([1.0, 0, 0, 0], (5, 2, 1))) is None
