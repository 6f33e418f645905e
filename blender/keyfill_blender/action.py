"""The armature's action: its keyed frames, its pose bones' basis at any frame, and writing keys back.

Blender 4.4+ keeps F-curves in an action's layers, per slot (a *channelbag*); ``bpy_extras.anim_utils``
finds it. Values here are Blender's own (a bone's ``rotation_quaternion`` or ``rotation_euler`` in its
rotation mode, ``location`` in its rest frame); :mod:`.convert` turns them into keyfill's.
"""

from __future__ import annotations

import numpy as np

from . import convert


class ActionError(ValueError):
    """What keeps an armature's action from being filled or edited (one line for the report)."""


def channelbag(obj, create: bool = False):
    """The channelbag of ``obj``'s action and slot (None without one, unless ``create``)."""
    from bpy_extras import anim_utils

    ad = obj.animation_data
    if ad is None or ad.action is None:
        return None
    if ad.action_slot is None:
        if not create:
            return None
        ad.action_slot = ad.action.slots.new(id_type="OBJECT", name=obj.name)
    get = anim_utils.action_ensure_channelbag_for_slot if create else anim_utils.action_get_channelbag_for_slot
    return get(ad.action, ad.action_slot)


def bone_curves(obj) -> list:
    """The F-curves of ``obj``'s action that animate its pose bones."""
    cb = channelbag(obj)
    return [fc for fc in cb.fcurves if fc.data_path.startswith("pose.bones[")] if cb is not None else []


def key_frames(obj, selected_only: bool = False) -> np.ndarray:
    """The frames where the armature's pose bones are keyed (on any F-curve), or where a selected key is."""
    frames = set()
    for fc in bone_curves(obj):
        n = len(fc.keyframe_points)
        co = np.empty(2 * n)
        fc.keyframe_points.foreach_get("co", co)
        if selected_only:
            sel = np.empty(n, dtype=bool)
            fc.keyframe_points.foreach_get("select_control_point", sel)
            co = co.reshape(n, 2)[sel].reshape(-1)
        frames.update(co[0::2].tolist())
    whole = np.array(sorted(frames))
    if len(whole) and np.any(np.abs(whole - np.round(whole)) > 1e-4):
        bad = whole[np.abs(whole - np.round(whole)) > 1e-4][0]
        raise ActionError(f"a key sits between frames (frame {bad:g}); keyfill fills whole frames: snap the keys "
                          "to frames first (Key > Snap > Selection to Nearest Frame)")
    return np.unique(np.round(whole).astype(np.int64))


def _mode(pb) -> str:
    if pb.rotation_mode == "AXIS_ANGLE":
        raise ActionError(f"bone {pb.name!r} rotates by axis and angle; set its rotation mode to quaternion or "
                          "an Euler order")
    return pb.rotation_mode


def _curves(cb, pb, prop: str, n: int) -> list:
    path = pb.path_from_id(prop)
    return [cb.fcurves.find(path, index=i) if cb is not None else None for i in range(n)]


def bvh_orders(obj, rig: convert.Rig) -> tuple[str, ...]:
    """Each bone's keyfill Euler order as Blender's BVH exporter writes it (:func:`.convert.bvh_order`)."""
    return tuple(convert.bvh_order(obj.pose.bones[name].rotation_mode) for name in rig.names)


