"""USD that keeps the stage (issue 43): a completed or converted USD shot keeps its meshes, materials, skinning,
names and metadata; ``--usd-layer over`` writes the animation alone over the source; ``.usdz`` in and out; what
a glTF's meshes become in USD; the inputs refused."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, one_error_line, run
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, UsdSkel, Vt

from keyfill import io
from keyfill.errors import FormatError, UsageError
from keyfill.io import bvh, usd_stage
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.registry import complete

#: a 1x1 PNG, the shot's texture
PNG = bytes.fromhex("89504e470d0a1a0a0000000d4948445200000001000000010806000000"
                    "1f15c4890000000d49444154789c6360f8cfc0f01f0005000201a2d6d4b10000000049454e44ae426082")
JOINTS = ["Hips", "Hips/Spine", "Hips/Spine/Head", "Hips/LegL", "Hips/LegR"]
OFFSETS = [(0, 0, 1), (0, 0, 0.2), (0, 0, 0.3), (0.1, 0, -0.1), (-0.1, 0, -0.1)]
SKEL, ANIM, MESH = "/root/Armature/Armature", "/root/Armature/Armature/ArmatureAction", "/root/Armature/Body"
MATERIAL, IMAGE = "/root/_materials/Skin", "/root/_materials/Skin/Image"
KEYS = (1, 11, 21)  # time codes: the shot starts at frame 1, as Blender's do


def blender_shot(folder: Path, name: str = "shot.usda") -> Path:
    """A small USD shot laid out as Blender 5 exports one: an Xform root over a SkelRoot with a Skeleton (its
    SkelAnimation below it, keyed at three frames from time code 1), a Mesh skinned to it (skel:skeleton,
    skel:joints, jointIndices / jointWeights, geomBindTransform), a Material with a texture (a relative path)
    bound to the mesh, Z-up metres at 24 fps, customLayerData and a prim's customData."""
    (folder / "textures").mkdir(parents=True, exist_ok=True)
    (folder / "textures" / "skin.png").write_bytes(PNG)
    path = folder / name
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(24)
    stage.SetFramesPerSecond(24)
    stage.SetStartTimeCode(KEYS[0])
    stage.SetEndTimeCode(KEYS[-1])
    stage.GetRootLayer().customLayerData = {"creator": "Blender v5.0.1"}
    root = UsdGeom.Xform.Define(stage, "/root")
    stage.SetDefaultPrim(root.GetPrim())
    root.GetPrim().SetCustomDataByKey("studio", {"shot": "sq010_sh020", "take": 3})
    UsdSkel.Root.Define(stage, "/root/Armature")
    skel = UsdSkel.Skeleton.Define(stage, SKEL)
    skel.CreateJointsAttr(Vt.TokenArray(JOINTS))
    rest = [Gf.Matrix4d(1).SetTranslateOnly(Gf.Vec3d(*o)) for o in OFFSETS]
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray(rest))
    world = []
    for j, p in enumerate(JOINTS):
        world.append(rest[j] * world[JOINTS.index(p.rsplit("/", 1)[0])] if "/" in p else rest[j])
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray(world))
    anim = UsdSkel.Animation.Define(stage, ANIM)
    anim.CreateJointsAttr(Vt.TokenArray(JOINTS))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    anim.CreateScalesAttr().Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * len(JOINTS)))
    for i, t in enumerate(KEYS):
        moved = [Gf.Vec3f(0.1 * i, 0, 1)] + [Gf.Vec3f(*o) for o in OFFSETS[1:]]
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray(moved), t)
        a = 0.3 * i
        turn = [Gf.Quatf(float(np.cos(a / 2)), 0, 0, float(np.sin(a / 2)))]
        bend = [Gf.Quatf(float(np.cos(a / 4)), float(np.sin(a / 4)), 0, 0)] * (len(JOINTS) - 1)
        anim.CreateRotationsAttr().Set(Vt.QuatfArray(turn + bend), t)
    mesh = UsdGeom.Mesh.Define(stage, MESH)
    mesh.CreatePointsAttr([(-0.1, 0, 0.9), (0.1, 0, 0.9), (0.1, 0, 1.5), (-0.1, 0, 1.5)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointsAttr(Vt.TokenArray(JOINTS))
    binding.CreateJointIndicesPrimvar(False, 2).Set(Vt.IntArray([0, 1, 0, 1, 2, 1, 2, 1]))
    binding.CreateJointWeightsPrimvar(False, 2).Set(Vt.FloatArray([0.5] * 8))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1))
    material = UsdShade.Material.Define(stage, MATERIAL)
    surface = UsdShade.Shader.Define(stage, MATERIAL + "/Principled_BSDF")
    surface.CreateIdAttr("UsdPreviewSurface")
    image = UsdShade.Shader.Define(stage, IMAGE)
    image.CreateIdAttr("UsdUVTexture")
    image.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath("./textures/skin.png"))
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(image.ConnectableAPI(), "rgb")
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)
    stage.GetRootLayer().Save()
    return path


