"""The pictures of docs/blender.md, rendered headless with bpy (Blender as a Python module) and the extension.

    .venv-blender/bin/python blender/render_pictures.py [--clip CLIP.bvh] [--out docs/img] [--method transformer]

Blender without a window cannot draw its UI, its viewport overlays (bones, motion paths) or OpenGL viewport
renders (``render.opengl``: "no opengl context"; the ``gpu`` module: "not available in background mode"), but
its render engines work: Workbench renders through EGL (Mesa's software driver on a machine without a GPU). An
armature does not render, so each pose shown is built as a mesh (a tube per bone, a sphere per joint, from the
pose bones' heads and tails) and each trail as a curve with a bevel. Writes:

* ``blender_fill.png``: frames 1-46 of a Bandai-Namco walk keyed every 15 frames; top, Blender's own
  interpolation of the keys; bottom, after *Fill In-betweens* (every 5th frame; keys orange), with the feet's
  and hands' paths over every frame; the poses are spread along the walk, 4.5 cm a frame, so that they part.
* ``blender_edit_tangents.png``: *Edit Tangents* moving Hand_L's tail at frame 9 to the 3D cursor (red): the
  pose before (grey) and after (blue), and the hand's path over frames 1-16 before and after.

The extension is registered from ``blender/keyfill_blender`` (not installed: no user folder is touched); keyfill
must import in this Python (``make test-interop`` installs it into ``.venv-blender``). Deterministic: the
same inputs give the same pictures (Workbench, no sampling noise).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import bpy  # isort: skip (bpy first: it makes bmesh and mathutils importable)
import bmesh  # isort: skip
import numpy as np
from clip_setup import import_clip, keep_every  # this folder: the clip as the Blender tests set it up
from mathutils import Matrix, Vector

ROOT = Path(__file__).resolve().parents[1]
CLIP = ROOT / "data" / "bandai2" / "bandai_namco_motiondataset2" / "data" / "dataset-2_walk_elderly_001.bvh"
KEY_COLOR = (0.95, 0.45, 0.1, 1.0)
FILL_COLOR = (0.25, 0.45, 0.8, 1.0)
BLENDER_COLOR = (0.45, 0.45, 0.45, 1.0)
GHOST = (0.72, 0.72, 0.72, 1.0)
TARGET = (0.85, 0.1, 0.1, 1.0)
SKIP = ("joint_Root",)  # the Bandai rig's ground-level root: a bone from the floor to the hips would mislead
SPREAD = 0.045  # m a frame: the poses of the Fill picture are spread along the walk


def load_extension() -> None:
    """Register the extension from its source folder (after a factory reset, which drops registrations)."""
    if str(ROOT / "blender") not in sys.path:
        sys.path.insert(0, str(ROOT / "blender"))
    import keyfill_blender

    if hasattr(bpy.types, "KEYFILL_OT_fill_inbetweens"):
        keyfill_blender.unregister()
    keyfill_blender.register()


def pose_at(obj, frame: int) -> dict:
    """World heads and tails of the pose bones at ``frame``: ``{name: (head, tail, parent name)}``."""
    bpy.context.scene.frame_set(frame)
    mw = obj.matrix_world.copy()
    return {pb.name: (mw @ pb.head, mw @ pb.tail, pb.parent.name if pb.parent else None) for pb in obj.pose.bones}


# --- geometry -----------------------------------------------------------------------------------------------


def _tube(bm, a: Vector, b: Vector, radius: float, segments: int = 8) -> None:
    d = b - a
    if d.length < 1e-6:
        return
    rot = d.normalized().to_track_quat("Z", "Y").to_matrix().to_4x4()
    m = Matrix.Translation((a + b) / 2) @ rot
    bmesh.ops.create_cone(bm, cap_ends=True, segments=segments, radius1=radius, radius2=radius, depth=d.length,
                          matrix=m)


def _ball(bm, c: Vector, radius: float) -> None:
    bmesh.ops.create_uvsphere(bm, u_segments=10, v_segments=6, radius=radius, matrix=Matrix.Translation(c))


def figure(name: str, pose: dict, color, offset: Vector | None = None, scale: float = 1.0, head: str = "Head"):
    """A mesh stick figure of ``pose`` (tubes from each bone's head to its tail, balls at joints)."""
    offset = Vector() if offset is None else offset
    bm = bmesh.new()
    for bone, (h, t, _parent) in pose.items():
        if bone in SKIP:
            continue
        _tube(bm, h + offset, t + offset, 0.014 * scale)
        _ball(bm, h + offset, 0.02 * scale)
    if head in pose:
        h, t, _ = pose[head]
        _ball(bm, h + (t - h).normalized() * 0.06 * scale + offset, 0.085 * scale)
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new(name, me)
    ob.color = color
    bpy.context.scene.collection.objects.link(ob)
    return ob


def trail(name: str, points, color, radius: float = 0.006):
    cu = bpy.data.curves.new(name, "CURVE")
    cu.dimensions = "3D"
    cu.bevel_depth = radius
    cu.bevel_resolution = 2
    sp = cu.splines.new("POLY")
    sp.points.add(len(points) - 1)
    for p, q in zip(sp.points, points):
        p.co = (*q, 1.0)
    ob = bpy.data.objects.new(name, cu)
    ob.color = color
    bpy.context.scene.collection.objects.link(ob)
    return ob


def label(text: str, where: Vector, facing, size: float = 0.12, color=(0.1, 0.1, 0.1, 1.0)):
    cu = bpy.data.curves.new("label", "FONT")
    cu.body = text
    cu.size = size
    ob = bpy.data.objects.new("label", cu)
    ob.location = where
    ob.rotation_euler = facing
    ob.color = color
    bpy.context.scene.collection.objects.link(ob)
    return ob


def ground(center: Vector, size: float):
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=size / 2, matrix=Matrix.Translation(center))
    me = bpy.data.meshes.new("ground")
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new("ground", me)
    ob.color = (0.93, 0.93, 0.9, 1.0)
    bpy.context.scene.collection.objects.link(ob)


