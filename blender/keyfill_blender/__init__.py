"""keyfill inside Blender: Fill In-betweens and Edit Tangents on an armature's action (MIT).

keyfill runs in Blender's own Python where it imports (installed there, or found in the folder the
preferences name), otherwise through a ``keyfill`` executable (docs/blender.md says why no wheels are
bundled). The pose-bone <-> keyfill conversion is :mod:`.convert`, the one place Blender's rest-pose and
axis conventions are handled.
"""

from __future__ import annotations

import bpy

from . import backend, fill, tangents

#: keyfill's humanoid roles (keyfill.characters.humanoid.ROLES), for the role map panel
ROLES = ("hips", "spine", "neck", "head") + tuple(
    f"{r}_{s}" for s in ("l", "r") for r in ("clavicle", "upper_arm", "forearm", "hand", "thigh", "shin", "foot", "toe"))


class KeyfillPreferences(bpy.types.AddonPreferences):
    bl_idname = __package__

    backend: bpy.props.EnumProperty(name="Run keyfill", default="AUTO", items=[
        ("AUTO", "Automatic", "In Blender's Python when keyfill imports there, else the executable"),
        ("PYTHON", "Blender's Python", "Import keyfill (installed in Blender's Python or in the folder below)"),
        ("EXECUTABLE", "Executable", "Run the keyfill executable below (a BVH file goes between)")])
    executable: bpy.props.StringProperty(name="keyfill Executable", subtype="FILE_PATH", default="keyfill",
                                         description="Path of the keyfill command (default: keyfill on PATH)")
    python_path: bpy.props.StringProperty(name="keyfill site-packages", subtype="DIR_PATH",
                                          description="A site-packages folder (Python 3.11, numpy 1.26) where "
                                                      "keyfill is installed, added to Blender's Python")

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "backend")
        layout.prop(self, "executable")
        layout.prop(self, "python_path")
        backend.add_python_path(self.python_path)
        layout.label(text="keyfill imports here" if backend.importable() else "keyfill does not import here")


class KeyfillRole(bpy.types.PropertyGroup):
    role: bpy.props.StringProperty(name="Role")
    bone: bpy.props.StringProperty(name="Bone", description="Bone (spine, neck: comma-separated, bottom to top)")


class KEYFILL_OT_detect_roles(bpy.types.Operator):
    """Fill the role map with the roles keyfill's rig mapper finds (edit what it gets wrong)"""

    bl_idname = "keyfill.detect_roles"
    bl_label = "Detect Roles"
    bl_options = {"REGISTER", "UNDO"}  # noqa: RUF012 (Blender reads a set)

    @classmethod
    def poll(cls, context):
        return context.active_object is not None and context.active_object.type == "ARMATURE"

    def execute(self, context):
        from . import convert

        obj = context.active_object
        try:
            if fill.backend_of(context)[0] != "python":
                raise backend.BackendError("detecting roles needs keyfill importable in Blender's Python")
            from keyfill.characters.humanoid import map_roles
            from keyfill.errors import KeyfillError

            rig = convert.rig_from_armature(obj)
            sk = convert.to_motion(rig, *_rest_arrays(rig), 30.0).skeleton
            try:
                roles = map_roles(sk, fill.rig_map_of(obj), label=obj.name)
            except KeyfillError as e:
                raise backend.BackendError(str(e)) from None
        except (backend.BackendError, convert.ConversionError) as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        found = {"hips": [roles.hips], "spine": list(roles.spine), "neck": list(roles.neck), "head": [roles.head]}
        found.update({r: [j] for r, j in roles.limbs.items()})
        items = obj.data.keyfill_roles
        items.clear()
        for role in ROLES:
            item = items.add()
            item.role = role
            item.bone = ", ".join(sk.names[j] for j in found.get(role, []))
        self.report({"INFO"}, f"{sum(1 for i in items if i.bone)} roles found")
        return {"FINISHED"}


def _rest_arrays(rig):
    import numpy as np

    rot = np.zeros((1, rig.num_bones, 4))
    rot[..., 0] = 1
    return rot, np.zeros((1, rig.num_bones, 3))


class KEYFILL_PT_roles(bpy.types.Panel):
    bl_label = "keyfill Roles"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "data"

    @classmethod
    def poll(cls, context):
        return context.armature is not None

    def draw(self, context):
        layout = self.layout
        layout.operator(KEYFILL_OT_detect_roles.bl_idname)
        arm = context.armature
        for item in arm.keyfill_roles:
            if item.role in ("spine", "neck"):
                layout.prop(item, "bone", text=item.role)
            else:
                layout.prop_search(item, "bone", arm, "bones", text=item.role)


def _fill_menu(self, context):
    self.layout.separator()
    self.layout.operator(fill.KEYFILL_OT_fill_inbetweens.bl_idname)


def _graph_menu(self, context):
    self.layout.separator()
    self.layout.operator(fill.KEYFILL_OT_fill_inbetweens.bl_idname)
    self.layout.operator(tangents.KEYFILL_OT_edit_tangents.bl_idname)


CLASSES = (KeyfillPreferences, KeyfillRole, KEYFILL_OT_detect_roles, KEYFILL_PT_roles,
           fill.KEYFILL_OT_fill_inbetweens, tangents.KEYFILL_OT_edit_tangents)
MENUS = (("DOPESHEET_MT_key", _fill_menu), ("GRAPH_MT_key", _graph_menu), ("VIEW3D_MT_object_animation", _fill_menu))
  # the 3D view's Animation menu (Object and Pose mode share it in Blender 5.0)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Armature.keyfill_roles = bpy.props.CollectionProperty(type=KeyfillRole)
    for menu, func in MENUS:
        if hasattr(bpy.types, menu):  # menus move between Blender versions
            getattr(bpy.types, menu).append(func)


def unregister():
    for menu, func in MENUS:
        if hasattr(bpy.types, menu):
            getattr(bpy.types, menu).remove(func)
    del bpy.types.Armature.keyfill_roles
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
