"""Long takes through USD (issue 44): a 100,000-frame file round-trips as a short one does, translations that
never change are written once, and the reader's block-at-a-time checks hold past the first block."""

import numpy as np
import pytest
from conftest import DATA
from pxr import Gf, Sdf, Usd, UsdSkel, Vt

from keyfill import io
from keyfill import rotations as R
from keyfill.errors import FormatError
from keyfill.io import bvh, usd, usd_samples
from keyfill.motion import Keys

EDGES = DATA / "edge_layouts_crlf.bvh"  # 6 joints in two roots, 0 to 6 channels each, decimals like -2.5e-1


def long_take(frames: int):
    """EDGES tiled to ``frames``: the root walks along X in steps of 0.01 (decimals, as a BVH holds them) and
    turns about Z, so no two frames are the same; keys every 1,000 frames."""
    m = bvh.read(EDGES)
    idx = np.arange(frames) % m.num_frames
    pos = m.positions[idx]
    pos[:, 0, 0] = np.round(np.arange(frames) * 0.01, 2)
    rot = m.rotations[idx]
    rot[:, 0] = R.quat_mul(R.quat_from_rotvec(np.outer(np.arange(frames) * 1e-4, [0, 0, 1.0])), rot[:, 0])
    return m.replace(rotations=rot, positions=pos, keys=Keys(np.arange(0, frames, 1000)))


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_a_100k_frame_take_round_trips_as_a_short_one_does(tmp_path, suffix):
    """Translations come back as the very decimals that went in, rotations to 32-bit floats (about 1e-7 rad),
    and the layout, rate and keys as they were: what test_usd checks of a short file, over 25 blocks of frames."""
    m = long_take(100_000)
    io.save(m, tmp_path / ("take" + suffix))
    back = io.load(tmp_path / ("take" + suffix))
    assert back.num_frames == 100_000 and back.fps == m.fps
    assert back.skeleton.names == m.skeleton.names and back.skeleton.channels == m.skeleton.channels
    assert np.array_equal(back.positions, m.positions)
    assert R.quat_angle(back.rotations, m.rotations).max() < 1e-6
    assert back.keys.to_list() == m.keys.to_list()


def _animation(path):
    """``(stage, its SkelAnimation)``; the animation lives as long as the stage is held."""
    stage = Usd.Stage.Open(str(path))
    anim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Animation))
    return stage, UsdSkel.Animation(anim)


def test_translations_that_never_change_are_written_once_and_read_back_the_same(tmp_path):
    m = long_take(50)
    still = m.replace(positions=np.broadcast_to(m.positions[:1], m.positions.shape).copy())
    io.save(still, tmp_path / "still.usda")
    stage, anim = _animation(tmp_path / "still.usda")
    t_attr = anim.GetTranslationsAttr()
    assert t_attr.GetNumTimeSamples() == 0 and anim.GetRotationsAttr().GetNumTimeSamples() == 50
    assert np.array_equal(np.asarray(t_attr.Get()), still.positions[0].astype(np.float32))
    # UsdSkel resolves the default at every frame: what a viewer poses the skeleton with
    query = UsdSkel.Cache().GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath("/Root/Skeleton"))).GetAnimQuery()
    for f in (0, 17, 49):
        local = query.ComputeJointLocalTransforms(Usd.TimeCode(f))
        assert np.allclose([list(x.ExtractTranslation()) for x in local], still.positions[f], atol=1e-5)
    back = io.load(tmp_path / "still.usda")
    assert back.num_frames == 50 and np.array_equal(back.positions, still.positions)
    assert R.quat_angle(back.rotations, still.rotations).max() < 1e-6 and back.keys.to_list() == [0]
    # one translation that moves once: every frame's translations are samples again, read back the same
    moved = still.positions.copy()
    moved[30, 2, 0] += 0.5
    io.save(still.replace(positions=moved), tmp_path / "moved.usda")
    _stage, anim = _animation(tmp_path / "moved.usda")
    assert anim.GetTranslationsAttr().GetNumTimeSamples() == 50
    assert np.array_equal(io.load(tmp_path / "moved.usda").positions, moved)


def test_a_sparse_file_with_still_translations_keeps_its_keys_in_the_rotations(tmp_path):
    m = long_take(40)
    still = m.replace(positions=np.broadcast_to(m.positions[:1], m.positions.shape).copy(), keys=Keys([0, 9, 39]))
    path = tmp_path / "keys.usdc"
    usd.write(still, path, sparse=True)
    layer = Sdf.Layer.FindOrOpen(str(path))
    stage = Usd.Stage.Open(layer)
    prim = next(p for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    custom = dict(prim.GetCustomDataByKey("keyfill"))
    del custom["keys"]  # the reader must find the keys in the samples
    prim.SetCustomDataByKey("keyfill", custom)
    layer.Save()
    back = io.load(path)
    assert back.keys.to_list() == [0, 9, 39] and np.array_equal(back.positions, still.positions)


def test_a_file_of_defaults_only_holds_its_pose_at_every_frame(tmp_path):
    """Another tool may write a still pose as default values alone: every frame of the stage's range is that pose,
    and no sample times become keys."""
    m = bvh.read(EDGES)
    path = tmp_path / "pose.usda"
    usd.write(m, path)
    stage, anim = _animation(path)
    for attr in (anim.GetRotationsAttr(), anim.GetTranslationsAttr()):
        first = attr.Get(1)
        attr.Clear()
        attr.Set(first)
    stage.GetRootLayer().Save()
    back = io.load(path)
    assert back.num_frames == 3 and back.keys is None
    assert np.array_equal(back.positions, m.positions[[1, 1, 1]])
    assert R.quat_angle(back.rotations, m.rotations[[1, 1, 1]]).max() < 1e-6


def _spoiled(tmp_path, frame: int, value) -> str:
    """A 5,000-frame .usdc whose rotation sample at ``frame`` (past the reader's first block) is ``value``."""
    path = tmp_path / "spoiled.usdc"
    usd.write(long_take(5000), path)
    layer = Sdf.Layer.FindOrOpen(str(path))
    _stage, anim = _animation(path)
    layer.SetTimeSample(anim.GetRotationsAttr().GetPath(), frame, value)
    layer.Save()
    return str(path)


@pytest.mark.parametrize(("value", "words"), [
    (Vt.QuatfArray([Gf.Quatf(1)]), "rotations at time 4500 holds 1 values for 6 animated joints"),
    (Vt.QuatfArray([Gf.Quatf(1)] * 5 + [Gf.Quatf(float("nan"))]),
     "rotations at time 4500 holds a value that is not finite"),
    (Sdf.ValueBlock(), "rotations has a blocked time sample at 4500"),
], ids=["one value for six joints", "nan", "blocked"])
def test_a_bad_sample_past_the_first_block_is_named(tmp_path, value, words):
    with pytest.raises(FormatError, match=words):
        io.load(_spoiled(tmp_path, 4500, value))


def test_shortest_decimal_in_chunks_gives_back_every_decimal_of_six_digits():
    """More values than one chunk of the shortening: decimals of at most 6 significant digits (what float32
    tells apart) come back exactly from their float32, in any shape."""
    x = np.round(np.random.default_rng(1).normal(0, 10, (300_001, 1)), 4)
    x = x[np.abs(x) < 100]
    assert len(x) > usd_samples.BLOCK * 64
    assert np.array_equal(usd_samples.shortest_decimal(x.astype(np.float32).reshape(-1, 1)).ravel(), x)
