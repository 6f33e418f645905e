"""Import a USD stage into Blender and print what came in, as JSON (for tests/test_usd_stage.py).

Runs inside Blender's Python (``.venv-blender``), importing nothing from keyfill::

    .venv-blender/bin/python tests/interop/blender_usd_stage.py filled.usda

Output: ``{"meshes": {name: {"materials": [...], "armature": modifier's object or null, "groups": [...]}},
"armatures": {name: [bone names]}, "frames": [first, last] of the armature's action, "heads": {frame:
[bone head world positions]}}`` at the action's first, middle and last frames.
"""

import json
import sys

import bpy

bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=sys.argv[1], import_materials=True, import_skeletons=True)
meshes, armatures, frames, heads = {}, {}, None, {}
for obj in bpy.data.objects:
    if obj.type == "MESH":
        mods = [m.object.name for m in obj.modifiers if m.type == "ARMATURE" and m.object]
        meshes[obj.name] = {"materials": [m.name for m in obj.data.materials if m],
                            "armature": mods[0] if mods else None, "groups": [g.name for g in obj.vertex_groups]}
    elif obj.type == "ARMATURE":
        armatures[obj.name] = [b.name for b in obj.data.bones]
        action = obj.animation_data.action if obj.animation_data else None
        if action is not None:
            frames = [round(action.frame_range[0]), round(action.frame_range[1])]
            for f in sorted({frames[0], (frames[0] + frames[1]) // 2, frames[1]}):
                bpy.context.scene.frame_set(f)
                heads[f] = [list(obj.matrix_world @ b.head) for b in obj.pose.bones]
print(json.dumps({"meshes": meshes, "armatures": armatures, "frames": frames, "heads": heads}))