@pytest.fixture
def shot(tmp_path) -> Path:
    return blender_shot(tmp_path / "asset")


def joint_samples(path: Path) -> tuple[float, np.ndarray, np.ndarray]:
    """``(start time code, translations (F, J, 3), rotations (F, J, 4) x-y-z-w)``: the composed values of the
    Skeleton's animation at every frame of the stage's time range, as a viewer poses it."""
    stage = Usd.Stage.Open(str(path))
    skel = next(UsdSkel.Skeleton(p) for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    anim = stage.GetPrimAtPath(UsdSkel.BindingAPI(skel.GetPrim()).GetAnimationSourceRel().GetTargets()[0])
    anim = UsdSkel.Animation(anim)
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    times = np.arange(start, end + 1)
    t = np.array([np.asarray(anim.GetTranslationsAttr().Get(x)) for x in times])
    r = np.array([[[q.imaginary[0], q.imaginary[1], q.imaginary[2], q.real] for q in anim.GetRotationsAttr().Get(x)]
                  for x in times])
    assert [str(j) for j in anim.GetJointsAttr().Get()] == [str(j) for j in skel.GetJointsAttr().Get()]
    return start, t, r


def completed(path: Path):
    motion = io.load(path)
    return complete(motion, motion.keys, "cubic", CompleteOptions()).motion


def test_a_completed_shot_keeps_its_stage_and_has_the_completions_samples(capsys, shot, tmp_path):
    code, _, err = run(capsys, "complete", shot, "-o", tmp_path / "filled.usda")
    assert code == 0, err
    assert "note" not in err
    io.save(completed(shot), tmp_path / "fresh.usda")  # the same completion into a new file
    stage = Usd.Stage.Open(str(tmp_path / "filled.usda"))
    source = Usd.Stage.Open(str(shot))
    # every prim of the source, same names, types and hierarchy, and no other
    assert [(str(p.GetPath()), p.GetTypeName()) for p in stage.Traverse()] == \
           [(str(p.GetPath()), p.GetTypeName()) for p in source.Traverse()]
    mesh = stage.GetPrimAtPath(MESH)
    assert mesh.IsA(UsdGeom.Mesh) and len(UsdGeom.Mesh(mesh).GetPointsAttr().Get()) == 4
    binding = UsdSkel.BindingAPI(mesh)
    assert binding.GetSkeletonRel().GetTargets() == [Sdf.Path(SKEL)]
    assert list(binding.GetJointIndicesPrimvar().Get()) == [0, 1, 0, 1, 2, 1, 2, 1]
    assert list(binding.GetJointWeightsPrimvar().Get()) == [0.5] * 8 and binding.GetJointIndicesPrimvar().GetElementSize() == 2
    assert [str(j) for j in binding.GetJointsAttr().Get()] == JOINTS
    bound, _ = UsdShade.MaterialBindingAPI(mesh).ComputeBoundMaterial()
    assert bound.GetPath() == Sdf.Path(MATERIAL)
    texture = stage.GetPrimAtPath(IMAGE).GetAttribute("inputs:file").Get()
    assert Path(texture.resolvedPath) == (shot.parent / "textures" / "skin.png").resolve()  # from another folder
    assert stage.GetRootLayer().customLayerData == {"creator": "Blender v5.0.1"}
    assert stage.GetPrimAtPath("/root").GetCustomDataByKey("studio") == {"shot": "sq010_sh020", "take": 3}
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/root")
    # the joint samples are the completion's, from the shot's own first frame
    start, t, r = joint_samples(tmp_path / "filled.usda")
    fresh_start, ft, fr = joint_samples(tmp_path / "fresh.usda")
    assert (start, fresh_start, stage.GetEndTimeCode(), stage.GetTimeCodesPerSecond()) == (1, 0, 21, 24)
    assert len(t) == 21 and np.array_equal(t, ft) and np.array_equal(r, fr)
    assert not np.array_equal(r[1], r[0])  # in-betweens, not the keys held
    # and it reads back as the same motion as the new file does
    back, fresh = io.load(tmp_path / "filled.usda"), io.load(tmp_path / "fresh.usda")
    assert back.skeleton.difference(fresh.skeleton) is None and back.keys.to_list() == fresh.keys.to_list()
    assert np.array_equal(back.positions, fresh.positions) and np.array_equal(back.rotations, fresh.rotations)


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usdz"])
def test_the_layer_over_the_source_composes_to_the_same_samples(capsys, shot, tmp_path, suffix):
    out = tmp_path / "anim" / ("shot_anim" + suffix)
    out.parent.mkdir()
    code, _, err = run(capsys, "complete", shot, "--usd-layer", "over", "-o", out)
    assert code == 0, err
    run(capsys, "complete", shot, "-o", tmp_path / "kept.usda")
    stage = Usd.Stage.Open(str(out))
    assert stage.GetPrimAtPath(MESH).IsA(UsdGeom.Mesh) and stage.GetDefaultPrim().GetPath() == Sdf.Path("/root")
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    start, t, r = joint_samples(out)
    kept = joint_samples(tmp_path / "kept.usda")
    assert start == kept[0] and np.array_equal(t, kept[1]) and np.array_equal(r, kept[2])
    if suffix == ".usdz":  # the package carries the source it sublayers
        return
    layer = Sdf.Layer.FindOrOpen(str(out))
    assert list(layer.subLayerPaths) == ["../asset/shot.usda"]  # relative to the output's folder
    specs = []
    layer.Traverse(Sdf.Path.absoluteRootPath, lambda p: specs.append(p) if p.IsPrimPath() else None)
    assert sorted(map(str, specs)) == ["/root", "/root/Armature", SKEL, ANIM]  # the animation alone
    assert all(layer.GetPrimAtPath(p).specifier == Sdf.SpecifierOver for p in specs)


def test_convert_keeps_the_stage_and_the_library_says_usd_layer(shot, tmp_path):
    motion = io.load(shot)
    io.save(motion, tmp_path / "same.usdc", source=shot)
    stage = Usd.Stage.Open(str(tmp_path / "same.usdc"))
    assert stage.GetPrimAtPath(MESH).IsA(UsdGeom.Mesh)
    assert stage.GetPrimAtPath(ANIM).IsA(UsdSkel.Animation)  # its own name, not the output's stem
    io.save(motion, tmp_path / "new.usda", source=shot, usd_layer="new")  # the skeleton and animation alone
    back, new = io.load(tmp_path / "same.usdc"), io.load(tmp_path / "new.usda")
    assert np.array_equal(back.positions, new.positions) and np.array_equal(back.rotations, new.rotations)
    assert back.keys.to_list() == [0, 10, 20] and np.abs(back.positions - motion.positions).max() < 1e-7
    stage = Usd.Stage.Open(str(tmp_path / "new.usda"))
    assert [str(p.GetPath()) for p in stage.Traverse()] == ["/Root", "/Root/Skeleton", "/Root/Skeleton/new"]
    with pytest.raises(UsageError, match="usd_layer must be one of stage, over, new"):
        io.save(motion, tmp_path / "x.usda", source=shot, usd_layer="flat")
    assert not (tmp_path / "x.usda").exists()


def test_asset_paths_stay_as_they_were_beside_the_source(shot):
    out = shot.parent / "filled.usda"
    io.save(completed(shot), out, source=shot)
    assert Usd.Stage.Open(str(out)).GetPrimAtPath(IMAGE).GetAttribute("inputs:file").Get().path == "./textures/skin.png"


def test_usdz_round_trip_is_lossless_as_usdc(tmp_path):
    m = bvh.read(DATA / "edge_layouts_crlf.bvh")
    io.save(m, tmp_path / "m.usdz")
    io.save(m, tmp_path / "m.usdc")
    assert Sdf.ZipFile.Open(str(tmp_path / "m.usdz")).GetFileNames() == ["m.usdc"]
    z, c = io.load(tmp_path / "m.usdz"), io.load(tmp_path / "m.usdc")
    assert z.skeleton.difference(c.skeleton) is None and z.skeleton.channels == c.skeleton.channels
    assert np.array_equal(z.rotations, c.rotations) and np.array_equal(z.positions, c.positions)
    assert z.fps == c.fps and z.keys == c.keys
    io.save(z, tmp_path / "again.usdz", source=tmp_path / "m.usdz")  # usdz -> usdz keeps the stage, the same bytes
    again = io.load(tmp_path / "again.usdz")
    assert np.array_equal(again.rotations, c.rotations) and np.array_equal(again.positions, c.positions)
    assert io.sniff((tmp_path / "m.usdz").read_bytes()[:16]) == "usdz"


def test_a_usdz_of_a_kept_shot_carries_its_texture_and_reads_back(capsys, shot, tmp_path):
    code, _, err = run(capsys, "complete", shot, "-o", tmp_path / "filled.usdz")
    assert code == 0, err
    names = Sdf.ZipFile.Open(str(tmp_path / "filled.usdz")).GetFileNames()
    assert names[0] == "filled.usdc" and any(n.endswith("skin.png") for n in names)
    stage = Usd.Stage.Open(str(tmp_path / "filled.usdz"))
    texture = stage.GetPrimAtPath(IMAGE).GetAttribute("inputs:file").Get()
    assert texture.resolvedPath.startswith(str(tmp_path / "filled.usdz") + "[")  # inside the package
    (tmp_path / "out").mkdir()
    code, _, err = run(capsys, "convert", tmp_path / "filled.usdz", tmp_path / "out" / "again.usda")
    assert code == 0, err
    stage = Usd.Stage.Open(str(tmp_path / "out" / "again.usda"))
    texture = stage.GetPrimAtPath(IMAGE).GetAttribute("inputs:file").Get()
    assert texture.path.startswith("../filled.usdz[") and texture.resolvedPath  # into the package, from out/
    assert np.array_equal(joint_samples(tmp_path / "out" / "again.usda")[2], joint_samples(tmp_path / "filled.usdz")[2])


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usdz"])
@pytest.mark.parametrize("layer", ["stage", "over"])
def test_the_same_input_gives_the_same_bytes(shot, tmp_path, suffix, layer):
    motion = completed(shot)
    written = []
    for n in range(2):
        out = tmp_path / str(n) / ("filled" + suffix)
        out.parent.mkdir()
        io.save(motion, out, source=shot, usd_layer=layer)
        written.append(out.read_bytes())
    assert written[0] == written[1]


def _write_zip(path: Path, files: dict) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        for name, data in files.items():
            z.writestr(name, data)
    return path


@pytest.mark.parametrize("content, why", [
    ({"skin.png": PNG}, "without a USD layer first (its first file is 'skin.png'"),
    ({}, "a .usdz package with no files"),
    (None, "not a .usdz package (not a zip archive)"),
])
def test_a_usdz_without_a_layer_is_one_error_line(capsys, tmp_path, content, why):
    bad = tmp_path / "bad.usdz"
    if content is None:
        bad.write_text("#usda 1.0\n")
    else:
        _write_zip(bad, content)
    for args in (("convert", bad, tmp_path / "out.usda"), ("complete", bad, "-o", tmp_path / "out.usda"),
                 ("info", bad)):
        code, _, err = run(capsys, *args)
        assert code == 1 and why in one_error_line(err) and str(bad) in err
    assert not list(tmp_path.glob("out*")) and sorted(p.name for p in tmp_path.iterdir()) == ["bad.usdz"]
    with pytest.raises(FormatError):
        io.load(bad)


def test_a_motion_of_another_skeleton_cannot_keep_the_stage(shot, tmp_path):
    other = bvh.read(DATA / "edge_layouts_crlf.bvh")
    with pytest.raises(UsageError, match="its Skeleton's joints are not those of the motion") as e:
        io.save(other, tmp_path / "x.usda", source=shot)
    assert e.value.params == ("usd_layer",)
    assert not list(tmp_path.glob("x*")) and not list(tmp_path.glob(".x*"))
    renamed = completed(shot)
    renamed = renamed.replace(skeleton=renamed.skeleton.replace(names=("Hips", "Spine", "Neck", "LegL", "LegR")))
    with pytest.raises(UsageError, match="not those of the motion"):
        io.save(renamed, tmp_path / "x.usdz", source=shot, usd_layer="over")
    assert not list(tmp_path.glob("x*"))
    io.save(other, tmp_path / "x.usda", source=shot, usd_layer="new")  # what the message offers works
    assert io.load(tmp_path / "x.usda").skeleton.names == other.skeleton.names


@pytest.mark.parametrize("args, why", [
    (("convert", DATA / "edge_layouts_crlf.bvh", "{out}/x.usda", "--usd-layer", "over"),
     "--usd-layer over writes a layer over the USD file read"),
    (("convert", "{shot}", "{out}/x.bvh", "--usd-layer", "stage"), "--usd-layer chooses what a USD output keeps"),
    (("complete", "{shot}", "-o", "{out}/x.glb", "--usd-layer", "new"), "--usd-layer chooses"),
    (("complete", "{shot}", "{shot}", "-o", "{out}/x/", "--usd-layer", "over"), "--usd-layer takes one input file and one output, not a batch"),
    (("convert", "{shot}", "-o", "{out}/x/", "--usd-layer", "over"), "--usd-layer takes one input file and one output"),
])
def test_usd_layer_where_it_cannot_apply_is_one_error_line(capsys, shot, tmp_path, args, why):
    out = tmp_path / "o"
    out.mkdir()
    args = [str(a).format(shot=shot, out=out) for a in args]
    code, _, err = run(capsys, *args)
    assert code == 2 and why in one_error_line(err)
    assert not list(out.iterdir())


def test_a_gltf_with_a_mesh_into_usd_says_once_what_is_not_carried(capsys, tmp_path):
    from test_gltf import character, write_glb

    char = write_glb(tmp_path / "char.glb", *character()[:2])
    bare = write_glb(tmp_path / "bare.glb", *character(mesh=False)[:2])
    code, _, err = run(capsys, "convert", char, tmp_path / "char.usda")
    assert code == 0, err
    notes = [line for line in err.splitlines() if line.startswith("keyfill: note:")]
    assert notes == [("keyfill: note: char.glb: its 1 mesh and 1 material are not carried into USD (only the "
                      "skeleton and its animation are)")]
    code, _, err = run(capsys, "complete", char, "--keys", "0,4", "-o", tmp_path / "filled.usdz")
    assert code == 0 and err.count("keyfill: note:") == 1 and "into USD" in err
    code, _, err = run(capsys, "convert", bare, tmp_path / "bare.usda")  # nothing to lose: nothing said
    assert code == 0 and "note" not in err
    code, _, err = run(capsys, "convert", char, tmp_path / "char2.glb")  # kept: nothing said
    assert code == 0 and "note" not in err
    code, _, err = run(capsys, "convert", DATA / "edge_layouts_crlf.bvh", tmp_path / "edges.usda")
    assert code == 0 and "note" not in err


def test_standard_output_writes_the_kept_stages_asset_paths_absolute(capsys, shot, tmp_path):
    code, out, err = run(capsys, "convert", shot, "-", "--format", "usda")
    assert code == 0, err
    assert f"@{(shot.parent / 'textures' / 'skin.png').resolve()}@" in out


def test_a_stage_with_a_subset_animation_and_sampled_scales_gets_every_joint(tmp_path):
    """An animation of some joints in another order, scales with samples: the output animates the Skeleton's
    joints in its order, scales one default."""
    shot = blender_shot(tmp_path)
    stage = Usd.Stage.Open(str(shot))
    anim = UsdSkel.Animation(stage.GetPrimAtPath(ANIM))
    order = [4, 0, 1]
    anim.GetJointsAttr().Set(Vt.TokenArray([JOINTS[j] for j in order]))
    for attr in (anim.GetTranslationsAttr(), anim.GetRotationsAttr()):
        for t in attr.GetTimeSamples():
            attr.Set(type(attr.Get(t))([attr.Get(t)[j] for j in order]), t)
    anim.GetScalesAttr().Clear()
    for t in KEYS:
        anim.GetScalesAttr().Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * 3), t)
    stage.Save()
    motion = completed(shot)
    io.save(motion, tmp_path / "filled.usda", source=shot)
    written = Usd.Stage.Open(str(tmp_path / "filled.usda"))
    out = UsdSkel.Animation(written.GetPrimAtPath(ANIM))
    assert [str(j) for j in out.GetJointsAttr().Get()] == JOINTS
    assert out.GetScalesAttr().GetNumTimeSamples() == 0 and len(out.GetScalesAttr().Get()) == len(JOINTS)
    back = io.load(tmp_path / "filled.usda")
    assert np.array_equal(back.rotations, io.load(_fresh(motion, tmp_path)).rotations)


