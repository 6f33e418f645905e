"""The Edit Tangents operator: keyfill's tangent-space QP (Ciccone et al. 2019) on the action's F-curves.

The F-curves map one to one onto keyfill's :class:`~keyfill.curves.Curves`: a bone in an Euler rotation
mode ``"XYZ"`` has the controls ``Zrotation, Yrotation, Xrotation`` (keyfill's intrinsic order is the mode
reversed) about its own axes, and its location F-curves are ``X/Y/Zposition`` in its rest frame. Each bone
is two keyfill joints: a fixed one carrying the bone's rest placement relative to its parent (its offset
and the rest rotation as three constant, locked Euler controls) and the bone itself (offset zero, its F-curve
controls). Keyfill's world is the armature's space here (metres, Z-up; no conversion is needed, since the
F-curves are edited as they are). A Blender key ``(t, v)`` with handles ``(tl, vl)`` and ``(tr, vr)`` has
keyfill's tangents ``in = (t - tl, v - vl)`` and ``out = (tr - t, vr - v)``. Controls keyed at other frames
than the rest get keys where the others have them, placed by de Casteljau's split, so their curves keep
their shape (the "new keys when the solver needs them"); the keys themselves never move.
"""

from __future__ import annotations

import bpy
import numpy as np

from . import action, backend, convert


class EditError(ValueError):
    pass


_LOCK_NAME = "@rest"


def _chain(bone) -> list:
    out = []
    while bone is not None:
        out.append(bone)
        bone = bone.parent
    return out[::-1]


