"""USD files: UsdSkel round trips, sparse keys, joint remapping, validation."""

from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, shared_fixtures
from pxr import Usd, UsdGeom, UsdSkel, UsdValidation, Vt

from keyfill import io
from keyfill import rotations as R
from keyfill.errors import FormatError
from keyfill.io import bvh, usd, usd_samples
from keyfill.motion import Keys

FIXTURES = sorted(DATA.glob("*.bvh"))


def validation_errors(path: Path) -> list[str]:
    """Errors of every UsdValidation validator (usd-core 26 replaced UsdUtils.ComplianceChecker)."""
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    errors = context.Validate(Usd.Stage.Open(str(path)))
    return [e.GetMessage() for e in errors if e.GetType() == UsdValidation.ValidationErrorType.Error]


def height(motion) -> float:
    return float(np.ptp(motion.skeleton.rest_world_positions()[:, motion.skeleton.up_axis == "Z" and 2 or 1]))


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usd"])
@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: p.name)
def test_bvh_usd_bvh_keeps_world_positions_and_layout(path, suffix, tmp_path):
    m = bvh.read(path)
    out = tmp_path / ("m" + suffix)
    io.save(m, out)
    back = io.load(out)
    assert back.skeleton.names == m.skeleton.names
    assert back.skeleton.channels == m.skeleton.channels
    assert back.fps == m.fps
    assert np.abs(back.world_positions() - m.world_positions()).max() < 1e-4 * height(m)
    again = bvh.parse(bvh.dumps(back))  # and back to BVH with the same layout
    assert again.skeleton.channels == m.skeleton.channels
    assert np.abs(again.world_positions() - m.world_positions()).max() < 1e-4 * height(m)