def _fresh(motion, tmp_path) -> Path:
    io.save(motion, tmp_path / "fresh.usda")
    return tmp_path / "fresh.usda"


def test_check_layer_and_a_package_name():
    usd_stage.check_layer("stage", None)
    with pytest.raises(UsageError, match="usd_layer over writes the animation as a layer over"):
        usd_stage.check_layer("over", None)


@pytest.mark.interop
@pytest.mark.parametrize("layer", ["stage", "over"])
def test_blender_imports_the_kept_stage_with_its_mesh_material_and_animation(capsys, shot, tmp_path, layer):
    """Blender 5.0.1 (``.venv-blender``, ``make test-interop``) imports the completed shot: the skinned mesh with
    its material and armature modifier, the five bones, the frames 1-21, and bone heads where keyfill puts the
    joints."""
    import json
    import subprocess
    import sys

    sys.path.insert(0, str(Path(__file__).parent / "interop"))
    from blender_check import BLENDER_PYTHON, blender_missing

    why = blender_missing()
    if why:
        pytest.skip(why)
    out = tmp_path / "filled.usda"
    assert run(capsys, "complete", shot, "--usd-layer", layer, "-o", out)[0] == 0
    script = Path(__file__).parent / "interop" / "blender_usd_stage.py"
    proc = subprocess.run([str(BLENDER_PYTHON), str(script), str(out)], capture_output=True, text=True,
                          timeout=300, check=True)
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["meshes"] == {"Body": {"materials": ["Skin"], "armature": "Armature",
                                      "groups": ["Hips", "Spine", "Head"]}}
    assert got["armatures"] == {"Armature": ["Hips", "Spine", "Head", "LegL", "LegR"]} and got["frames"] == [1, 21]
    world = io.load(out).world_positions()
    for frame, heads in got["heads"].items():
        assert np.abs(np.array(heads) - world[int(frame) - 1]).max() < 1e-6