# --- rendering ----------------------------------------------------------------------------------------------


def camera(location: Vector, target: Vector, ortho: float | None = None, lens: float = 50.0):
    cam = bpy.data.cameras.new("camera")
    if ortho:
        cam.type = "ORTHO"
        cam.ortho_scale = ortho
    else:
        cam.lens = lens
    ob = bpy.data.objects.new("camera", cam)
    ob.location = location
    ob.rotation_euler = (target - location).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.scene.camera = ob
    return ob


def render(path: Path, width: int, height: int) -> None:
    sc = bpy.context.scene
    sc.render.engine = "BLENDER_WORKBENCH"
    sc.render.resolution_x, sc.render.resolution_y, sc.render.resolution_percentage = width, height, 100
    sh = sc.display.shading
    sh.light = "STUDIO"
    sh.color_type = "OBJECT"
    sh.show_shadows = True
    sh.shadow_intensity = 0.25
    sc.display.render_aa = "8"
    sc.view_settings.view_transform = "Standard"
    if sc.world is None:
        sc.world = bpy.data.worlds.new("world")
    sc.world.color = (1.0, 1.0, 1.0)
    im = sc.render.image_settings
    im.file_format, im.color_mode, im.color_depth, im.compression = "PNG", "RGB", "8", 100
    sc.render.filepath = str(path)
    t0 = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    seconds = time.perf_counter() - t0
    try:  # a palette of 64 colours keeps the picture small (Pillow comes with matplotlib; without it, as rendered)
        from PIL import Image

        with Image.open(path) as im:
            small = im.convert("RGB").quantize(colors=64, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
        small.save(path, optimize=True)
    except ImportError:
        pass
    print(f"{path.name}: {seconds:.1f} s, {path.stat().st_size / 1024:.0f} KB")


def hide_armatures() -> None:
    for ob in bpy.data.objects:
        if ob.type == "ARMATURE":
            ob.hide_render = True


# --- the pictures -------------------------------------------------------------------------------------------


def frame_camera(points: np.ndarray, look_along: Vector, width: int, margin: float = 0.06):
    """An orthographic camera looking along ``look_along`` (horizontal) that frames ``points (N, 3)`` in a
    ``width``-pixel-wide picture; returns the picture's height."""
    up = Vector((0.0, 0.0, 1.0))
    right = look_along.cross(up).normalized()
    u, v = points @ np.array(right), points[:, 2]
    du, dv = (np.ptp(u) * (1 + 2 * margin)), (np.ptp(v) * (1 + 2 * margin))
    height = round(float(width * dv / du) / 2) * 2
    c = Vector(((u.max() + u.min()) / 2) * right) + Vector((0.0, 0.0, (v.max() + v.min()) / 2))
    depth = float(np.mean(points @ np.array(look_along)))
    c += look_along * depth
    camera(c - look_along * 30, c, ortho=max(du, dv))  # Blender fits ortho_scale to the longer side
    return height


def picture_fill(clip: Path, out: Path, method: str) -> None:
    obj = import_clip(clip, own_axes=True, rotate_mode="QUATERNION")
    load_extension()
    first, last, every, step = 1, 46, 15, 5
    sc = bpy.context.scene
    sc.frame_start, sc.frame_end = first, last
    keep_every(obj, every, first)
    frames = range(first, last + 1)
    blender = {f: pose_at(obj, f) for f in frames}  # Blender's own interpolation of the keys
    result = bpy.ops.keyfill.fill_inbetweens(method=method, use_range=True, frame_start=first, frame_end=last)
    assert "FINISHED" in result, result
    filled = {f: pose_at(obj, f) for f in frames}
    hide_armatures()
    hips = np.array([list(filled[f]["Hips"][0]) for f in frames])
    walk = Vector((*(hips[-1, :2] - hips[0, :2]), 0.0)).normalized()
    side = Vector((0.0, 0.0, 1.0)).cross(walk)  # the camera looks at the walk's left side
    tall = max(max(h.z for h, _t, _p in p.values()) for p in filled.values())
    up = Vector((0.0, 0.0, tall * 1.35))  # the top row (Blender's interpolation) stands above the bottom one
    points = []
    for row, poses, offset, inbetween in (("blender", blender, up, BLENDER_COLOR),
                                          ("keyfill", filled, Vector(), FILL_COLOR)):
        def at(f, p, offset=offset):  # spread along the walk, SPREAD a frame, so that the figures part
            return p + offset + walk * SPREAD * (f - first)

        for f in frames:
            key = (f - first) % every == 0
            if key or (f - first) % step == 0:
                pose = {n: (at(f, h), at(f, t), par) for n, (h, t, par) in poses[f].items()}
                figure(f"{row}{f}", pose, KEY_COLOR if key else inbetween, scale=1.0 if key else 0.8)
            points += [list(at(f, h)) for n, (h, _t, _p) in poses[f].items() if n not in SKIP]
        for bone in ("Toes_L", "Toes_R", "Hand_L", "Hand_R"):
            trail(f"{row}-{bone}", [tuple(at(f, poses[f][bone][0])) for f in frames], inbetween)
    points = np.array(points)
    facing = (math.pi / 2, 0.0, math.atan2(walk.y, walk.x))
    start = Vector(points[np.argmin(points @ np.array(walk))]) - side * 0.6
    for text, z in ((f"Blender's interpolation of the keys (every {step}th frame; keys orange)", up.z + tall + 0.08),
                    (f"after Fill In-betweens, {method} (every {step}th frame; keys orange)", tall + 0.08)):
        label(text, Vector((start.x, start.y, z)), facing, size=0.1)
        points = np.vstack([points, [[start.x, start.y, z + 0.12]]])
    height = frame_camera(points, side, 960)
    render(out / "blender_fill.png", 960, height)


def picture_tangents(clip: Path, out: Path) -> None:
    obj = import_clip(clip, own_axes=False, rotate_mode="NATIVE")
    load_extension()
    sc = bpy.context.scene
    first = round(obj.animation_data.action.frame_range[0])
    keep_every(obj, 15, first)
    frame = first + 8
    frames = range(first, first + 16)
    sc.frame_set(frame)
    obj.data.bones.active = obj.data.bones["Hand_L"]
    tail = obj.matrix_world @ obj.pose.bones["Hand_L"].tail
    target = tail + Vector((0.0, 0.1, 0.1))
    sc.cursor.location = target
    before = {f: pose_at(obj, f) for f in frames}
    sc.frame_set(frame)
    result = bpy.ops.keyfill.edit_tangents(bone="Hand_L", point="TAIL", target="CURSOR", pins="Hips",
                                           contacts=f"Toes_L:{first}-{first + 15}", tolerance=5e-4)
    assert "FINISHED" in result, result
    after = {f: pose_at(obj, f) for f in frames}
    hide_armatures()
    figure("before", before[frame], GHOST, scale=0.8)
    figure("after", after[frame], FILL_COLOR, scale=0.8)
    trail("path-before", [tuple(before[f]["Hand_L"][1]) for f in frames], GHOST, 0.004)
    trail("path-after", [tuple(after[f]["Hand_L"][1]) for f in frames], FILL_COLOR, 0.004)
    bm = bmesh.new()
    _ball(bm, target, 0.022)
    me = bpy.data.meshes.new("target")
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new("target", me)
    ob.color = TARGET
    sc.collection.objects.link(ob)
    # from the figure's left (Hand_L's side), along the world axis across the move (which is along +Y, +Z)
    fwd = after[frame]["Toes_L"][0] - after[frame]["Foot_L"][0]
    left = Vector((0.0, 0.0, 1.0)).cross(Vector((fwd.x, fwd.y, 0.0)).normalized())
    look = Vector((-1.0 if left.x > 0 else 1.0, 0.0, 0.0))
    points = [list(h) for pose in (before[frame], after[frame]) for n, (h, t, _p) in pose.items()
              if n not in SKIP]
    points += [list(pose[f]["Hand_L"][1]) for pose in (before, after) for f in frames] + [list(target)]
    right = look.cross(Vector((0.0, 0.0, 1.0)))
    top = max(p[2] for p in points) + 0.08
    corner = Vector(min(points, key=lambda p: np.dot(p, right))) - look * 0.5
    for i, text in enumerate(("Edit Tangents: Hand_L at frame 9 to the 3D cursor (red)",
                              "before grey, after blue; lines: the hand over frames 1-16")):
        z = top + 0.09 - 0.05 * i
        label(text, Vector((corner.x, corner.y, z)), (math.pi / 2, 0.0, math.atan2(right.y, right.x)), size=0.035)
        points.append([corner.x, corner.y, z + 0.04])
        points.append(list(Vector((corner.x, corner.y, z)) + right * 0.95))
    height = frame_camera(np.array(points), look, 720, margin=0.05)
    render(out / "blender_edit_tangents.png", 720, height)


def main(argv) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--clip", type=Path, default=CLIP)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "img")
    p.add_argument("--method", default="transformer")
    p.add_argument("--only", choices=["fill", "tangents"])
    args = p.parse_args(argv)
    if not args.clip.exists():
        raise SystemExit(f"needs {args.clip} (Bandai-Namco dataset-2, unpacked by `make corpora`)")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.only in (None, "fill"):
        picture_fill(args.clip, args.out, args.method)
    if args.only in (None, "tangents"):
        picture_tangents(args.clip, args.out)


if __name__ == "__main__":
    main(sys.argv[1:])
