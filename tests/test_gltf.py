"""glTF 2.0 in and out (issue 28): round trips, the mapping against hand-built files, the CLI, bad input.

Hand-built files are made here with numpy and struct only (:func:`glb`), so
the reader is checked against glTF's own rule for a node's world transform
(parent matrix @ T @ R @ S), not against keyfill's writer.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import BVH_FIXTURES, DATA, one_error_line, run, shared_path

from keyfill import io
from keyfill.errors import DataError, FormatError
from keyfill.motion import Keys

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
LOCAL = sorted(DATA.glob("*.bvh"))
SHARED = sorted(p.name for p in BVH_FIXTURES.glob("*.bvh")) or ["(absent)"]
#: the issue's bound for BVH -> glTF -> BVH, relative to the skeleton's height
TOL = 1e-6
VALIDATOR = Path(os.environ.get("KEYFILL_GLTF_VALIDATOR", Path(__file__).parents[1] / ".venv-gltf-validator"))



def height(motion) -> float:
    return float(np.ptp(motion.skeleton.rest_world_positions()[:, 1]))


# --- hand-built files ---------------------------------------------------------------------------


class Blob:
    """Accessors over one binary buffer, for hand-built files."""

    def __init__(self):
        self.data, self.views, self.accessors = bytearray(), [], []

    def add(self, array, kind: str, component: int = 5126, bounds: bool = False) -> int:
        dtype = {5126: "<f4", 5121: "<u1", 5123: "<u2"}[component]
        a = np.ascontiguousarray(array, dtype=dtype)
        self.data += b"\0" * (-len(self.data) % 4)
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": a.nbytes})
        self.data += a.tobytes()
        acc = {"bufferView": len(self.views) - 1, "componentType": component, "count": len(a), "type": kind}
        if bounds:
            acc.update(min=[float(v) for v in a.reshape(len(a), -1).min(0)],
                       max=[float(v) for v in a.reshape(len(a), -1).max(0)])
        self.accessors.append(acc)
        return len(self.accessors) - 1


def glb(doc: dict, binary: bytes) -> bytes:
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary = bytes(binary) + b"\0" * (-len(binary) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def unglb(data: bytes) -> tuple[dict, bytes]:
    n = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20: 20 + n])
    m = struct.unpack_from("<I", data, 20 + n)[0]
    return doc, data[28 + n: 28 + n + m]


def quat_xyzw(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return [*(axis * math.sin(angle / 2)), math.cos(angle / 2)]


def trs(t=(0, 0, 0), r=(0, 0, 0, 1), s=(1, 1, 1)) -> np.ndarray:
    x, y, z, w = r
    rot = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                    [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                    [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    m = np.eye(4)
    m[:3, :3] = rot * np.asarray(s)
    m[:3, 3] = t
    return m


#: the hand-built rig: an Armature node (Blender's 0.01 scale and a turn) above Hips -> Spine -> Head, in cm
ARMATURE = {"translation": [0.0, 0.5, 0.2], "rotation": quat_xyzw([1, 0, 0], math.pi / 2), "scale": [0.01] * 3}
REST = {"Hips": ([0, 100, 0], [0, 0, 0, 1]), "Spine": ([0, 20, 0], quat_xyzw([0, 0, 1], 0.1)),
        "Head": ([0, 30, 5], [0, 0, 0, 1])}
FRAMES = 5


def character(interpolation: str = "LINEAR", times=None, mesh: bool = True, armature: bool = True):
    """``(json, binary, world positions (samples, 3 joints, 3) in metres)`` of the hand-built rig.

    ``armature``: the joints sit under the Armature node (else they are the scene's roots, in metres).
    """
    blob = Blob()
    times = np.arange(FRAMES) / 30.0 if times is None else np.asarray(times)
    k = len(times)
    hips_t = np.array([[0.0, 100 + 2 * i, 3.0 * i] for i in range(k)])
    hips_r = np.array([quat_xyzw([0, 1, 0], 0.2 * i) for i in range(k)])
    spine_r = np.array([quat_xyzw([1, 0, 0], 0.1 + 0.05 * i) for i in range(k)])
    nodes = [{"name": "Armature", **(ARMATURE if armature else {}), "children": [1]},
             {"name": "Hips", "translation": REST["Hips"][0], "children": [2]},
             {"name": "Spine", "translation": REST["Spine"][0], "rotation": REST["Spine"][1], "children": [3]},
             {"name": "Head", "translation": REST["Head"][0]}]
    inp = blob.add(times[:, None], "SCALAR", bounds=True)

    def out(values):
        if interpolation != "CUBICSPLINE":
            return blob.add(values, "VEC3" if values.shape[1] == 3 else "VEC4")
        zero = np.zeros_like(values)
        return blob.add(np.stack([zero, values, zero], 1).reshape(-1, values.shape[1]),
                        "VEC3" if values.shape[1] == 3 else "VEC4")

    samplers = [{"input": inp, "output": out(v), "interpolation": interpolation} for v in (hips_t, hips_r, spine_r)]
    channels = [{"sampler": 0, "target": {"node": 1, "path": "translation"}},
                {"sampler": 1, "target": {"node": 1, "path": "rotation"}},
                {"sampler": 2, "target": {"node": 2, "path": "rotation"}}]
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 4] if mesh else [0]}], "nodes": nodes,
           "skins": [{"joints": [1, 2, 3], "name": "Rig"}],
           "animations": [{"name": "Walk", "samplers": samplers, "channels": channels}]}
    if mesh:
        pos = blob.add([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], "VEC3", bounds=True)
        joints = blob.add([[0, 0, 0, 0], [0, 1, 0, 0], [2, 0, 0, 0]], "VEC4", component=5121)
        weights = blob.add([[1, 0, 0, 0], [0.5, 0.5, 0, 0], [1, 0, 0, 0]], "VEC4")
        indices = blob.add([0, 1, 2], "SCALAR", component=5123)
        for view, target in zip(blob.views[-4:], (34962, 34962, 34962, 34963)):
            view["target"] = target
        ibm = np.tile(np.eye(4).T.reshape(16), (3, 1))
        doc["skins"][0]["inverseBindMatrices"] = blob.add(ibm, "MAT4")
        nodes.append({"name": "Body", "mesh": 0, "skin": 0})
        doc["meshes"] = [{"name": "Body", "primitives": [{"attributes": {"POSITION": pos, "JOINTS_0": joints,
                                                                          "WEIGHTS_0": weights},
                                                           "indices": indices, "material": 0}]}]
        doc["materials"] = [{"name": "Skin", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.6, 0.5, 1]}}]
    doc["bufferViews"], doc["accessors"] = blob.views, blob.accessors
    doc["buffers"] = [{"byteLength": len(blob.data)}]
    arm = trs(ARMATURE["translation"], ARMATURE["rotation"], ARMATURE["scale"]) if armature else np.eye(4)
    world = []
    for f in range(k):  # at the sample times (the frames, unless a test moves them)
        hips = arm @ trs(hips_t[f], hips_r[f])
        spine = hips @ trs(REST["Spine"][0], spine_r[f])
        head = spine @ trs(REST["Head"][0])
        world.append([hips[:3, 3], spine[:3, 3], head[:3, 3]])
    return doc, bytes(blob.data), np.array(world)


def write_glb(path: Path, doc: dict, binary: bytes) -> Path:
    path.write_bytes(glb(doc, binary))
    return path


# --- round trips -----------------------------------------------------------------------------------


def _check_round_trip(path: Path, tmp_path: Path, suffix: str):
    motion = io.load(path)
    io.save(motion, tmp_path / ("out" + suffix))
    back = io.load(tmp_path / ("out" + suffix))
    sk, bk = motion.skeleton, back.skeleton
    assert bk.names == sk.names and np.array_equal(bk.parents, sk.parents) and bk.channels == sk.channels
    assert bk.euler_orders == sk.euler_orders and bk.up_axis == sk.up_axis
    assert bk.meters_per_unit == sk.meters_per_unit and back.fps == motion.fps
    assert len(bk.end_sites) == len(sk.end_sites)
    assert all(a == b and np.array_equal(x, y) for (a, x), (b, y) in zip(bk.end_sites, sk.end_sites))
    assert np.abs(bk.offsets - sk.offsets).max() <= 1e-12 * max(1.0, np.abs(sk.offsets).max())
    assert back.num_frames == motion.num_frames
    assert np.abs(back.world_positions() - motion.world_positions()).max() < TOL * height(motion)
    # BVH -> glTF -> BVH with --bvh-layout source: the same layout (every line the same words, numbers aside)
    io.save(back, tmp_path / "back.bvh", bvh_layout="source")
    words = [[w for w in line.split() if not w.lstrip("-").replace(".", "").replace("e", "").isdigit()]
             for line in path.read_text().splitlines() if line.strip()]
    again = [[w for w in line.split() if not w.lstrip("-").replace(".", "").replace("e", "").isdigit()]
             for line in (tmp_path / "back.bvh").read_text().splitlines() if line.strip()]
    assert again[: len(again) - motion.num_frames] == words[: len(words) - motion.num_frames]


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
@pytest.mark.parametrize("path", LOCAL, ids=lambda p: p.name)
def test_bvh_gltf_bvh_round_trip_of_the_local_fixtures(path, suffix, tmp_path):
    _check_round_trip(path, tmp_path, suffix)


@pytest.mark.parametrize("name", SHARED)
def test_bvh_gltf_bvh_round_trip_of_the_shared_fixtures(name, tmp_path):
    _check_round_trip(shared_path("bvh_fixtures", name), tmp_path, ".glb")


def test_units_and_up_axis_are_converted_and_recorded(tmp_path):
    """A Z-up motion in cm is metres and Y-up inside the file, and reads back as it was."""
    motion = io.load(MIXAMO)
    z_up = motion.replace(skeleton=motion.skeleton.replace(up_axis="Z"))
    io.save(z_up, tmp_path / "z.glb")
    doc, _ = unglb((tmp_path / "z.glb").read_bytes())
    assert doc["skins"][0]["extras"]["keyfill"]["upAxis"] == "Z"
    assert doc["skins"][0]["extras"]["keyfill"]["metersPerUnit"] == 0.01
    hips = np.array(doc["nodes"][0]["translation"])  # the root's rest offset, turned Z-up -> Y-up, in metres
    x, y, z = motion.skeleton.offsets[0] * 0.01
    assert np.allclose(hips, [x, z, -y], atol=1e-12)
    back = io.load(tmp_path / "z.glb")
    assert back.skeleton.up_axis == "Z"
    assert np.abs(back.world_positions() - z_up.world_positions()).max() < TOL * height(motion)
    # without keyfill's extras, the same file is read as glTF says: metres, Y-up
    for skin in doc["skins"]:
        skin.pop("extras")
    (tmp_path / "plain.glb").write_bytes(glb(doc, unglb((tmp_path / "z.glb").read_bytes())[1]))
    plain = io.load(tmp_path / "plain.glb")
    assert plain.skeleton.meters_per_unit == 1.0 and plain.skeleton.up_axis == "Y"
    world = z_up.world_positions() * 0.01
    expected = np.stack([world[..., 0], world[..., 2], -world[..., 1]], axis=-1)
    assert np.abs(plain.world_positions() - expected).max() < 1e-6 * height(plain)


def test_keys_and_partial_keys_survive(tmp_path):
    motion = io.load(MIXAMO)
    mask = np.zeros((3, motion.num_joints), dtype=bool)
    mask[:, 0] = True
    keyed = motion.replace(keys=Keys(np.array([0, 30, 68]), mask, "position"))
    io.save(keyed, tmp_path / "k.gltf")
    back = io.load(tmp_path / "k.gltf")
    assert back.keys.to_list() == [0, 30, 68] and back.keys.given == "position"
    assert np.array_equal(back.keys.mask, mask)


# --- reading other files -------------------------------------------------------------------------


def test_a_hand_built_rig_under_an_armature_node(tmp_path):
    """Nodes above the roots (scale 0.01 and a turn) are folded in; world positions are glTF's, in metres."""
    doc, binary, world = character()
    m = io.load(write_glb(tmp_path / "c.glb", doc, binary))
    assert m.skeleton.names == ("Hips", "Spine", "Head") and m.num_frames == FRAMES and m.fps == 30.0
    assert m.skeleton.meters_per_unit == pytest.approx(0.01) and m.skeleton.up_axis == "Y"
    assert np.abs(m.world_positions() * m.skeleton.meters_per_unit - world).max() < 1e-7
    assert m.keys is None  # a sample on every frame


@pytest.mark.parametrize("interpolation", ["LINEAR", "STEP", "CUBICSPLINE"])
def test_samplers_off_the_frame_grid_are_resampled(tmp_path, interpolation):
    """Samples at 0, 1.5 and 3 frames (of a 30 fps grid set by another channel) give glTF's values at the frames."""
    doc, binary, _ = character(interpolation=interpolation, times=np.array([0, 1.5, 3]) / 30, armature=False)
    blob = Blob()
    blob.data = bytearray(binary)
    blob.views, blob.accessors = doc["bufferViews"], doc["accessors"]
    grid = blob.add(np.arange(FRAMES)[:, None] / 30.0, "SCALAR", bounds=True)
    still = blob.add(np.tile(REST["Head"][1], (FRAMES, 1)), "VEC4")
    doc["animations"][0]["samplers"].append({"input": grid, "output": still})
    doc["animations"][0]["channels"].append({"sampler": 3, "target": {"node": 3, "path": "rotation"}})
    doc["buffers"] = [{"byteLength": len(blob.data)}]
    m = io.load(write_glb(tmp_path / "c.glb", doc, bytes(blob.data)))
    assert m.fps == 30.0 and m.num_frames == FRAMES
    hips_y = m.positions[:, 0, 1]  # samples 100, 102, 104 cm at frames 0, 1.5, 3
    expected = {"LINEAR": [100, 100 + 4 / 3, 100 + 8 / 3, 104, 104], "STEP": [100, 100, 102, 104, 104],
                # Hermite with zero tangents: smoothstep between samples
                "CUBICSPLINE": [100, 100 + 2 * (3 * (2 / 3) ** 2 - 2 * (2 / 3) ** 3),
                                102 + 2 * (3 * (1 / 3) ** 2 - 2 * (1 / 3) ** 3), 104, 104]}[interpolation]
    assert np.allclose(hips_y, expected, atol=1e-5)


def test_several_skins_and_animations_read_the_first_and_say_so(capsys, tmp_path):
    doc, binary, _ = character(mesh=False)
    doc["skins"].append({"joints": [2, 3], "name": "Upper"})
    doc["animations"].append(dict(doc["animations"][0], name="Run"))
    path = write_glb(tmp_path / "two.glb", doc, binary)
    code, out, err = run(capsys, "info", path, "--json")
    assert code == 0 and json.loads(out)["joints"] == 3
    notes = err.strip().splitlines()
    assert notes == [f"keyfill: note: {path}: 2 skins; reading the first ('Rig')",
                     f"keyfill: note: {path}: 2 animations; reading the first ('Walk')"]
    from keyfill.io import gltf

    assert gltf.read(path, skin="Upper").skeleton.names == ("Spine", "Head")
    with pytest.raises(FormatError, match="no animation 'Jump'; the file has 'Walk', 'Run'"):
        gltf.read(path, animation="Jump")


# --- the command line -------------------------------------------------------------------------------


def test_cli_convert_info_complete_on_glb(capsys, tmp_path):
    glb_path = tmp_path / "walk.glb"
    code, _, err = run(capsys, "convert", MIXAMO, glb_path)
    assert code == 0 and "wrote" in err
    code, out, _ = run(capsys, "info", glb_path, "--json")
    info = json.loads(out)
    assert code == 0 and (info["frames"], info["fps"], info["joints"]) == (69, 30.0, 55)
    assert info["meters_per_unit"] == 0.01 and info["hierarchy"][0]["channels"][0] == "Xposition"
    code, _, err = run(capsys, "complete", glb_path, "--key-every", "10", "-o", tmp_path / "filled.glb")
    assert code == 0, err
    filled, source = io.load(tmp_path / "filled.glb"), io.load(glb_path)
    assert filled.keys.to_list() == [0, 10, 20, 30, 40, 50, 60, 68]
    keys = filled.keys.frames
    assert np.abs(filled.world_positions()[keys] - source.world_positions()[keys]).max() < 1e-4


def test_complete_keeps_the_mesh_of_a_character(capsys, tmp_path):
    """`keyfill complete char.gltf -o filled.glb`: meshes, materials and the texture survive, embedded."""
    doc, binary, _ = character()
    (tmp_path / "char.bin").write_bytes(binary)
    (tmp_path / "skin.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(16))
    doc["buffers"] = [{"uri": "char.bin", "byteLength": len(binary)}]
    doc["images"] = [{"uri": "skin.png"}]
    doc["textures"] = [{"source": 0}]
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    (tmp_path / "char.gltf").write_text(json.dumps(doc))
    code, _, err = run(capsys, "complete", tmp_path / "char.gltf", "--keys", "0,4", "-o", tmp_path / "filled.glb")
    assert code == 0, err
    out, data = unglb((tmp_path / "filled.glb").read_bytes())
    assert [n["name"] for n in out["nodes"]] == ["Armature", "Hips", "Spine", "Head", "Body"]
    assert out["meshes"][0]["name"] == "Body" and out["materials"][0]["name"] == "Skin"
    assert len(out["buffers"]) == 1 and "uri" not in out["buffers"][0] and "uri" not in out["images"][0]
    view = out["bufferViews"][out["images"][0]["bufferView"]]
    assert data[view["byteOffset"]: view["byteOffset"] + view["byteLength"]] == (tmp_path / "skin.png").read_bytes()
    pos = out["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
    acc = out["accessors"][pos]
    view = out["bufferViews"][acc["bufferView"]]
    vertices = np.frombuffer(data, "<f4", 9, view["byteOffset"] + acc.get("byteOffset", 0)).reshape(3, 3)
    assert np.array_equal(vertices, np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], dtype=np.float32))
    used = {s[k] for s in out["animations"][0]["samplers"] for k in ("input", "output")}
    used |= {out["skins"][0]["inverseBindMatrices"], *out["meshes"][0]["primitives"][0]["attributes"].values(),
             out["meshes"][0]["primitives"][0]["indices"]}
    assert used == set(range(len(out["accessors"])))  # the animation replaced left nothing behind
    code, _, err = run(capsys, "complete", tmp_path / "filled.glb", "--keys", "0,4", "-o", tmp_path / "again.glb")
    assert code == 0 and (tmp_path / "again.glb").stat().st_size == (tmp_path / "filled.glb").stat().st_size
    filled, source = io.load(tmp_path / "filled.glb"), io.load(tmp_path / "char.gltf")
    assert len(out["animations"]) == 1 and filled.keys.to_list() == [0, 4]
    assert np.abs(filled.world_positions()[[0, 4]] - source.world_positions()[[0, 4]]).max() < 1e-4


#: two joints without channels (a rigid prop), two frames: nothing to animate
NO_CHANNELS = """HIERARCHY
ROOT Base
{
  OFFSET 0 0 0
  CHANNELS 0
  JOINT Tip
  {
    OFFSET 0 10 0
    CHANNELS 0
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333


"""


def no_channels(tmp_path: Path) -> Path:
    (tmp_path / "prop.bvh").write_text(NO_CHANNELS)
    return tmp_path / "prop.bvh"


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_a_skeleton_without_channels_writes_a_static_animation(tmp_path, suffix):
    """glTF has no empty animation (no channels, no samplers): the first joint's rotation is held instead."""
    motion = io.load(no_channels(tmp_path))
    assert motion.num_frames == 2 and motion.skeleton.num_channels == 0
    out = tmp_path / f"prop{suffix}"
    io.save(motion, out)
    doc = unglb(out.read_bytes())[0] if suffix == ".glb" else json.loads(out.read_text())
    (anim,) = doc["animations"]
    assert anim["channels"] == [{"sampler": 0, "target": {"node": 0, "path": "rotation"}}]
    assert len(anim["samplers"]) == 1 and doc["accessors"][anim["samplers"][0]["input"]]["count"] == 2
    back = io.load(out)
    assert back.num_frames == 2 and back.keys is None and back.skeleton.channels == ((), ())
    np.testing.assert_allclose(back.world_positions(), motion.world_positions(), atol=1e-6)
    io.save(back, tmp_path / "back.bvh")
    io.save(motion, tmp_path / "direct.bvh")
    assert (tmp_path / "back.bvh").read_text() == (tmp_path / "direct.bvh").read_text()


def test_animations_are_named_after_the_output(capsys, tmp_path):
    """Blender renames clips that share a name (`keyfill.001`): each output's animation is called by its stem."""
    io.save(io.load(MIXAMO), tmp_path / "walk_filled.glb")
    assert unglb((tmp_path / "walk_filled.glb").read_bytes())[0]["animations"][0]["name"] == "walk_filled"
    doc, binary, _ = character()  # a character's clip ("Walk") takes the output's name too
    code, _, err = run(capsys, "complete", write_glb(tmp_path / "char.glb", doc, binary), "--keys", "0,4",
                       "-o", tmp_path / "char_cubic.glb")
    assert code == 0, err
    assert [a["name"] for a in unglb((tmp_path / "char_cubic.glb").read_bytes())[0]["animations"]] == ["char_cubic"]
    exe = [sys.executable, "-m", "keyfill", "convert", str(MIXAMO), "-", "--format", "gltf"]
    assert json.loads(subprocess.run(exe, capture_output=True, check=True).stdout)["animations"][0]["name"] == (
        MIXAMO.stem)  # standard output: the source's stem


def test_stdout_and_stdin(tmp_path):
    exe = [sys.executable, "-m", "keyfill"]
    data = subprocess.run(exe + ["convert", str(MIXAMO), "-", "--format", "glb"], capture_output=True,
                          check=True).stdout
    assert data[:4] == b"glTF"
    text = subprocess.run(exe + ["convert", "-", "-", "--in-format", "glb", "--format", "gltf"], input=data,
                          capture_output=True, check=True).stdout
    doc = json.loads(text)
    assert doc["buffers"][0]["uri"].startswith("data:application/octet-stream;base64,")
    info = subprocess.run(exe + ["info", "-", "--format", "gltf", "--json"], input=text, capture_output=True,
                          check=True)
    assert json.loads(info.stdout)["frames"] == 69


def test_a_gltf_and_its_bin_are_written_atomically(tmp_path):
    motion = io.load(MIXAMO)
    io.save(motion, tmp_path / "w.gltf")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.bin", "w.gltf"]
    doc = json.loads((tmp_path / "w.gltf").read_text())
    assert doc["buffers"][0]["uri"] == "w.bin"
    with pytest.raises(DataError, match="no frames"):
        io.save(motion.frames(slice(0, 0)), tmp_path / "bad.gltf")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.bin", "w.gltf"]


# --- bad input --------------------------------------------------------------------------------------


def _keyfill_glb(tmp_path) -> tuple[dict, bytes]:
    io.save(io.load(MIXAMO), tmp_path / "good.glb")
    return unglb((tmp_path / "good.glb").read_bytes())


def _sampler(doc, path="translation"):
    anim = doc["animations"][0]
    channel = next(c for c in anim["channels"] if c["target"]["path"] == path)
    return anim["samplers"][channel["sampler"]]


def _nan_in_binary(doc, binary):
    acc = doc["accessors"][_sampler(doc)["output"]]
    at = doc["bufferViews"][acc["bufferView"]]["byteOffset"]
    return doc, binary[:at] + struct.pack("<f", float("nan")) + binary[at + 4:]


def _mutate(case: str, doc: dict, binary: bytes, tmp_path: Path):
    if case == "version 1":
        doc["asset"]["version"] = "1.0"
    elif case == "accessor outside its buffer":
        doc["accessors"][_sampler(doc)["output"]]["byteOffset"] = 10**6
    elif case == "view outside its buffer":
        doc["bufferViews"][0]["byteLength"] = 10**9
    elif case == "counts disagree":
        doc["accessors"][_sampler(doc)["input"]]["count"] -= 1
    elif case == "bind matrices disagree":
        doc["accessors"][doc["skins"][0]["inverseBindMatrices"]]["count"] -= 1
    elif case == "nan in the binary":
        doc, binary = _nan_in_binary(doc, binary)
    elif case == "skin without joints":
        doc["skins"][0]["joints"] = []
    elif case == "cycle":
        doc["nodes"][-1]["children"] = [0]
    elif case == "two parents":
        doc["nodes"][2].setdefault("children", []).append(doc["nodes"][1]["children"][0])
    elif case == "scaled joint":
        doc["nodes"][1]["scale"] = [2, 2, 2]
    elif case == "wrong type":
        doc["accessors"][0]["count"] = 3.5
    elif case == "joint out of range":
        doc["skins"][0]["joints"][3] = 10**6
    elif case == "a billion seconds":
        acc = doc["accessors"][_sampler(doc)["input"]]
        at = doc["bufferViews"][acc["bufferView"]]["byteOffset"] + 4 * (acc["count"] - 1)
        binary = binary[:at] + struct.pack("<f", 1e9) + binary[at + 4:]
    elif case == "huge sparse accessor":
        doc["accessors"][_sampler(doc)["output"]] = {"componentType": 5126, "type": "VEC3", "count": 10**11,
                                                      "sparse": {"count": 1, "indices": {"bufferView": 0,
                                                                 "componentType": 5125}, "values": {"bufferView": 0}}}
    return doc, binary


BAD_JSON = {
    "version 1": "not glTF 2.0: asset.version is '1.0'",
    "accessor outside its buffer": "needs 1000",
    "view outside its buffer": "runs past the end of buffer 0",
    "counts disagree": "has 68 times and 69 values",
    "nan in the binary": "holds a value that is not finite",
    "bind matrices disagree": "skin 0 has 55 joints and 54 inverse bind matrices",
    "skin without joints": "skin 0 has no joints",
    "cycle": "is its own ancestor",
    "two parents": "is a child of two nodes",
    "scaled joint": "is scaled (2); keyfill motions have no scale",
    "wrong type": "accessors[0].count is not a whole number",
    "joint out of range": "skin 0 lists a node that does not exist",
    "a billion seconds": "the animation runs 1e+09 s at 30 fps: 30000000001 frames is more than keyfill reads",
    "huge sparse accessor": "100000000000 elements is more than keyfill reads",
}


@pytest.mark.parametrize("case", sorted(BAD_JSON))
def test_bad_glb_content_is_one_clean_error(capsys, tmp_path, case):
    doc, binary = _mutate(case, *_keyfill_glb(tmp_path), tmp_path)
    bad = write_glb(tmp_path / "bad.glb", doc, binary)
    code, _, err = run(capsys, "convert", bad, tmp_path / "out.bvh")
    line = one_error_line(err)
    assert code == 1 and str(bad) in line and BAD_JSON[case] in line, line
    assert not (tmp_path / "out.bvh").exists()


def test_bad_containers_are_one_clean_error(capsys, tmp_path):
    good = (tmp_path / "good.glb")
    io.save(io.load(MIXAMO), good)
    data = good.read_bytes()
    json_length = struct.unpack_from("<I", data, 12)[0]
    cases = {
        "truncated": (data[:-10], "the file has"),
        "header only": (data[:12], "the glTF header gives a length of"),
        "magic": (b"glTX" + data[4:], "not a glTF binary: the file starts with b'glTX'"),
        "chunk length": (data[:12] + struct.pack("<I", 2**31) + data[16:], "past the end of the file"),
        "json chunk": (data[:16] + b"BIN\0" + data[20:], "the first chunk of a glTF binary must be its JSON"),
        "nan": (data[:20] + data[20: 20 + json_length].replace(b'"fps":30.0', b'"fps":NaN ')
                + data[20 + json_length:], "the JSON holds NaN"),
        "empty": (b"", "shorter than the 12-byte header"),
    }
    for name, (content, fragment) in cases.items():
        bad = tmp_path / f"{name.replace(' ', '_')}.glb"
        bad.write_bytes(content)
        code, _, err = run(capsys, "info", bad)
        line = one_error_line(err)
        assert code == 1 and str(bad) in line and fragment in line, (name, line)


def test_uris_outside_the_folder_are_never_followed(capsys, tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    io.save(io.load(MIXAMO), folder / "w.gltf")
    shutil.copy(folder / "w.bin", tmp_path / "outside.bin")
    doc = json.loads((folder / "w.gltf").read_text())
    for uri, fragment in [("../outside.bin", "outside the file's folder"),
                          (str(tmp_path / "outside.bin"), "outside the file's folder"),
                          ("file:///etc/passwd", "outside the file's folder"),
                          ("missing.bin", "the file 'missing.bin' it names is missing")]:
        doc["buffers"][0]["uri"] = uri
        (folder / "w.gltf").write_text(json.dumps(doc))
        code, _, err = run(capsys, "convert", folder / "w.gltf", tmp_path / "out.bvh")
        line = one_error_line(err)
        assert code == 1 and "w.gltf" in line and fragment in line, line
        assert not (tmp_path / "out.bvh").exists()
    os.symlink(tmp_path / "outside.bin", folder / "link.bin")
    doc["buffers"][0]["uri"] = "link.bin"
    (folder / "w.gltf").write_text(json.dumps(doc))
    code, _, err = run(capsys, "info", folder / "w.gltf")
    assert code == 1 and "leads outside the file's folder" in one_error_line(err)


def test_a_scaled_animation_is_refused(tmp_path):
    doc, binary, _ = character(mesh=False)
    blob = Blob()
    blob.data, blob.views, blob.accessors = bytearray(binary), doc["bufferViews"], doc["accessors"]
    scale = blob.add(np.tile([1.0, 1.0, 1.5], (FRAMES, 1)), "VEC3")
    doc["animations"][0]["samplers"].append({"input": 0, "output": scale})
    doc["animations"][0]["channels"].append({"sampler": 3, "target": {"node": 2, "path": "scale"}})
    doc["buffers"] = [{"byteLength": len(blob.data)}]
    with pytest.raises(DataError, match="joint 'Spine' is scaled at frame 0"):
        io.load(write_glb(tmp_path / "s.glb", doc, bytes(blob.data)))


# --- the Khronos validator (skips without node and the gltf-validator package) -------------------


def validate(files: list[Path]) -> dict:
    node = shutil.which("node")
    if node is None or not (VALIDATOR / "node_modules" / "gltf-validator").is_dir():
        pytest.skip(f"needs node and the npm package gltf-validator in {VALIDATOR}/node_modules "
                    "(make gltf-validator, or set KEYFILL_GLTF_VALIDATOR)")
    script = Path(__file__).parent / "interop" / "gltf_validate.js"
    result = subprocess.run([node, str(script), *map(str, files)], capture_output=True, text=True, check=True,
                            env={**os.environ, "NODE_PATH": str(VALIDATOR / "node_modules")})
    return json.loads(result.stdout)


def test_the_khronos_validator_finds_no_error_in_what_keyfill_writes(capsys, tmp_path):
    files = []
    fixtures = LOCAL + (sorted(BVH_FIXTURES.glob("*.bvh")) if BVH_FIXTURES.is_dir() else [])
    for i, path in enumerate(fixtures):
        motion = io.load(path)
        for suffix in (".glb", ".gltf"):
            files.append(tmp_path / f"{i}_{path.stem}{suffix}")
            io.save(motion, files[-1])
    doc, binary, _ = character()
    code, _, err = run(capsys, "convert", write_glb(tmp_path / "char.glb", doc, binary), tmp_path / "kept.glb")
    assert code == 0, err
    files.append(tmp_path / "kept.glb")
    for suffix in (".glb", ".gltf"):  # a skeleton without channels: a static animation, not an empty one
        files.append(tmp_path / f"prop{suffix}")
        io.save(io.load(no_channels(tmp_path)), files[-1])
    report = validate(files)
    for file, r in report.items():
        assert r["errors"] == 0 and r["warnings"] == 0, (file, r["messages"])
    print("validator:", {Path(f).name: (r["errors"], r["warnings"], r["infos"], r["hints"]) for f, r in report.items()})


# --- long takes in bounded memory (issue 44) -----------------------------------------------------------


def _long_take():
    """MIXAMO's 69 frames 60 times over: 4,140 frames of 55 joints, 12 MiB of arrays."""
    from keyfill.motion import Motion

    m = io.load(MIXAMO)
    return Motion(m.skeleton, m.fps, np.tile(m.rotations, (60, 1, 1)), np.tile(m.positions, (60, 1, 1)))


def _peak_beyond(work, *args, **kwargs) -> tuple[int, object]:
    """``(bytes allocated at the peak of work(*args, **kwargs) beyond what was held before, its result)``: numpy's
    arrays are traced."""
    import tracemalloc

    tracemalloc.start()
    try:
        before = tracemalloc.get_traced_memory()[0]
        result = work(*args, **kwargs)
        return tracemalloc.get_traced_memory()[1] - before, result
    finally:
        tracemalloc.stop()


def test_long_takes_are_read_and_written_in_bounded_memory(monkeypatch, tmp_path):
    """Neither the buffer nor a converted copy of the motion is held whole: writing allocates less than the
    motion's float32 buffer would take (0.5x; 1.6x to 2.2x before), reading the motion and little more (1.2x
    beyond it before: the file's bytes, float copies)."""
    from keyfill.io import gltf, gltf_buffers, gltf_write

    monkeypatch.setattr(gltf_buffers, "BLOCK", 1 << 16)  # a block small beside this take, as 4 MiB beside a long one
    monkeypatch.setattr(gltf, "BLOCK", 1 << 16)
    motion = _long_take()
    own = motion.rotations.nbytes + motion.positions.nbytes
    for suffix in (".glb", ".gltf"):  # the imports and first calls, before anything is measured
        gltf_write.write(motion.frames(slice(0, 3)), tmp_path / f"warm{suffix}")
        gltf.read(tmp_path / f"warm{suffix}")
    for suffix in (".glb", ".gltf"):
        path = tmp_path / f"long{suffix}"
        # limits.check_values takes 0.48x (the magnitudes of the positions, CHECK_ROWS frames at once: all of this take)
        assert _peak_beyond(gltf_write.write, motion, path)[0] < 0.7 * own
        assert _peak_beyond(gltf_write.write, motion, tmp_path / f"kept{suffix}", template=path)[0] < 0.7 * own
        peak, back = _peak_beyond(gltf.read, path)
        assert peak < 1.4 * own
        assert np.abs(back.positions - motion.positions).max() < 1e-3 * height(motion)


def test_blocks_change_no_value_and_no_byte(monkeypatch, tmp_path):
    """Accessors interleaved in one strided view, sparse values, a template's bytes and an embedded buffer,
    read and written 100 bytes at a time (a multiple of no element and no stride), give what 4 MiB blocks
    give."""
    from keyfill.io import gltf, gltf_buffers, gltf_write

    doc, binary = _keyfill_glb(tmp_path)
    move, turn = _sampler(doc), _sampler(doc, "rotation")
    a, b = doc["accessors"][move["output"]], doc["accessors"][turn["output"]]
    count = a["count"]
    rows = []
    for acc, width in ((a, 3), (b, 4)):
        at = doc["bufferViews"][acc["bufferView"]]["byteOffset"]
        rows.append(np.frombuffer(binary, "<f4", count * width, at).reshape(count, width))
    stride = 4 * 7 + 4  # translation, rotation and 4 spare bytes per element
    interleaved = np.zeros((count, stride // 4), "<f4")
    interleaved[:, :3], interleaved[:, 3:7] = rows
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": interleaved.nbytes,
                               "byteStride": stride})
    binary += interleaved.tobytes()
    a.update(bufferView=len(doc["bufferViews"]) - 1, byteOffset=0)
    b.update(bufferView=len(doc["bufferViews"]) - 1, byteOffset=12)
    # and one sparse value over the translation: element 2 holds what it held (read through the sparse part)
    doc["bufferViews"] += [{"buffer": 0, "byteOffset": len(binary), "byteLength": 4},
                           {"buffer": 0, "byteOffset": len(binary) + 4, "byteLength": 12}]
    binary += struct.pack("<I", 2) + rows[0][2].tobytes()
    a["sparse"] = {"count": 1, "indices": {"bufferView": len(doc["bufferViews"]) - 2, "componentType": 5125},
                   "values": {"bufferView": len(doc["bufferViews"]) - 1}}
    doc["buffers"][0]["byteLength"] = len(binary)
    src = write_glb(tmp_path / "strided.glb", doc, binary)
    reference = io.load(tmp_path / "good.glb")
    outputs = {}
    for block in (1 << 22, 100):
        monkeypatch.setattr(gltf_buffers, "BLOCK", block)
        monkeypatch.setattr(gltf, "BLOCK", block)
        motion = io.load(src)
        assert np.array_equal(motion.rotations, reference.rotations)
        assert np.array_equal(motion.positions, reference.positions)
        out = tmp_path / str(block)
        out.mkdir()
        gltf_write.write(motion, out / "kept.glb", template=src)
        gltf_write.write(motion, out / "embedded.gltf", template=src, sidecar=None)
        gltf_write.write(motion, out / "beside.gltf", template=src)
        outputs[block] = {p.name: p.read_bytes() for p in out.iterdir()}
    assert outputs[100] == outputs[1 << 22]
    embedded = json.loads(outputs[100]["embedded.gltf"])
    data = base64_bytes(embedded["buffers"][0].pop("uri"))
    assert data == outputs[100]["beside.bin"] == unglb(outputs[100]["kept.glb"])[1][:len(data)]
    beside = json.loads(outputs[100]["beside.gltf"])
    assert beside["buffers"][0].pop("uri") == "beside.bin" and beside == embedded


def base64_bytes(uri: str) -> bytes:
    import base64

    head, _, body = uri.partition(",")
    assert head == "data:application/octet-stream;base64"
    return base64.b64decode(body, validate=True)


@pytest.mark.parametrize("suffix", [".glb", ".gltf"])
def test_a_template_written_over_itself_is_read_first(suffix, tmp_path):
    """The writer copies a template's bytes as it writes: the one file it writes over is read beforehand."""
    from keyfill.io import gltf_write

    doc, binary, _ = character()
    src = write_glb(tmp_path / "source.glb", doc, binary)
    motion = io.load(src)
    path = tmp_path / f"char{suffix}"
    gltf_write.write(motion, tmp_path / f"other{suffix}", template=src)
    gltf_write.write(motion, path, template=src)
    gltf_write.write(motion, path, template=path)  # a .gltf: its .bin is both the template's and the output's
    other = tmp_path / f"other{suffix}"
    if suffix == ".gltf":
        assert (tmp_path / "char.bin").read_bytes() == (tmp_path / "other.bin").read_bytes()
        assert json.loads(path.read_text())["meshes"] == json.loads(other.read_text())["meshes"]
    else:
        assert path.read_bytes() == other.read_bytes()
    assert np.allclose(io.load(path).positions, motion.positions, atol=1e-4)


def test_a_buffer_file_cut_short_while_it_is_read_is_one_clean_error(tmp_path):
    from keyfill.io import gltf_buffers

    io.save(io.load(MIXAMO), tmp_path / "w.gltf")
    doc = gltf_buffers.load_document(tmp_path / "w.gltf", "w.gltf")
    acc = _sampler(doc.json)["output"]
    (tmp_path / "w.bin").write_bytes(b"")
    with pytest.raises(FormatError, match=r"buffer 0: the file 'w.bin' it names ends before byte \d+"):
        gltf_buffers.read_accessor(doc, acc, "a channel", ("VEC3",))