def _bezier_points(fc) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(times, values, in_tan (K, 2), out_tan (K, 2))`` of an F-curve, with Blender's own correction of
    handles that overlap (so keyfill evaluates the curve as Blender plays it)."""
    kps = fc.keyframe_points
    K = len(kps)
    co, hl, hr = np.empty(2 * K), np.empty(2 * K), np.empty(2 * K)
    kps.foreach_get("co", co)
    kps.foreach_get("handle_left", hl)
    kps.foreach_get("handle_right", hr)
    co, hl, hr = co.reshape(K, 2), hl.reshape(K, 2), hr.reshape(K, 2)
    in_tan, out_tan = co - hl, hr - co
    for k in range(K - 1):
        interp = kps[k].interpolation
        seg = co[k + 1, 0] - co[k, 0]
        if interp == "LINEAR":
            slope = (co[k + 1, 1] - co[k, 1]) / seg
            out_tan[k] = in_tan[k + 1] = (seg / 3, slope * seg / 3)
        elif interp != "BEZIER":
            raise EditError(f"{fc.data_path}[{fc.array_index}]: the key at frame {co[k, 0]:g} interpolates "
                            f"{interp.lower()}; edit tangents works on Bezier and linear keys")
        w1, w2 = max(out_tan[k, 0], 0.0), max(in_tan[k + 1, 0], 0.0)
        if w1 + w2 > seg:  # BKE_fcurve_correct_bezpart
            fac = seg / (w1 + w2)
            out_tan[k] *= fac
            in_tan[k + 1] *= fac
    return co[:, 0], co[:, 1], in_tan, out_tan


def _split(times, values, in_tan, out_tan, at: float):
    """Insert a key at time ``at`` into a Bezier curve without changing its shape (de Casteljau)."""
    from keyfill.curves import solve_bezier_time

    k = int(np.searchsorted(times, at) - 1)
    if k < 0 or k >= len(times) - 1:  # outside the keys the curve holds: a flat key
        v = values[0] if k < 0 else values[-1]
        i = 0 if k < 0 else len(times)
        zero = np.zeros(2)
        return (np.insert(times, i, at), np.insert(values, i, v), np.insert(in_tan, i, zero, axis=0),
                np.insert(out_tan, i, zero, axis=0))
    p0 = np.array([times[k], values[k]])
    p3 = np.array([times[k + 1], values[k + 1]])
    p1, p2 = p0 + out_tan[k], p3 - in_tan[k + 1]
    seg = p3[0] - p0[0]
    lam = float(solve_bezier_time(np.array([(at - p0[0]) / seg]), np.array([(p1[0] - p0[0]) / seg]),
                                  np.array([(p2[0] - p0[0]) / seg]))[0])
    a, b, c = p0 + lam * (p1 - p0), p1 + lam * (p2 - p1), p2 + lam * (p3 - p2)
    d, e = a + lam * (b - a), b + lam * (c - b)
    s = d + lam * (e - d)
    out_tan, in_tan = out_tan.copy(), in_tan.copy()
    out_tan[k], in_tan[k + 1] = a - p0, p3 - c
    i = k + 1
    return (np.insert(times, i, s[0]), np.insert(values, i, s[1]), np.insert(in_tan, i, s - d, axis=0),
            np.insert(out_tan, i, e - s, axis=0))


class _Model:
    """The keyfill skeleton and curves of the bones an edit needs (the chains of the edited, pinned and
    contact bones), with the F-curve of each control (None: a constant, locked control)."""

    def __init__(self, obj, bone_names: list[str]):
        arm = obj.data
        cb = action.channelbag(obj)
        if cb is None:
            raise EditError(f"{obj.name!r} has no action")
        bones, seen = [], set()
        for name in bone_names:
            for b in _chain(arm.bones[name]):
                if b.name not in seen:
                    seen.add(b.name)
                    bones.append(b)
        bones.sort(key=lambda b: len(_chain(b)))
        self.names, parents, offsets, chans = [], [], [], []
        self.controls, self.sources, self.constants = [], [], []  # (joint, channel), fcurve, value
        self.bone_joint = {}
        for b in bones:
            pb = obj.pose.bones[b.name]
            if pb.rotation_mode not in convert.EULER_MODES:
                quat = action._curves(cb, pb, "rotation_quaternion", 4)
                if any(fc is not None for fc in quat):
                    raise EditError(f"bone {b.name!r} animates a quaternion; edit tangents works on Euler F-curves "
                                    "(set its rotation mode to an Euler order and re-key)")
            rest = b.matrix_local if b.parent is None else b.parent.matrix_local.inverted() @ b.matrix_local
            fixed = len(self.names)
            self.names.append(b.name + _LOCK_NAME)
            parents.append(self.bone_joint[b.parent.name] if b.parent else -1)
            offsets.append(list(rest.to_translation()))
            chans.append(("Zrotation", "Yrotation", "Xrotation"))
            e = rest.to_3x3().to_euler("XYZ")  # R = Rz Ry Rx: keyfill's intrinsic ZYX
            for ch, v in zip(("Zrotation", "Yrotation", "Xrotation"), (e.z, e.y, e.x)):
                self.controls.append((fixed, ch))
                self.sources.append(None)
                self.constants.append(v)
            joint = len(self.names)
            self.bone_joint[b.name] = joint
            self.names.append(b.name)
            parents.append(fixed)
            offsets.append([0.0, 0.0, 0.0])
            mine = []
            loc = action._curves(cb, pb, "location", 3)
            if not (b.use_connect and b.parent) and (any(fc is not None for fc in loc) or any(pb.location)):
                for i, ch in enumerate(("Xposition", "Yposition", "Zposition")):
                    mine.append(ch)
                    self.controls.append((joint, ch))
                    self.sources.append(loc[i])
                    self.constants.append(pb.location[i])
            if pb.rotation_mode in convert.EULER_MODES:
                mode = pb.rotation_mode
                rot = action._curves(cb, pb, "rotation_euler", 3)
                for axis in convert.keyfill_order(mode):
                    i = "XYZ".index(axis)
                    mine.append(axis + "rotation")
                    self.controls.append((joint, axis + "rotation"))
                    self.sources.append(rot[i])
                    self.constants.append(pb.rotation_euler[i])
            else:  # a quaternion bone that is not animated: its pose rotation is constant
                e = pb.rotation_quaternion.to_euler("XYZ")
                for ch, v in zip(("Zrotation", "Yrotation", "Xrotation"), (e.z, e.y, e.x)):
                    mine.append(ch)
                    self.controls.append((joint, ch))
                    self.sources.append(None)
                    self.constants.append(v)
            chans.append(tuple(mine))
        self.parents, self.offsets, self.channels = parents, np.array(offsets), tuple(chans)

    def curves(self, fps: float):
        from keyfill.curves import Curves
        from keyfill.motion import Skeleton

        data = [_bezier_points(fc) if fc is not None and len(fc.keyframe_points) else None for fc in self.sources]
        times = sorted({float(t) for d in data if d is not None for t in d[0]})
        if len(times) < 2:
            raise EditError("the bones of this edit have fewer than two keys")
        self.keyed = [d is not None for d in data]
        C, K = len(self.controls), len(times)
        values, in_tan, out_tan = np.zeros((K, C)), np.zeros((K, C, 2)), np.zeros((K, C, 2))
        self.added = []  # (control, time) of keys the split inserted
        for c, d in enumerate(data):
            if d is None:
                values[:, c] = self.constants[c]
                continue
            t, v, i_t, o_t = d
            for at in times:
                if not np.any(np.abs(t - at) < 1e-6):
                    t, v, i_t, o_t = _split(t, v, i_t, o_t, at)
                    self.added.append((c, at))
            values[:, c], in_tan[:, c], out_tan[:, c] = v, i_t, o_t
        # widths of flat (constant) controls: a third of each neighbouring segment
        seg = np.diff(times)
        for c, d in enumerate(data):
            if d is None:
                out_tan[:-1, c, 0] = seg / 3
                in_tan[1:, c, 0] = seg / 3
        slope_in = in_tan[..., 1] / np.where(in_tan[..., 0] > 0, in_tan[..., 0], 1)
        slope_out = out_tan[..., 1] / np.where(out_tan[..., 0] > 0, out_tan[..., 0], 1)
        broken = np.abs(slope_in - slope_out) > 1e-6 * (1 + np.abs(slope_in))
        broken[0] = broken[-1] = False
        sk = Skeleton(names=tuple(self.names), parents=self.parents, offsets=self.offsets, channels=self.channels,
                      meters_per_unit=1.0, up_axis="Z")
        self.times = np.array(times)
        return Curves(sk, fps, int(np.ceil(times[-1])) + 1, tuple(self.controls), self.times, values, in_tan,
                      out_tan, broken)

    def write(self, curves) -> int:
        """Write the edited tangents (and the split keys) into the F-curves; returns the keys changed."""
        changed = 0
        for c, fc in enumerate(self.sources):
            if fc is None or not self.keyed[c]:
                continue
            kps = fc.keyframe_points
            for k, t in enumerate(curves.times):
                v = curves.values[k, c]
                kp = next((p for p in kps if abs(p.co[0] - t) < 1e-6), None)
                if kp is None:
                    kp = kps.insert(t, v, options={"FAST"})
                    kp.co = (t, v)
                iw, ih = curves.in_tan[k, c]
                ow, oh = curves.out_tan[k, c]
                left, right = (t - iw, v - ih), (t + ow, v + oh)
                if (np.allclose(kp.handle_left, left, atol=1e-5) and np.allclose(kp.handle_right, right, atol=1e-5)
                        and kp.interpolation == "BEZIER"):
                    continue
                kp.interpolation = "BEZIER"
                # FREE: Blender recomputes neither handle (ALIGNED would move one to match the other's
                # direction at float32 precision, AUTO would recompute both); unified keys stay unified
                kp.handle_left_type = kp.handle_right_type = "FREE"
                kp.handle_left, kp.handle_right = left, right
                changed += 1
            fc.update()
        return changed


def _bone_names(obj, text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    for n in names:
        if n not in obj.data.bones:
            raise EditError(f"no bone {n!r} in {obj.name!r}")
    return names


def _contacts(obj, text: str) -> list[tuple[str, float, float]]:
    """``"Toes_L:1-15, Toes_R:20-30"`` -> [(bone, start, end)]."""
    out = []
    for part in [p.strip() for p in text.split(",") if p.strip()]:
        bone, _, span = part.rpartition(":")
        try:
            a, b = (float(x) for x in span.split("-"))
        except ValueError:
            raise EditError(f"contact {part!r}: write Bone:start-end (frames of two keys)") from None
        _bone_names(obj, bone)
        out.append((bone, a, b))
    return out


class KEYFILL_OT_edit_tangents(bpy.types.Operator):
    """Move a bone through a target at a frame between keys by changing only the F-curves' tangents"""

    bl_idname = "keyfill.edit_tangents"
    bl_label = "Edit Tangents (keyfill)"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012 (Blender reads a set)

    bone: bpy.props.StringProperty(name="Bone", description="The bone to move (empty: the active bone)")
    point: bpy.props.EnumProperty(name="Point", default="TAIL", items=[
        ("TAIL", "Tail", "The bone's tail passes through the target"),
        ("HEAD", "Head", "The bone's head passes through the target")])
    frame: bpy.props.FloatProperty(name="Frame", default=-1.0,
                                   description="Frame of the edit, between two keys (-1: the current frame)")
    target: bpy.props.EnumProperty(name="Target", default="CURSOR", items=[
        ("CURSOR", "3D Cursor", "The 3D cursor's location"),
        ("OBJECT", "Object", "The location of an object (an empty)")])
    target_object: bpy.props.StringProperty(name="Target Object", description="The empty (or any object)")
    pins: bpy.props.StringProperty(name="Pins", description="Bones whose paths stay (comma-separated)")
    contacts: bpy.props.StringProperty(name="Contacts",
                                       description="Bone:start-end, comma-separated: the bone's head stays put "
                                                   "between those two keys")
    break_tangents: bpy.props.BoolProperty(name="Only This Segment", default=False,
                                           description="Break the two keys' tangents and change only this segment")
    tolerance: bpy.props.FloatProperty(name="Tolerance", default=0.0, min=0.0,
                                       description="Reach the target this closely (0: 1e-3 of the character's size)")
    epsilon: bpy.props.FloatProperty(name="Epsilon", default=0.0, min=0.0,
                                     description="Pin and contact band (0: 1e-4 of the character's size)")
    best_effort: bpy.props.BoolProperty(name="Best Effort", default=False,
                                        description="Keep the closest result when the target is out of reach")

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE"

    def execute(self, context):
        try:
            msg = self._edit(context)
        except (EditError, action.ActionError, backend.BackendError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        except Exception as e:  # noqa: BLE001 (one line in Blender, details in the console)
            if type(e).__module__.startswith("keyfill"):  # KeyfillError: keyfill's own one line
                self.report({"ERROR"}, f"keyfill: {e}")
                return {"CANCELLED"}
            import traceback

            traceback.print_exc()
            self.report({"ERROR"}, f"keyfill failed: {type(e).__name__}: {e}")
            return {"CANCELLED"}
        self.report({"INFO"}, msg)
        return {"FINISHED"}

    def _edit(self, context) -> str:
        from .fill import backend_of

        if backend_of(context)[0] != "python":
            raise EditError("edit tangents needs keyfill importable in Blender's Python (see docs/blender.md)")
        from keyfill.edit.edits import Contact, EditFile, Manipulation
        from keyfill.edit.rig import Point
        from keyfill.edit.solve import edit_tangents

        obj = context.active_object
        name = self.bone or (obj.data.bones.active.name if obj.data.bones.active else "")
        if not name or name not in obj.data.bones:
            raise EditError("select a bone (or name it in the operator's Bone field)")
        pins = _bone_names(obj, self.pins)
        contacts = _contacts(obj, self.contacts)
        model = _Model(obj, [name, *pins, *(c[0] for c in contacts)])
        curves = model.curves(backend.frame_rate(context.scene))
        t = float(context.scene.frame_current if self.frame < 0 else self.frame)
        if not curves.times[0] < t < curves.times[-1] or curves.key_index(t) is not None:
            raise EditError(f"frame {t:g} is not between two keys of {name!r}'s chain (keys "
                            f"{curves.times[0]:g} to {curves.times[-1]:g})")
        if self.target == "CURSOR":
            world = np.array(context.scene.cursor.location)
        else:
            target = context.scene.objects.get(self.target_object)
            if target is None:
                raise EditError(f"no object {self.target_object!r} to aim at")
            world = np.array(target.matrix_world.translation)
        inv = obj.matrix_world.inverted()
        goal = np.array(inv @ type(obj.matrix_world.translation)(world))
        bone = obj.data.bones[name]
        offset = np.array([0.0, bone.length, 0.0]) if self.point == "TAIL" else np.zeros(3)
        locked = frozenset(i for i, s in enumerate(model.sources) if s is None or not model.keyed[i])
        edit = Manipulation(index=1, line=0, point=Point(model.bone_joint[name], offset), time=t, target=goal,
                            move=None, orientation=None, holds=(), pins=(), contacts=(),
                            break_tangents=self.break_tangents)
        ef = EditFile(path="(Blender)", edits=(edit,),
                      pins=tuple(Point(model.bone_joint[p]) for p in pins),
                      contacts=tuple(Contact(Point(model.bone_joint[b]), a, z) for b, a, z in contacts),
                      locked=locked, tolerance=self.tolerance or None, epsilon=self.epsilon or None)
        edited, reports = edit_tangents(curves, ef, best_effort=self.best_effort)
        changed = model.write(edited)
        context.scene.frame_set(context.scene.frame_current)
        r = reports[0]
        return (f"keyfill: {name} at frame {t:g} {'reached' if r.reached else 'stopped'} "
                f"{r.distance:.3g} m from the target; {changed} keys' handles written, {len(model.added)} keys "
                f"added, {r.iterations} iteration(s)")
