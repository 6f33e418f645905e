"""Make the small FBX fixtures of ``tests/data`` with Blender's own FBX exporter.

Runs inside Blender's Python (the ``bpy`` wheel in ``.venv-blender``; ``make
.venv-blender/.bpy-installed`` creates it), so it imports nothing from keyfill::

    .venv-blender/bin/python tests/interop/make_fbx.py tests/data

It writes five files (binary FBX 7.4, 20-60 KB each: Blender writes a full
property template per kind of object; Blender stamps the creation time in
them, so a re-run gives other bytes and the same content):

* ``fbx_rig.fbx``: an armature of four bones and no mesh, exported as Blender
  does by default (Y-up, ``axis_forward="-Z"``), 20 frames at 30 fps.
* ``fbx_rig_zup.fbx``: the same scene exported Z-up (``axis_up="Z"``,
  ``axis_forward="Y"``: the file's axes are Blender's own).
* ``fbx_skinned.fbx``: the same armature deforming a box mesh (an Armature
  modifier, one vertex group per bone), exported Y-up.
* ``fbx_no_anim.fbx``: the armature without its animation (``bake_anim=False``:
  no animation stack), and ``fbx_mesh_only.fbx``: the box alone (no bone), both
  for keyfill's refusals.

Every file: no leaf bones (``add_leaf_bones=False``), one animation stack
(``bake_anim_use_all_actions=False``, no NLA strips) baked at every frame
without simplification (``bake_anim_simplify_factor=0``), scene units metres.

The rig (Blender's Z-up world, metres; every bone along +Z but ``Arm``, roll 0)::

    Hips   head (0, 0, 1.0)   tail (0, 0, 1.1)
    Spine  head (0, 0, 1.1)   tail (0, 0, 1.5)   parent Hips
    Head   head (0, 0, 1.5)   tail (0, 0, 1.7)   parent Spine
    Arm    head (0.2, 0, 1.45) tail (0.6, 0, 1.45) parent Spine

The animation, at frame index ``i = 0 .. 19`` (Blender frame ``i + 1``): pose
bone Euler XYZ rotations and the Hips' location, in each bone's own frame::

    Hips   location (0.02 i, 0, 0), rotation (0, 0.3 sin(pi i / 10), 0)
    Spine  rotation (pi/2 * i / 10, 0, 0.2 sin(pi i / 10))
    Head   rotation (0.4 sin(pi i / 10), 0, 0)
    Arm    rotation (0, 0, 0.5 sin(pi i / 5))

So frame 0 is the rest pose and at frame 10 only the Hips' shift (0.2 m along
X) and the Spine's quarter turn about X remain: the heads are then (Blender
world, metres) Hips (0.2, 0, 1.0), Spine (0.2, 0, 1.1), Head (0.2, -0.4, 1.1)
and Arm (0.4, -0.35, 1.1). This script checks those figures against
Blender's own pose before it writes anything (:data:`EXPECTED_FRAME_10`);
``tests/test_fbx.py`` checks keyfill's reading of the files against them.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import bpy
from mathutils import Vector

FPS = 30
NUM_FRAMES = 20
BONES = {  # name: (head, tail, parent)
    "Hips": ((0.0, 0.0, 1.0), (0.0, 0.0, 1.1), None),
    "Spine": ((0.0, 0.0, 1.1), (0.0, 0.0, 1.5), "Hips"),
    "Head": ((0.0, 0.0, 1.5), (0.0, 0.0, 1.7), "Spine"),
    "Arm": ((0.2, 0.0, 1.45), (0.6, 0.0, 1.45), "Spine"),
}
#: bone heads at frame index 10, Blender world metres (see the module docstring)
EXPECTED_FRAME_10 = {"Hips": (0.2, 0.0, 1.0), "Spine": (0.2, 0.0, 1.1), "Head": (0.2, -0.4, 1.1),
                     "Arm": (0.4, -0.35, 1.1)}
EXPORT = {"add_leaf_bones": False, "bake_anim": True, "bake_anim_use_all_actions": False,
          "bake_anim_use_nla_strips": False, "bake_anim_simplify_factor": 0.0, "bake_anim_force_startend_keying": True,
          "use_metadata": True}


def pose_at(i: int) -> dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]]:
    """Per bone, ``(location, euler XYZ)`` at frame index ``i``."""
    s10, s5 = math.sin(math.pi * i / 10), math.sin(math.pi * i / 5)
    zero = (0.0, 0.0, 0.0)
    return {
        "Hips": ((0.02 * i, 0.0, 0.0), (0.0, 0.3 * s10, 0.0)),
        "Spine": (zero, (math.pi / 2 * i / 10, 0.0, 0.2 * s10)),
        "Head": (zero, (0.4 * s10, 0.0, 0.0)),
        "Arm": (zero, (0.0, 0.0, 0.5 * s5)),
    }


def build(skinned: bool):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = FPS, 1.0
    scene.frame_start, scene.frame_end = 1, NUM_FRAMES
    scene.unit_settings.system, scene.unit_settings.scale_length = "METRIC", 1.0
    data = bpy.data.armatures.new("Rig")
    arm = bpy.data.objects.new("Rig", data)
    scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode="EDIT")
    for name, (head, tail, parent) in BONES.items():
        bone = data.edit_bones.new(name)
        bone.head, bone.tail, bone.roll = head, tail, 0.0
        if parent:
            bone.parent = data.edit_bones[parent]
    bpy.ops.object.mode_set(mode="POSE")
    for pb in arm.pose.bones:
        pb.rotation_mode = "XYZ"
    for i in range(NUM_FRAMES):
        for name, (loc, rot) in pose_at(i).items():
            pb = arm.pose.bones[name]
            pb.location, pb.rotation_euler = loc, rot
            pb.keyframe_insert("location", frame=i + 1)
            pb.keyframe_insert("rotation_euler", frame=i + 1)
    bpy.ops.object.mode_set(mode="OBJECT")
    if skinned:
        _box(arm)
    return arm


def _box(arm) -> None:
    """A box around the spine, each vertex weighted to the bone whose head is nearest."""
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0.0, 0.0, 1.3))
    box = bpy.context.active_object
    box.name = "Body"
    box.scale = (0.3, 0.2, 0.8)
    bpy.ops.object.transform_apply(location=False, rotation=False, scale=True)
    heads = {name: Vector(head) for name, (head, _, _) in BONES.items()}
    groups = {name: box.vertex_groups.new(name=name) for name in BONES}
    for v in box.data.vertices:
        world = box.matrix_world @ v.co
        nearest = min(heads, key=lambda n: (heads[n] - world).length)
        groups[nearest].add([v.index], 1.0, "REPLACE")
    box.parent = arm
    box.modifiers.new("Armature", "ARMATURE").object = arm


def check(arm) -> None:
    """Blender's own bone heads at frame index 10 are the figures of the docstring."""
    bpy.context.scene.frame_set(11)
    for name, want in EXPECTED_FRAME_10.items():
        got = arm.matrix_world @ arm.pose.bones[name].head
        if (got - Vector(want)).length > 1e-6:
            raise SystemExit(f"make_fbx: {name} at frame 10 is {tuple(got)}, not {want}")


def export(path: Path, **options) -> None:
    bpy.ops.export_scene.fbx(filepath=str(path), **{**EXPORT, **options})
    print(f"make_fbx: wrote {path} ({path.stat().st_size} bytes)")


def main(argv: list[str]) -> None:
    folder = Path(argv[0] if argv else Path(__file__).resolve().parents[1] / "data")
    arm = build(skinned=False)
    check(arm)
    export(folder / "fbx_rig.fbx", object_types={"ARMATURE"})
    export(folder / "fbx_rig_zup.fbx", object_types={"ARMATURE"}, axis_up="Z", axis_forward="Y")
    arm = build(skinned=True)
    check(arm)
    export(folder / "fbx_skinned.fbx", object_types={"ARMATURE", "MESH"})
    export(folder / "fbx_no_anim.fbx", object_types={"ARMATURE"}, bake_anim=False)
    export(folder / "fbx_mesh_only.fbx", object_types={"MESH"}, bake_anim=False)


if __name__ == "__main__":
    main(sys.argv[1:])
