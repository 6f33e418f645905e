"""The Blender side of tests/test_blender_addon.py: runs in ``.venv-blender`` (bpy 5.0.1, keyfill installed there).

    .venv-blender/bin/python tests/interop/blender_addon_check.py convert CLIP.bvh --out r.json
    .venv-blender/bin/python tests/interop/blender_addon_check.py fill CLIP.bvh --zip keyfill.zip --every 15 \
        --method cubic --exported keys.bvh --out r.json
    .venv-blender/bin/python tests/interop/blender_addon_check.py fill CLIP.bvh --zip keyfill.zip --every 15 \
        --method cubic --backend EXECUTABLE --executable .venv/bin/keyfill --no-import --exported keys.bvh --out r.json
    .venv-blender/bin/python tests/interop/blender_addon_check.py refuse CLIP.bvh --zip keyfill.zip \
        --executable /no/such/keyfill --executable NOT_EXECUTABLE --out r.json
    .venv-blender/bin/python tests/interop/blender_addon_check.py tangents CLIP.bvh --zip keyfill.zip --out r.json

``convert``: the clip through Blender's BVH importer (Z-up, metres, as a user imports it; and a second time
with the file's own axes and centimetres, the armature object turned and scaled instead), then through the
extension's convert module; writes keyfill's local arrays and world positions of every frame.
``fill``: installs the extension zip (bpy's ``extensions.package_install_files``, into a user folder under
``$HOME``), imports the clip with its own axes (the object turned Z-up, scaled to metres: so Blender's BVH
exporter, which writes armature space, writes the file's own Y-up centimetres), deletes every key but every
``--every``-th frame, writes those keys with Blender's BVH exporter, runs Fill In-betweens and writes the bone
heads (armature space) at every frame, the operator's time and reports (its INFO report names the backend it
used), and whether undo restored the action. ``--backend``/``--executable`` set the add-on's preferences (*Run
keyfill*, *keyfill Executable*) as a user would; ``--no-import`` makes keyfill unimportable in this Python the way
the add-on asks (:func:`_block_keyfill`), so only the executable can fill.
``refuse``: the clip keyed every ``--every``-th frame, Fill In-betweens with each ``--executable`` under *Run
keyfill: Executable* (keyfill importable), then the first under *Automatic* with keyfill unimportable: each call's
error report, what it wrote to stderr, and whether the action is unchanged.
``tangents``: the clip (Euler rotations) keyed every 15th frame; Edit Tangents moves Hand_L's tail at frame 9
by (0, 0.1, 0.1) m (the 3D cursor); writes the distance left, the keys before and after, and the undo check.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import json
import sys
import time
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "blender"))
from clip_setup import import_clip, keep_every  # blender/: the clip as the pictures set it up too


def _convert_module():
    from keyfill_blender import action, convert

    return action, convert


def cmd_convert(args) -> dict:
    action, convert = _convert_module()
    out = {}
    for label, own in (("default", False), ("object", True)):
        obj = import_clip(args.clip, own)
        rig = convert.rig_from_armature(obj)
        first, last = (round(x) for x in obj.animation_data.action.frame_range)
        frames = np.arange(first, last + 1)
        brot, bloc, _ = action.read_basis(obj, rig, frames)
        rot, pos = convert.to_keyfill(rig, brot, bloc)
        back_rot, back_loc = convert.to_blender(rig, rot, pos)
        dots = np.abs(np.sum(back_rot * brot, axis=-1))
        loc_err = np.abs(np.where(rig.connected[:, None], 0, back_loc - bloc)).max()
        # Blender's own bone heads, in keyfill's frame (K (scene) / meters_per_unit), at a few frames
        blender = []
        for f in frames[:: max(1, len(frames) // 5)]:
            bpy.context.scene.frame_set(int(f))
            mw = obj.matrix_world
            heads = np.array([list(mw @ obj.pose.bones[n].head) for n in rig.names])
            blender.append([int(f - first), (heads @ convert.Z_UP_TO_Y_UP.T / 0.01).tolist()])
        out[label] = {"names": list(rig.names), "world": convert.world_positions(rig, rot, pos).tolist(),
                      "roundtrip_rot": float(1 - dots.min()), "roundtrip_loc": float(loc_err),
                      "blender_heads": blender}
    return out


def _install(zip_path: Path) -> str:
    """Install and enable the extension zip (after the scene is made: a factory reset would disable it)."""
    result = bpy.ops.extensions.package_install_files(filepath=str(zip_path), repo="user_default",
                                                      enable_on_install=True)
    mod = "bl_ext.user_default.keyfill"
    if "FINISHED" not in result or mod not in bpy.context.preferences.addons:
        raise SystemExit(f"the extension did not install: {result}; add-ons: {list(bpy.context.preferences.addons.keys())}")
    bpy.ops.wm.save_userpref()
    return mod


def _use_backend(mod: str, backend: str, executable: str | None) -> None:
    """The add-on's preferences *Run keyfill* (AUTO, PYTHON, EXECUTABLE) and *keyfill Executable*."""
    prefs = bpy.context.preferences.addons[mod].preferences
    prefs.backend = backend
    if executable is not None:
        prefs.executable = executable