def test_shared_fixtures_through_usd(tmp_path):
    for path in shared_fixtures():
        m = bvh.read(path)
        io.save(m, tmp_path / "x.usdc")
        back = io.load(tmp_path / "x.usdc")
        assert np.abs(back.world_positions() - m.world_positions()).max() < 1e-4 * height(m)


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_written_files_pass_usd_validation(tmp_path, suffix):
    m = bvh.read(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")  # names with ':' become identifiers
    out = tmp_path / ("m" + suffix)
    io.save(m, out)
    assert validation_errors(out) == []
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    assert stage.GetTimeCodesPerSecond() == 30
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Root/Skeleton"))
    assert UsdSkel.Topology(skel.GetJointsAttr().Get()).Validate()[0]


@pytest.mark.parametrize(("stem", "prim"), [("walk_filled", "walk_filled"), ("3 walk-fast.v2", "_3_walk_fast_v2")])
def test_the_skel_animation_is_named_after_the_output(tmp_path, stem, prim):
    """Several clips imported into one scene keep their names; a stem that is no identifier is made one."""
    m = bvh.read(DATA / "cmu_02_03_cgspeed_first4frames.bvh")
    out = tmp_path / f"{stem}.usda"
    io.save(m, out)
    stage = Usd.Stage.Open(str(out))
    skel = stage.GetPrimAtPath("/Root/Skeleton")
    assert [str(t) for t in UsdSkel.BindingAPI(skel).GetAnimationSourceRel().GetTargets()] == [
        f"/Root/Skeleton/{prim}"]
    assert io.load(out).num_frames == 4
    usd.write(m, tmp_path / "plain.usda")  # the writer alone, with no name: "Animation"
    assert Usd.Stage.Open(str(tmp_path / "plain.usda")).GetPrimAtPath("/Root/Skeleton/Animation").IsValid()


def test_validation_catches_a_broken_file(tmp_path):
    """The validator used above does find errors (so an empty list means something)."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "bad.usda"))
    UsdSkel.Root.Define(stage, "/Root")
    UsdSkel.Skeleton.Define(stage, "/Root/Skel")  # no SkelBindingAPI, no stage metadata
    stage.GetRootLayer().Save()
    assert validation_errors(tmp_path / "bad.usda") != []


def test_sparse_samples_are_read_as_keys(tmp_path):
    m = bvh.read(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")
    keys = Keys([0, 20, 45, 68])
    out = tmp_path / "keys.usda"
    usd.write(m.replace(keys=keys), out, sparse=True)
    stage = Usd.Stage.Open(str(out))
    # Drop the recorded keys so the reader must infer them from the authored samples.
    custom = dict(stage.GetPrimAtPath("/Root/Skeleton").GetCustomDataByKey("keyfill"))
    del custom["keys"]
    stage.GetPrimAtPath("/Root/Skeleton").SetCustomDataByKey("keyfill", custom)
    stage.GetRootLayer().Save()
    back = io.load(out)
    assert back.num_frames == 69
    assert back.keys.to_list() == [0, 20, 45, 68]
    k = keys.frames
    assert R.quat_angle(back.rotations[k], m.rotations[k]).max() < 1e-6


def test_foreign_joint_order_and_partial_animation_are_remapped(tmp_path):
    """An animation listing joints in another order, and only some of them, maps onto the skeleton."""
    path = tmp_path / "foreign.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(3)
    stage.SetTimeCodesPerSecond(24)
    root = UsdSkel.Root.Define(stage, "/Char")
    stage.SetDefaultPrim(root.GetPrim())
    skel = UsdSkel.Skeleton.Define(stage, "/Char/Skel")
    joints = ["hip", "hip/knee", "hip/knee/ankle"]
    skel.CreateJointsAttr(joints)
    from pxr import Gf

    rest = [Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 0, 1)), Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 0, -0.5)),
            Gf.Matrix4d(1).SetTranslate(Gf.Vec3d(0, 0, -0.4))]
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray(rest))
    anim = UsdSkel.Animation.Define(stage, "/Char/Anim")
    anim.CreateJointsAttr(["hip/knee", "hip"])  # reversed, ankle missing
    quarter = Gf.Quatf(float(np.cos(np.pi / 8)), Gf.Vec3f(float(np.sin(np.pi / 8)), 0, 0))  # 45 deg about x
    for t in (1, 2, 3):
        anim.CreateRotationsAttr().Set(Vt.QuatfArray([quarter, Gf.Quatf(1)]), t)
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(0, 0, -0.5), Gf.Vec3f(t, 0, 1)]), t)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    stage.GetRootLayer().Save()

    m = io.load(path)
    assert m.skeleton.names == ("hip", "knee", "ankle")
    assert m.num_frames == 3 and m.fps == 24 and m.skeleton.up_axis == "Z" and m.skeleton.meters_per_unit == 1
    np.testing.assert_allclose(m.positions[:, 0], [[1, 0, 1], [2, 0, 1], [3, 0, 1]], atol=1e-6)
    assert R.quat_angle(m.rotations[0, 1], R.quat_from_rotvec(np.array([np.pi / 4, 0, 0]))) < 1e-6
    np.testing.assert_allclose(m.positions[:, 2], [[0, 0, -0.4]] * 3, atol=1e-6)  # ankle keeps its rest pose
    # Without a recorded layout: roots get 6 channels, other joints 3 rotation channels.
    assert len(m.skeleton.channels[0]) == 6 and len(m.skeleton.channels[2]) == 3
    assert m.keys is None  # every frame has a sample


def _stage_with(tmp_path, build) -> Path:
    path = tmp_path / "t.usda"
    stage = Usd.Stage.CreateNew(str(path))
    build(stage)
    stage.GetRootLayer().Save()
    return path


def test_file_without_skeleton(tmp_path):
    path = _stage_with(tmp_path, lambda s: UsdGeom.Xform.Define(s, "/World"))
    with pytest.raises(FormatError, match="no UsdSkel Skeleton"):
        io.load(path)


def test_skeleton_without_animation(tmp_path):
    def build(s):
        sk = UsdSkel.Skeleton.Define(s, "/Skel")
        sk.CreateJointsAttr(["a"])
        from pxr import Gf

        sk.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1)]))

    with pytest.raises(FormatError, match="no UsdSkel SkelAnimation"):
        io.load(_stage_with(tmp_path, build))


def test_animation_joints_not_in_skeleton(tmp_path):
    def build(s):
        from pxr import Gf

        sk = UsdSkel.Skeleton.Define(s, "/Skel")
        sk.CreateJointsAttr(["a", "a/b"])
        sk.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1), Gf.Matrix4d(1)]))
        an = UsdSkel.Animation.Define(s, "/Anim")
        an.CreateJointsAttr(["a", "a/zzz"])
        UsdSkel.BindingAPI.Apply(sk.GetPrim()).CreateAnimationSourceRel().SetTargets([an.GetPath()])

    with pytest.raises(FormatError, match="'a/zzz' is not in the Skeleton"):
        io.load(_stage_with(tmp_path, build))


def test_not_a_usd_file(tmp_path):
    p = tmp_path / "junk.usda"
    p.write_text("this is not usd\n")
    with pytest.raises(FormatError, match="not a readable USD file"):
        io.load(p)


# --- values as they came (issue 32) -------------------------------------------------------------------------------


def test_usd_round_trip_writes_the_decimals_that_went_in(tmp_path):
    src = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
    assert "-0.2399 " in src.read_text()
    io.save(io.load(src), tmp_path / "walk.usda")
    text = (tmp_path / "walk.usda").read_text()
    tokens = text.replace(",", " ").replace("(", " ").replace(")", " ").replace("[", " ").replace("]", " ").split()
    assert "-0" not in tokens
    io.save(io.load(tmp_path / "walk.usda"), tmp_path / "back.bvh")
    back = (tmp_path / "back.bvh").read_text()
    assert "-0.2399 " in back and "-0.239899992943" not in back
    assert "-0" not in back.split()
    given, written = bvh.parse_values(src.read_bytes())[2], bvh.parse_values(back.encode())[2]
    pos = [i for i, c in enumerate(c for chans in bvh.read(src).skeleton.channels for c in chans)
           if c.endswith("position")]
    assert np.array_equal(written[:, pos], given[:, pos])  # every translation: the input's own numbers


def test_shortest_decimal_rounds_to_the_stored_float():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.normal(0, 100, 2000), rng.normal(0, 1e-5, 500), [0.0, -0.0, 1e30, -2.5e-30],
                        np.round(rng.normal(0, 100, 500), 4)]).astype(np.float32)
    d = usd_samples.shortest_decimal(x.astype(np.float64))
    assert np.array_equal(d.astype(np.float32), x) and not np.signbit(d[x == 0]).any()
    for a, b in zip(x.tolist(), d.tolist()):  # never longer than Python's shortest repr of the float32
        assert len(repr(b).replace("e-0", "e-").lstrip("-")) <= len(np.format_float_positional(np.float32(a), unique=True, trim="-").lstrip("-")) + 6
    assert usd_samples.shortest_decimal(np.float32([-0.2399])).tolist() == [-0.2399]