# --- long takes: the template opened before the motion is read (issue 44) ----------------------------------


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
@pytest.mark.parametrize("source_suffix", [".usda", ".usdc"])
def test_a_template_opened_before_reading_writes_the_bytes_of_the_source_path(shot, tmp_path, suffix, source_suffix):
    source = shot if source_suffix == ".usda" else shot.with_suffix(".usdc")
    if source != shot:
        Sdf.Layer.FindOrOpen(str(shot)).Export(str(source))
    template = usd_stage.template_for(source, suffix.lstrip("."), None)
    assert isinstance(template, usd_stage.Template) and not template.used
    motion = completed(source)
    by_path, by_template = tmp_path / ("by_path" + suffix), tmp_path / ("by_template" + suffix)
    io.save(motion, by_path, source=source)
    io.save(motion, by_template, source=source, template=template)
    assert template.used
    assert by_template.read_bytes() == by_path.read_bytes()
    again = tmp_path / ("again" + suffix)  # a used template is not written into twice: the file is opened again
    io.save(motion, again, source=source, template=template)
    assert again.read_bytes() == by_path.read_bytes()


def test_the_template_holds_none_of_the_sources_joint_samples(shot):
    template = usd_stage.open_template(shot)
    anim = template.layer.GetPrimAtPath(ANIM)
    for name in ("translations", "rotations"):
        assert anim.attributes[name].GetInfo("timeSamples") == {}  # dropped at once: a long take's are large
    assert Usd.Stage.Open(str(shot)).GetPrimAtPath(ANIM).GetAttribute("rotations").GetNumTimeSamples() == len(KEYS)
    assert template.start == KEYS[0] and template.names == [j.rsplit("/", 1)[-1] for j in JOINTS]


@pytest.mark.parametrize("case", ["bvh source", "bvh output", "over", "new", "standard input", "not USD"])
def test_template_for_opens_only_a_stage_the_output_keeps(shot, tmp_path, case):
    source, output, layer = shot, "usdc", None
    if case == "bvh source":
        source = tmp_path / "clip.bvh"
        bvh.write(completed(shot), source)
    elif case == "bvh output":
        output = "bvh"
    elif case in ("over", "new"):
        layer = case
    elif case == "standard input":
        source = "-"
    else:  # a .usda that is not USD: the reader's own error is the one the user gets
        source = tmp_path / "broken.usda"
        source.write_text("#usda 1.0\n(\n")
    assert usd_stage.template_for(source, output, layer) is None


def test_a_template_checks_the_layers_it_composes_as_the_reader_does(shot):
    import os

    fifo = shot.parent / "fifo.usda"
    os.mkfifo(fifo)
    layer = Sdf.Layer.FindOrOpen(str(shot))
    layer.subLayerPaths.append("./fifo.usda")
    layer.Save()
    with pytest.raises(FormatError, match="not a regular file"):  # refused, never opened (a pipe would hang)
        usd_stage.open_template(shot)
    assert usd_stage.template_for(shot, "usda", None) is None