def _block_keyfill() -> bool:
    """Make keyfill unimportable here, as in a Blender without it: ``None`` in ``sys.modules`` makes
    ``importlib.util.find_spec`` (what the add-on asks, ``backend.importable``) find nothing and ``import keyfill``
    fail. Returns whether keyfill still imports (False)."""
    for name in [n for n in sys.modules if n == "keyfill" or n.startswith("keyfill.")]:
        del sys.modules[name]
    sys.modules["keyfill"] = None
    return importlib.util.find_spec("keyfill") is not None


def _fill_op(**kw) -> dict:
    """Fill In-betweens with ``kw``: its result (None when it raised), its ERROR report (bpy raises it as
    RuntimeError), its reports (bpy writes an operator's reports to ``sys.stdout``; the INFO one says
    ``keyfill METHOD (python|executable): ...``), what it wrote to ``sys.stderr`` (a traceback would be there),
    and its time."""
    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            result, error = sorted(bpy.ops.keyfill.fill_inbetweens(**kw)), None
        except RuntimeError as e:
            result, error = None, str(e)
    return {"result": result, "error": error, "reports": out.getvalue(), "stderr": err.getvalue(),
            "seconds": time.perf_counter() - t0}


def _undo() -> None:
    """Undo the operator. Blender without a window pushes no undo step after an operator a script calls (the
    UI does, as the operator's UNDO flag asks), so the step is pushed here as the UI would, then undone."""
    if not bpy.ops.ed.undo.poll():
        bpy.ops.ed.undo_push(message="keyfill")
    bpy.ops.ed.undo()


def _keys_snapshot(obj) -> dict:
    from bpy_extras import anim_utils

    ad = obj.animation_data
    cb = anim_utils.action_get_channelbag_for_slot(ad.action, ad.action_slot)
    snap = {}
    for fc in cb.fcurves:
        co = np.empty(2 * len(fc.keyframe_points))
        fc.keyframe_points.foreach_get("co", co)
        snap[f"{fc.data_path}[{fc.array_index}]"] = co.tolist()
    return snap


def _heads(obj, frames) -> list:
    out = []
    for f in frames:
        bpy.context.scene.frame_set(int(f))
        out.append([list(pb.head) for pb in obj.pose.bones])
    return out


