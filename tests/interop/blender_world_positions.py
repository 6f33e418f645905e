"""Import a BVH, USD, glTF or FBX file into Blender and print every bone head's world position per frame.

Runs inside Blender's Python (the ``bpy`` wheel in ``.venv-blender``, which
cannot share keyfill's venv: it pins numpy<2), so it imports nothing from
keyfill::

    .venv-blender/bin/python tests/interop/blender_world_positions.py walk.bvh --scale 0.01
    .venv-blender/bin/python tests/interop/blender_world_positions.py walk.usda --out walk.json

Output (JSON, on stdout or in ``--out``)::

    {"blender": "5.0.1", "format": "bvh", "frame_start": 0, "frames": F,
     "bones": [name, ...], "positions": [[[x, y, z] per bone] per frame]}

``positions`` are Blender world coordinates (``armature.matrix_world @
pose_bone.head``) in meters: Blender's scene is Z-up, so a point ``(x, y, z)``
of a Y-up file lands at ``scale * (x, -z, y)``. Both importers are set up to
make that same conversion, so the two formats are comparable with each other
and with keyfill:

* BVH (``bpy.ops.import_anim.bvh``): ``axis_forward="-Z", axis_up="Y"`` (the
  importer's defaults: the file is Y-up, -Z forward; a +90 degree turn about
  X), ``global_scale=--scale`` (the file's meters per unit, 0.01 for cm),
  ``rotate_mode="QUATERNION"``, ``use_fps_scale=False`` and ``frame_start=1``
  (the importer's minimum: BVH frame i is Blender frame i + 1).
* USD (``bpy.ops.wm.usd_import``): Blender turns a Y-up stage Z-up with the
  same +90 degree turn about X and, with ``apply_unit_conversion_scale=True``
  and ``scale=1``, scales by the stage's ``metersPerUnit``. Time code i is
  Blender frame i. ``--scale`` is ignored (the file carries its unit).
* glTF (``bpy.ops.import_scene.gltf``): the file is metres and Y-up, turned Z-up
  the same way; ``--scale`` is ignored. The importer turns seconds into frames at
  the scene's rate, so the scene's fps is first set to the animation's
  ``extras.keyfill.fps`` (read from the file's JSON here).

* FBX (``bpy.ops.import_scene.fbx``, ``use_anim=True``, no leaf bones ignored, no
  automatic bone orientation): Blender reads the file's own axes and units
  (a Y-up file is turned Z-up the same way); ``--scale`` is ignored. The
  importer keys the animation from its first frame on.

``positions[i]`` is always the file's frame i (Blender frame ``frame_start + i``).

Bone names are Blender's: the BVH joint names (cut to 63 bytes), or for USD the
last component of each UsdSkel joint path.
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
from pathlib import Path

import bpy


def _clear_scene() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)


def _gltf_fps(path: Path) -> float:
    data = path.read_bytes()
    text = data[20: 20 + struct.unpack_from("<I", data, 12)[0]] if data[:4] == b"glTF" else data
    anims = json.loads(text).get("animations", [])
    return float(anims[0].get("extras", {}).get("keyfill", {}).get("fps", 24.0)) if anims else 24.0


def _import(path: Path, scale: float) -> str:
    suffix = path.suffix.lower()
    fmt = ("bvh" if suffix == ".bvh" else "gltf" if suffix in (".glb", ".gltf") else "fbx" if suffix == ".fbx"
           else "usd")
    if fmt == "fbx":
        result = bpy.ops.import_scene.fbx(filepath=str(path), use_anim=True, ignore_leaf_bones=False,
                                          automatic_bone_orientation=False)
    elif fmt == "gltf":
        fps = _gltf_fps(path)
        bpy.context.scene.render.fps = round(fps)
        bpy.context.scene.render.fps_base = round(fps) / fps
        result = bpy.ops.import_scene.gltf(filepath=str(path))
    elif fmt == "bvh":
        result = bpy.ops.import_anim.bvh(
            filepath=str(path),
            target="ARMATURE",
            global_scale=scale,
            frame_start=1,
            use_fps_scale=False,
            update_scene_fps=True,
            update_scene_duration=True,
            rotate_mode="QUATERNION",
            axis_forward="-Z",
            axis_up="Y",
        )
    else:
        result = bpy.ops.wm.usd_import(
            filepath=str(path),
            scale=1.0,
            apply_unit_conversion_scale=True,
            set_frame_range=True,
            import_skeletons=True,
        )
    if "FINISHED" not in result:
        raise SystemExit(f"blender_world_positions: Blender could not import {path} ({result})")
    return fmt


def _armature():
    arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
    if len(arms) != 1:
        raise SystemExit(f"blender_world_positions: expected one armature after import, found {len(arms)}")
    return arms[0]


def _frame_range(arm) -> tuple[int, int]:
    """First and last frame of the armature's action (both formats key every frame)."""
    action = arm.animation_data.action if arm.animation_data else None
    if action is None:
        raise SystemExit("blender_world_positions: the imported armature has no animation")
    first, last = action.frame_range
    return round(first), round(last)


def world_positions(path: Path, scale: float) -> dict:
    _clear_scene()
    fmt = _import(path, scale)
    arm = _armature()
    first, last = _frame_range(arm)
    scene = bpy.context.scene
    bones = [pb.name for pb in arm.pose.bones]
    frames = []
    for f in range(first, last + 1):
        scene.frame_set(f)
        mw = arm.matrix_world
        frames.append([list(mw @ pb.head) for pb in arm.pose.bones])
    return {
        "blender": bpy.app.version_string,
        "format": fmt,
        "frame_start": first,
        "frames": len(frames),
        "bones": bones,
        "positions": frames,
    }


def main(argv: list[str]) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", type=Path, help="a .bvh, .usda, .usdc, .usd, .glb, .gltf or .fbx file")
    parser.add_argument("--scale", type=float, default=0.01, help="BVH only: meters per file unit (default 0.01, cm)")
    parser.add_argument("--out", default="-", help="JSON output file ('-': stdout, the default)")
    args = parser.parse_args(argv)
    result = world_positions(args.file.resolve(), args.scale)
    text = json.dumps(result)
    if args.out == "-":
        sys.stdout.write(text + "\n")
    else:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main(sys.argv[1:])
