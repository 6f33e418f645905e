"""The Fill In-betweens operator: the active armature's keyed frames are the keys, keyfill fills the gaps."""

from __future__ import annotations

import time

import bpy
import numpy as np

from . import action, backend, convert

#: keyfill complete's methods (the registry's names), cubic first: the CLI's default
METHODS = [
    ("cubic", "Cubic", "C1 cubic spline through the keys (quaternions): keyfill's default"),
    ("linear", "Linear", "Linear interpolation (slerp)"),
    ("velocity", "Velocity", "Spline that keeps the keys' velocities"),
    ("transformer", "Transformer", "The shipped human transformer (models/bandai, CC BY-NC 4.0)"),
    ("gan", "GAN", "The shipped generative tweening model (models/bandai, CC BY-NC 4.0)"),
    ("match", "Match", "Real motion from the shipped motion library (models/bandai, CC BY-NC 4.0)"),
    ("arnn", "ARNN", "The lamp's ARNN (a model folder for other skeletons)"),
]
FEET = [("DEFAULT", "Method's default", "free for most methods, lock for match"),
        ("LOCK", "Lock", "Hold the feet still where they touch the ground"),
        ("FREE", "Free", "The method's output as it is")]
GUARD = [("DEFAULT", "Default (fallback)", "Unfamiliar gaps fall back to cubic"),
         ("FALLBACK", "Fallback", "Unfamiliar gaps fall back to cubic"),
         ("WARN", "Warn", "Only report unfamiliar gaps"),
         ("OFF", "Off", "Do not score the gaps")]


def rig_map_of(obj) -> dict | None:
    """The role map edited in the panel (roles with a bone), for keyfill's rig bridge; None when empty."""
    out = {}
    for item in getattr(obj.data, "keyfill_roles", ()):
        bones = [b.strip() for b in item.bone.split(",") if b.strip()]
        if bones:
            out[item.role] = bones if item.role in ("spine", "neck") else bones[0]
    return out or None


def preferences(context):
    addon = context.preferences.addons.get(__package__)
    return addon.preferences if addon is not None else None


def backend_of(context) -> tuple[str, str]:
    prefs = preferences(context)
    mode = prefs.backend if prefs else "AUTO"
    exe = prefs.executable if prefs else ""
    return backend.choose(mode, exe, prefs.python_path if prefs else ""), exe


class KEYFILL_OT_fill_inbetweens(bpy.types.Operator):
    """Fill the frames between the active armature's keys with keyfill (keys stay as they are)"""

    bl_idname = "keyfill.fill_inbetweens"
    bl_label = "Fill In-betweens (keyfill)"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012 (Blender reads a set)

    method: bpy.props.EnumProperty(name="Method", items=METHODS, default="cubic")
    model: bpy.props.StringProperty(name="Model", subtype="DIR_PATH",
                                    description="Model folder or .onnx graph (empty: the method's shipped model)")
    seed: bpy.props.IntProperty(name="Seed", default=0, min=0)
    feet: bpy.props.EnumProperty(name="Feet", items=FEET, default="DEFAULT")
    guard: bpy.props.EnumProperty(name="Guard", items=GUARD, default="DEFAULT")
    selected_only: bpy.props.BoolProperty(name="Selected Keys Only", default=False,
                                          description="Only the frames of selected keys are keys; others are refilled")
    use_range: bpy.props.BoolProperty(name="Frame Range", default=False,
                                      description="Only keys inside the frame range (default: all keys)")
    frame_start: bpy.props.IntProperty(name="Start", default=1)
    frame_end: bpy.props.IntProperty(name="End", default=250)
    output: bpy.props.EnumProperty(name="Result", default="SAME", items=[
        ("SAME", "Same Action", "Key the in-betweens into the armature's action"),
        ("NEW", "New Action", "Key them into a copy of the action, assigned to the armature")])
    meters_per_unit: bpy.props.FloatProperty(name="keyfill Unit (m)", default=0.01, min=1e-6, precision=4,
                                             description="Metres per keyfill unit (0.01: centimetres, as the "
                                                         "Bandai-Namco files and the human models)")

    @classmethod
    def poll(cls, context):
        obj = context.active_object
        return obj is not None and obj.type == "ARMATURE"

    def execute(self, context):
        wm = context.window_manager
        wm.progress_begin(0, 4)
        try:
            info = self._fill(context, wm)
        except (action.ActionError, backend.BackendError, convert.ConversionError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        except Exception as e:  # noqa: BLE001 (never a traceback in Blender's face: one line, details in the console)
            import traceback

            traceback.print_exc()
            self.report({"ERROR"}, f"keyfill failed: {type(e).__name__}: {e}")
            return {"CANCELLED"}
        finally:
            wm.progress_end()
            if context.workspace is not None:
                context.workspace.status_text_set(None)
        self.report({"INFO"}, info)
        return {"FINISHED"}

    def _status(self, context, wm, step: int, text: str) -> None:
        wm.progress_update(step)
        if context.workspace is not None:
            context.workspace.status_text_set(f"keyfill: {text}")

    def _fill(self, context, wm) -> str:
        obj = context.active_object
        if obj.animation_data is None or obj.animation_data.action is None:
            raise action.ActionError(f"{obj.name!r} has no action to fill; key some poses first")
        keys = action.key_frames(obj, self.selected_only)
        if self.use_range:
            keys = keys[(keys >= self.frame_start) & (keys <= self.frame_end)]
        if len(keys) < 2:
            raise action.ActionError(f"{len(keys)} keyed frame(s){' selected' if self.selected_only else ''}"
                                     f"{' in the frame range' if self.use_range else ''}; keyfill needs two or more")
        where, exe = backend_of(context)
        self._status(context, wm, 1, f"reading {len(keys)} keys")
        t0 = time.perf_counter()
        rig = convert.rig_from_armature(obj, self.meters_per_unit)
        first = int(keys[0])
        frames = np.arange(first, int(keys[-1]) + 1)
        krot, kloc, moving = action.read_basis(obj, rig, keys)
        held = np.searchsorted(keys, frames, side="right") - 1  # every frame holds its last key (never read)
        rot, loc = krot[held], kloc[held]
        settings = backend.Settings(self.method, self.model.strip(), self.seed, self.feet, self.guard, rig_map_of(obj))
        self._status(context, wm, 2, f"{self.method} over {len(frames)} frames")
        out_rot, out_loc, _report = backend.complete(rig, rot, loc, moving, backend.frame_rate(context.scene),
                                                     keys - first, settings, where, exe,
                                                     orders=action.bvh_orders(obj, rig))
        self._status(context, wm, 3, "keying the in-betweens")
        at_keys = keys - first
        out_rot[at_keys], out_loc[at_keys] = krot, kloc  # the keys exactly as they were
        if self.output == "NEW":
            ad = obj.animation_data
            slot = ad.action_slot
            new = ad.action.copy()
            new.name = ad.action.name + ".keyfill"
            ad.action = new
            if slot is not None and ad.action_slot is None:
                ad.action_slot = new.slots[slot.identifier]
        gaps = sorted(set(frames.tolist()) - set(keys.tolist()))
        still = np.ptp(out_loc, axis=0).max(axis=-1) < 1e-9
        write_loc = moving | (~rig.connected & ~still)
        action.write_basis(obj, rig, frames, out_rot, out_loc, gaps, write_loc)
        context.scene.frame_set(context.scene.frame_current)  # pose follows the new keys
        return (f"keyfill {self.method} ({where}): filled {len(gaps)} frames between {len(keys)} keys in "
                f"{time.perf_counter() - t0:.2f} s")