def cmd_fill(args) -> dict:
    obj = import_clip(args.clip, own_axes=True)
    mod = _install(args.zip)
    if args.backend:
        _use_backend(mod, args.backend, args.executable[0] if args.executable else None)
    importable = _block_keyfill() if args.no_import else importlib.util.find_spec("keyfill") is not None
    scene = bpy.context.scene
    first, last = (round(x) for x in obj.animation_data.action.frame_range)
    last = min(last, first + args.frames - 1)
    scene.frame_start, scene.frame_end = first, last
    keep_every(obj, args.every, first)
    bpy.ops.export_anim.bvh(filepath=str(args.exported), global_scale=1.0, frame_start=first, frame_end=last,
                            rotate_mode="NATIVE", root_transform_only=False)
    before = _keys_snapshot(obj)
    bpy.ops.ed.undo_push(message="before keyfill")
    call = _fill_op(method=args.method, use_range=True, frame_start=first, frame_end=last)
    if call["result"] is None:
        raise SystemExit(f"Fill In-betweens failed: {call['error']}\n{call['stderr']}")
    obj = bpy.data.objects[obj.name]
    after = _keys_snapshot(obj)
    heads = _heads(obj, range(first, last + 1))
    keys_kept = True
    for k, v in before.items():
        got = dict(zip(after[k][0::2], after[k][1::2]))
        keys_kept &= all(abs(got.get(f, np.inf) - x) < 1e-6 for f, x in zip(v[0::2], v[1::2]))
    n_after = sum(len(v) // 2 for v in after.values())
    name = obj.name
    _undo()
    obj = bpy.data.objects[name]
    undone = _keys_snapshot(obj)
    # a failing call: one ERROR report and CANCELLED, no traceback
    failed = _fill_op(method="transformer", model="/nonexistent/model")
    return {"module": mod, "result": call["result"], "seconds": call["seconds"], "reports": call["reports"],
            "keyfill_importable": importable, "first": first, "last": last,
            "bones": [pb.name for pb in obj.pose.bones], "heads": heads, "keys_kept": bool(keys_kept),
            "points_before": sum(len(v) // 2 for v in before.values()), "points_after": n_after,
            "undo_restored": undone == before, "error_report": failed["error"], "error_stderr": failed["stderr"]}


def cmd_refuse(args) -> dict:
    obj = import_clip(args.clip, own_axes=True)
    mod = _install(args.zip)
    name = obj.name
    keep_every(obj, args.every, round(obj.animation_data.action.frame_range[0]))
    before, actions = _keys_snapshot(obj), len(bpy.data.actions)
    cases = [("EXECUTABLE", exe, False) for exe in args.executable] + [("AUTO", args.executable[0], True)]
    out = []
    for backend, exe, blocked in cases:
        _use_backend(mod, backend, exe)
        importable = _block_keyfill() if blocked else importlib.util.find_spec("keyfill") is not None
        call = _fill_op(method="cubic")
        obj = bpy.data.objects[name]
        out.append({"backend": backend, "executable": exe, "keyfill_importable": importable, **call,
                    "unchanged": _keys_snapshot(obj) == before and len(bpy.data.actions) == actions})
    return {"module": mod, "cases": out}


def cmd_tangents(args) -> dict:
    obj = import_clip(args.clip, own_axes=False, rotate_mode="NATIVE")
    mod = _install(args.zip)
    first = round(obj.animation_data.action.frame_range[0])
    keep_every(obj, 15, first)
    scene = bpy.context.scene
    frame = first + 8
    scene.frame_set(frame)
    bone = obj.data.bones["Hand_L"]
    obj.data.bones.active = bone
    tail = np.array(obj.matrix_world @ obj.pose.bones["Hand_L"].tail)
    target = tail + np.array([0.0, 0.1, 0.1])
    scene.cursor.location = target.tolist()
    before = _keys_snapshot(obj)
    bpy.ops.ed.undo_push(message="before edit")
    t0 = time.perf_counter()
    result = bpy.ops.keyfill.edit_tangents(bone="Hand_L", point="TAIL", target="CURSOR", pins="Hips",
                                           contacts=f"Toes_L:{first}-{first + 15}", tolerance=5e-4)
    seconds = time.perf_counter() - t0
    obj = bpy.data.objects[obj.name]
    scene.frame_set(frame)
    got = np.array(obj.matrix_world @ obj.pose.bones["Hand_L"].tail)
    after = _keys_snapshot(obj)
    changed_values = 0
    for k, v in before.items():
        now = dict(zip(after[k][0::2], after[k][1::2]))
        changed_values += sum(abs(now.get(f, np.inf) - x) > 1e-6 for f, x in zip(v[0::2], v[1::2]))
    heights = [np.array(obj.matrix_world @ obj.pose.bones[n].head)[2] for n in ("Head", "Toes_L", "Toes_R")]
    name = obj.name
    _undo()
    obj = bpy.data.objects[name]
    return {"module": mod, "result": sorted(result), "seconds": seconds, "moved": float(np.linalg.norm(tail - target)),
            "distance": float(np.linalg.norm(got - target)), "changed_key_values": int(changed_values),
            "height": float(max(heights) - min(heights)), "undo_restored": _keys_snapshot(obj) == before}


def main(argv):
    p = argparse.ArgumentParser()
    p.add_argument("command", choices=["convert", "fill", "refuse", "tangents"])
    p.add_argument("clip", type=Path)
    p.add_argument("--zip", type=Path)
    p.add_argument("--every", type=int, default=15)
    p.add_argument("--frames", type=int, default=301)
    p.add_argument("--method", default="cubic")
    p.add_argument("--exported", type=Path)
    p.add_argument("--backend", choices=["AUTO", "PYTHON", "EXECUTABLE"], help="the add-on's *Run keyfill*")
    p.add_argument("--executable", action="append", help="the add-on's *keyfill Executable* (refuse: each in turn)")
    p.add_argument("--no-import", action="store_true", help="keyfill unimportable in Blender's Python")
    p.add_argument("--out", type=Path, required=True)
    args = p.parse_args(argv)
    result = {"convert": cmd_convert, "fill": cmd_fill, "refuse": cmd_refuse, "tangents": cmd_tangents}[args.command](args)
    args.out.write_text(json.dumps(result))


if __name__ == "__main__":
    main(sys.argv[1:])
