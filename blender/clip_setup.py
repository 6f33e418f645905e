"""A Bandai clip in bpy as the Blender tests (tests/interop/blender_addon_check.py) and the pictures
(render_pictures.py) both set it up: imported by Blender's BVH importer, then keyed every few frames.
Not part of the extension's zip (blender/keyfill_blender)."""

from __future__ import annotations

import math
from pathlib import Path

import bpy


def import_clip(path: Path, own_axes: bool, rotate_mode: str = "QUATERNION"):
    """The armature of the BVH ``path`` in an empty scene: with ``own_axes`` in the file's own axes (Y-up
    centimetres) under an object turned Z-up and scaled to metres, else as a user imports it (Z-up metres)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    kw = {"axis_forward": "Y", "axis_up": "Z", "global_scale": 1.0} if own_axes else {"global_scale": 0.01}
    bpy.ops.import_anim.bvh(filepath=str(path), target="ARMATURE", frame_start=1, use_fps_scale=False,
                            update_scene_fps=True, update_scene_duration=True, rotate_mode=rotate_mode, **kw)
    obj = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    if own_axes:
        obj.rotation_euler = (math.pi / 2, 0.0, 0.0)
        obj.scale = (0.01, 0.01, 0.01)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.context.view_layer.update()
    return obj


def keep_every(obj, every: int, first: int) -> None:
    """Remove every key of ``obj``'s action but those on frames ``first + n * every``."""
    from bpy_extras import anim_utils

    ad = obj.animation_data
    for fc in anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot).fcurves:
        kps = fc.keyframe_points
        for i in reversed(range(len(kps))):
            if (round(kps[i].co[0]) - first) % every:
                kps.remove(kps[i], fast=True)
        fc.update()