def read_basis(obj, rig: convert.Rig, frames) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rotations (F, J, 4), locations (F, J, 3), moving (J,))``: every bone's basis at ``frames``, evaluated
    from the action's F-curves (a channel without one keeps its pose value); ``moving``: the bone has
    location F-curves."""
    frames = np.asarray(frames, dtype=np.float64)
    cb = channelbag(obj)
    F, J = len(frames), rig.num_bones
    rot, loc, moving = np.empty((F, J, 4)), np.empty((F, J, 3)), np.zeros(J, bool)

    def values(curves, static):
        return np.stack([np.array([fc.evaluate(f) for f in frames]) if fc is not None else np.full(F, s)
                         for fc, s in zip(curves, static)], axis=-1)

    for j, name in enumerate(rig.names):
        pb = obj.pose.bones[name]
        mode = _mode(pb)
        if mode == "QUATERNION":
            q = values(_curves(cb, pb, "rotation_quaternion", 4), tuple(pb.rotation_quaternion))
        else:
            q = convert.euler_to_quat(values(_curves(cb, pb, "rotation_euler", 3), tuple(pb.rotation_euler)), mode)
        norm = np.linalg.norm(q, axis=-1, keepdims=True)
        if np.any(norm < 1e-9):
            raise ActionError(f"bone {name!r} has a zero quaternion at some key")
        rot[:, j] = q / norm
        lc = _curves(cb, pb, "location", 3)
        moving[j] = any(fc is not None for fc in lc)
        loc[:, j] = values(lc, tuple(pb.location))
    return rot, loc, moving


def _write_curve(cb, path: str, index: int, group: str, frames: np.ndarray, values: np.ndarray,
                 replace: set) -> None:
    """Key ``values`` at ``frames`` on one F-curve: points at frames in ``replace`` are replaced, frames that
    already have a point and are not in ``replace`` are left as they are."""
    fc = cb.fcurves.find(path, index=index)
    if fc is None:
        fc = cb.fcurves.new(path, index=index, group_name=group)
    kps = fc.keyframe_points
    n = len(kps)
    co = np.empty(2 * n)
    kps.foreach_get("co", co)
    have = np.round(co[0::2]).astype(np.int64)
    for i in reversed(range(n)):
        if int(have[i]) in replace:
            kps.remove(kps[i], fast=True)
    kept = {int(f) for f in have if int(f) not in replace}
    new = np.array([f not in kept for f in frames.tolist()], dtype=bool)
    m = int(new.sum())
    if m:
        start = len(kps)
        kps.add(m)
        co = np.empty(2 * len(kps))
        kps.foreach_get("co", co)
        co = co.reshape(-1, 2)
        co[start:, 0] = frames[new]
        co[start:, 1] = values[new]
        kps.foreach_set("co", co.reshape(-1))
        for kp in kps[start:]:
            kp.interpolation = "BEZIER"
            kp.handle_left_type = kp.handle_right_type = "AUTO_CLAMPED"
    fc.update()


def write_basis(obj, rig: convert.Rig, frames, rot: np.ndarray, loc: np.ndarray, replace, write_location) -> None:
    """Key every bone's basis ``rot (F, J, 4)`` (in its rotation mode) and, where ``write_location (J,)``, its
    ``loc (F, J, 3)`` at ``frames``; points at frames of ``replace`` are replaced, other existing points
    kept. Quaternions are made continuous (no sign flips between neighbouring frames)."""
    from mathutils import Euler, Quaternion

    frames = np.asarray(frames, dtype=np.int64)
    replace = {int(f) for f in replace}
    cb = channelbag(obj, create=True)
    for j, name in enumerate(rig.names):
        pb = obj.pose.bones[name]
        mode = _mode(pb)
        q = rot[:, j].copy()
        for i in range(1, len(q)):
            if np.dot(q[i], q[i - 1]) < 0:
                q[i] = -q[i]
        if mode == "QUATERNION":
            prop, vals = "rotation_quaternion", q
        else:
            prev = Euler(tuple(pb.rotation_euler), mode)
            vals = np.empty((len(q), 3))
            for i, qi in enumerate(q):
                prev = Quaternion(qi).to_euler(mode, prev)
                vals[i] = tuple(prev)
            prop = "rotation_euler"
        path = pb.path_from_id(prop)
        for i in range(vals.shape[1]):
            _write_curve(cb, path, i, name, frames, vals[:, i], replace)
        if write_location[j]:
            path = pb.path_from_id("location")
            for i in range(3):
                _write_curve(cb, path, i, name, frames, loc[:, j, i], replace)
