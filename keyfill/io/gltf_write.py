"""Writing glTF 2.0 (``.glb``, ``.gltf``): the mapping of :mod:`keyfill.io.gltf`, the other way.

What keyfill writes from a motion: one node per joint (its name, its rest
offset as translation, in metres), a scene of the roots, one skin of all
joints with inverse bind matrices of the rest pose (identity rotations, as in
BVH), and one animation with a LINEAR sampler per animated channel (times
``i / fps`` s, shared by all samplers; a rotation channel for each joint with
rotation channels or whose rotation moves, a translation channel for each with
position channels or whose translation moves; a skeleton with none of these
gets its first joint's rotation held, since glTF has no empty animations),
named after the output file (its stem). Translations are turned into
metres and a Z-up skeleton's roots into Y-up; the skin's and the animation's
``extras.keyfill`` record the source units, up axis, channel layout, End
Sites, frame rate and keys, so that reading gives back what was written.
The document is built with pygltflib; one binary buffer holds the data (the
``.glb``'s BIN chunk; beside a ``.gltf`` as ``.bin``, or in it as a ``data:``
URI).

With ``template`` (a glTF file whose chosen skin has the motion's joints, see
:func:`keyfill.io.gltf.read`), the output is that file with the motion as its
animation: meshes, materials, textures, other nodes and other animations are
kept; the buffers and images the template refers to are put into the one
buffer of the output, so it does not depend on files beside the template.

The buffer is written as it is made (:mod:`keyfill.io.gltf_blob`): each
channel's values are turned into glTF's frame and written one at a time, and a
template's bytes are copied a block at a time, so writing a long take holds
little beside the motion itself (issue 44).
"""

from __future__ import annotations

import json
import urllib.parse
from pathlib import Path

import numpy as np

from keyfill import limits
from keyfill import rotations as R
from keyfill.errors import DataError, FormatError, UsageError
from keyfill.io.gltf import EXTRAS, Z_TO_Y, pick, rig_of
from keyfill.io.gltf_blob import Blob, BufferWriter, write_bin, write_glb, write_gltf
from keyfill.io.gltf_buffers import IMAGE_TYPES, load_document, resolve_uri, stored_file
from keyfill.kinematics import fk
from keyfill.motion import POSITION_CHANNELS, ROTATION_CHANNELS, Motion

#: ``sidecar`` default of :func:`write`: the buffer goes to ``<stem>.bin`` beside a ``.gltf``
BESIDE = "beside"
#: the animation's name when :func:`write` is given none (standard output without a source file)
DEFAULT_NAME = "keyfill"


def from_source(values: np.ndarray, path: str, above: tuple[np.ndarray, np.ndarray] | None, scale: float,
                mpu: float, up: str) -> np.ndarray:
    """One joint's ``values`` in glTF's frame: the inverse of :func:`keyfill.io.gltf.to_source`.

    ``values``: ``(..., 4)`` rotations (``path`` ``"rotation"``) or ``(..., 3)`` translations (a rest offset
    too), from ``mpu`` and ``up`` into glTF's metres and Y axis, then, for a root joint, into the frame of the
    nodes above it (``above``: their ``(rotation (4,), translation (3,))``, whose uniform scale is ``scale``;
    None for a joint under another). A new array, but for the rotations of a joint that is no root (then
    ``values`` itself).
    """
    if path == "rotation":
        if above is None:
            return values
        if up == "Z":
            values = R.quat_mul(Z_TO_Y, values)
        return R.quat_mul(R.quat_conjugate(above[0]), values)
    if above is not None and up == "Z":
        values = R.quat_rotate(Z_TO_Y, values)
    values = values * (mpu / scale)
    if above is None:
        return values
    q, t = above
    return R.quat_rotate(R.quat_conjugate(q), values - t / scale)


def _rest(motion: Motion, above: dict, scale: float) -> np.ndarray:
    """``(J, 3)`` the rest offsets in glTF's frame (:func:`from_source`; ``above`` per root joint)."""
    sk = motion.skeleton
    return np.stack([from_source(sk.offsets[j], "translation", above.get(j), scale, sk.meters_per_unit, sk.up_axis)
                     for j in range(sk.num_joints)])


def _layout(motion: Motion) -> dict:
    sk = motion.skeleton
    return {"metersPerUnit": float(sk.meters_per_unit), "upAxis": sk.up_axis,
            "channels": [" ".join(c) for c in sk.channels],
            "endSites": [[int(j), *map(float, o)] for j, o in sk.end_sites]}


def _timing(motion: Motion) -> dict:
    out = {"fps": float(motion.fps)}
    if motion.keys is not None:
        out["keys"] = motion.keys.to_list()
        if motion.keys.partial:
            out["keyGiven"] = motion.keys.given
            out["keyMask"] = motion.keys.joint_mask(motion.num_joints).astype(int).ravel().tolist()
    return out


def _animation(writer: BufferWriter, motion: Motion, above: dict, scale: float, rest_rot, rest_pos,
               nodes: list[int], name: str):
    """The pygltflib Animation ``name`` of ``motion`` for joint ``nodes``, in glTF's frame (:func:`from_source`
    with ``above`` per root joint and ``scale``); ``rest_rot (J, 4)`` and ``rest_pos (J, 3)`` there too.

    A joint's values are turned into glTF's frame to see whether it moves, and again, one channel at a time,
    when the buffer is written (:class:`~keyfill.io.gltf_blob.BufferWriter`). A skeleton with nothing to
    animate (every joint without channels and at rest) still gets one channel, its first joint's rotation
    held at every frame: glTF allows no animation without channels, and the samples keep the frame count.
    """
    from pygltflib import Animation, AnimationChannel, AnimationChannelTarget, AnimationSampler

    times = (np.arange(motion.num_frames) / motion.fps).astype(np.float32)
    if np.any(np.diff(times) <= 0):
        raise DataError(f"{motion.num_frames} frames at {motion.fps:g} fps: the frame times cannot be told apart "
                        "in glTF's 32-bit float times")
    anim = Animation(name=name, extras={EXTRAS: _timing(motion)})
    time_acc = writer.add(times[:, None], "SCALAR", bounds=True)
    sk = motion.skeleton
    chans = sk.channels

    def joint(j: int, path: str) -> np.ndarray:  # (F, 4) w-x-y-z or (F, 3)
        values = motion.rotations[:, j] if path == "rotation" else motion.positions[:, j]
        return from_source(values, path, above.get(j), scale, sk.meters_per_unit, sk.up_axis)

    def add(j: int, path: str) -> None:
        if path == "translation":
            output = writer.add(lambda: joint(j, path), "VEC3", count=motion.num_frames)
        else:
            output = writer.add(lambda: joint(j, path)[:, [1, 2, 3, 0]], "VEC4", count=motion.num_frames)
        anim.samplers.append(AnimationSampler(input=time_acc, output=output, interpolation="LINEAR"))
        anim.channels.append(AnimationChannel(sampler=len(anim.samplers) - 1,
                                              target=AnimationChannelTarget(node=nodes[j], path=path)))

    for j in range(len(nodes)):
        if any(c in POSITION_CHANNELS for c in chans[j]) or np.abs(joint(j, "translation") - rest_pos[j]).max(
                initial=0.0) > 1e-9 * max(1.0, float(np.abs(rest_pos).max())):
            add(j, "translation")
        if any(c in ROTATION_CHANNELS for c in chans[j]) or np.abs(R.quat_angle(joint(j, "rotation"),
                                                                                rest_rot[j])).max(initial=0.0) > 1e-9:
            add(j, "rotation")
    if not anim.channels:
        add(0, "rotation")
    return anim


def _fresh(motion: Motion, name: str) -> tuple[dict, Blob]:
    """The JSON and binary buffer of a glTF file holding ``motion`` alone."""
    from pygltflib import GLTF2, Asset, Buffer, Node, Scene, Skin

    from keyfill import __version__

    sk = motion.skeleton
    J = sk.num_joints
    roots = [j for j in range(J) if sk.parents[j] < 0]
    ident = np.tile([1.0, 0.0, 0.0, 0.0], (J, 1))
    above = {r: (ident[0], np.zeros(3)) for r in roots}
    rest = _rest(motion, above, 1.0)
    gltf = GLTF2(asset=Asset(generator=f"keyfill {__version__}"), scene=0)
    writer = BufferWriter(gltf)
    kids: dict[int, list[int]] = {}
    for j in range(J):
        kids.setdefault(int(sk.parents[j]), []).append(j)
    gltf.nodes = [Node(name=sk.names[j], translation=[float(v) for v in rest[j]], children=kids.get(j, []))
                  for j in range(J)]
    gltf.scenes = [Scene(nodes=roots)]
    world = fk(ident, rest, sk.parents)[1]
    ibm = np.tile(np.eye(4), (J, 1, 1))
    ibm[:, :3, 3] = -world
    gltf.skins = [Skin(joints=list(range(J)), inverseBindMatrices=writer.add(ibm.transpose(0, 2, 1).reshape(J, 16),
                                                                            "MAT4"),
                       skeleton=roots[0] if len(roots) == 1 else None, extras={EXTRAS: _layout(motion)})]
    gltf.animations = [_animation(writer, motion, above, 1.0, ident, rest, list(range(J)), name)]
    gltf.buffers = [Buffer(byteLength=writer.blob.size)]
    return json.loads(gltf.gltf_to_json()), writer.blob


#: extensions that refer to no accessor and no buffer view (the others may: then nothing is pruned)
PLAIN_EXTENSIONS = ("KHR_materials_", "KHR_texture_transform", "KHR_lights_punctual", "KHR_texture_basisu",
                    "EXT_texture_webp", "KHR_mesh_quantization")


def _accessor_refs(raw: dict) -> list[tuple[dict, str]]:
    """Every ``(object, key)`` of ``raw`` whose value is an accessor index, in the places glTF 2.0 has them."""
    refs = []  # the types are those gltf_buffers.check_schema checked
    for prim in (p for mesh in raw.get("meshes", []) for p in mesh.get("primitives", [])):
        for attrs in [prim.get("attributes", {}), *prim.get("targets", [])]:
            refs += [(attrs, k) for k in attrs]
        refs += [(prim, "indices")] if "indices" in prim else []
    refs += [(skin, "inverseBindMatrices") for skin in raw.get("skins", []) if "inverseBindMatrices" in skin]
    refs += [(s, k) for a in raw.get("animations", []) for s in a.get("samplers", []) for k in ("input", "output")
             if k in s]
    return [(obj, key) for obj, key in refs if type(obj[key]) is int]


def _view_refs(raw: dict) -> list[tuple[dict, str]]:
    """Every ``(object, "bufferView")`` of ``raw``: accessors, their sparse parts and images."""
    objs = list(raw.get("accessors", [])) + list(raw.get("images", []))
    objs += [acc["sparse"][part] for acc in raw.get("accessors", []) if isinstance(acc.get("sparse"), dict)
             for part in ("indices", "values") if isinstance(acc["sparse"].get(part), dict)]
    return [(obj, "bufferView") for obj in objs if type(obj.get("bufferView")) is int]


def _renumber(items: list, dead: set[int], refs: list[tuple[dict, str]]) -> list:
    """``items`` without the indices ``dead``, every reference in ``refs`` renumbered to match."""
    new, kept = {}, []
    for i, item in enumerate(items):
        if i not in dead:
            new[i] = len(kept)
            kept.append(item)
    for obj, key in refs:
        obj[key] = new.get(obj[key], obj[key])
    return kept


def _drop_animation(raw: dict, a: int) -> None:
    """Remove animation ``a`` and, unless an extension may refer to them, the accessors and buffer views that
    only it used (the others renumbered), in place."""
    old = raw["animations"].pop(a)
    if any(not str(e).startswith(PLAIN_EXTENSIONS) for e in raw.get("extensionsUsed", [])):
        return
    refs = _accessor_refs(raw)
    used = {obj[key] for obj, key in refs}
    dead = {s.get(k) for s in old.get("samplers", []) for k in ("input", "output")} - used
    raw["accessors"] = _renumber(raw.get("accessors", []), dead, refs)
    refs = _view_refs(raw)
    used = {obj[key] for obj, key in refs}
    raw["bufferViews"] = _renumber(raw.get("bufferViews", []), set(range(len(raw.get("bufferViews", [])))) - used,
                                   refs)


def _with_template(motion: Motion, template: Path, name: str) -> tuple[dict, Blob]:
    """The JSON and buffer of ``template`` with ``motion`` as the animation of its skin."""
    from pygltflib import GLTF2

    from keyfill import __version__

    doc = load_document(template, template)
    rig = rig_of(doc, None, note=False)  # the skin the motion was read from (noted then)
    sk = motion.skeleton
    if rig.names != list(sk.names) or not np.array_equal(rig.parents, sk.parents):
        raise UsageError(f"{template}: its skin's joints are not those of the motion, so its meshes cannot be "
                         "kept; write to a file of another format, or read the motion from this file")
    raw = doc.json
    anims = raw.setdefault("animations", [])
    replaced = pick(anims, None, "animation", template, note=False) if anims else 0
    if anims:
        _drop_animation(raw, replaced)
    blob = Blob()
    for i, view in enumerate(raw.get("bufferViews", [])):  # each view's bytes, at its offset's residue mod 8
        b = view.get("buffer")
        data = doc.buffers[b] if type(b) is int and 0 <= b < len(doc.buffers) else None
        start, length = view.get("byteOffset", 0), view.get("byteLength", 0)
        if data is None or not 0 <= start <= start + length <= data.length:
            raise FormatError(f"bufferView {i} does not lie in a buffer keyfill can read (one an extension fills?); "
                              "the file's meshes cannot be kept", template)
        view.update(buffer=0, byteOffset=blob.put(data.part(start, length), length, residue=start, modulus=8))
    scratch = GLTF2()
    writer = BufferWriter(scratch)  # the images and the animation, appended to the template's views below
    embedded = []
    for i, image in enumerate(raw.get("images", [])):
        uri = image.get("uri")
        if uri is None or uri.startswith("data:"):
            continue
        source = resolve_uri(doc.folder, uri, template, f"image {i}")
        mime = image.get("mimeType") or IMAGE_TYPES.get(source.suffix.lower())
        if mime is None:
            raise FormatError(f"image {i} ({uri[:60]!r}) is of no image type glTF knows", template)
        image.update(bufferView=writer.add_bytes(stored_file(source, template, f"image {i}")), mimeType=mime)
        del image["uri"]
        embedded.append(image)
    scratch.animations = [_animation(writer, motion, rig.above, rig.scale, rig.rest_rot, rig.rest_pos, rig.nodes,
                                     name)]
    part = json.loads(scratch.gltf_to_json())
    views, accessors = raw.setdefault("bufferViews", []), raw.setdefault("accessors", [])
    offset_views, offset_acc = len(views), len(accessors)
    start = blob.extend(writer.blob, 8)
    for view in part.get("bufferViews", []):
        view["byteOffset"] = view.get("byteOffset", 0) + start
        views.append(view)
    for image in embedded:
        image["bufferView"] += offset_views
    for acc in part.get("accessors", []):
        acc["bufferView"] += offset_views
        accessors.append(acc)
    anim = part["animations"][0]
    for sampler in anim["samplers"]:
        sampler["input"] += offset_acc
        sampler["output"] += offset_acc
    anims.insert(replaced, anim)
    skin = raw["skins"][rig.skin]
    skin["extras"] = {**(skin["extras"] if isinstance(skin.get("extras"), dict) else {}), EXTRAS: _layout(motion)}
    raw["asset"]["generator"] = f"keyfill {__version__}"
    raw["buffers"] = [{"byteLength": blob.size}]
    return raw, blob


def write(motion: Motion, path: str | Path, sidecar=BESIDE, template: str | Path | None = None,
          name: str | None = None) -> None:
    """Write ``motion`` to ``path`` as glTF, binary for ``.glb`` (not atomic; see :func:`keyfill.io.save`).

    Args:
        sidecar: where a ``.gltf``'s buffer goes: :data:`BESIDE` (``<stem>.bin``
            next to ``path``), ``(file to write, name the .gltf gives it)``, or
            None: embedded in the ``.gltf`` as a ``data:`` URI.
        template: a glTF file whose meshes, materials and other content to keep
            (see the module docstring).
        name: the animation's name (:func:`keyfill.io.save` gives the output's
            stem); None: :data:`DEFAULT_NAME`.
    """
    limits.check_values(motion)
    if motion.num_frames == 0:
        raise DataError("the motion has no frames; a glTF animation needs at least one")
    path = Path(path)
    name = DEFAULT_NAME if name is None else name
    doc, blob = _fresh(motion, name) if template is None else _with_template(motion, Path(template), name)
    if path.suffix.lower() == ".glb":
        blob.hold([path])
        write_glb(path, json.dumps(doc, separators=(",", ":"), allow_nan=False), blob)
        return
    if sidecar is None:
        blob.hold([path])
        write_gltf(path, doc, blob, None)
        return
    target, name = (path.with_suffix(".bin"), path.with_suffix(".bin").name) if sidecar == BESIDE else sidecar
    blob.hold([path, Path(target)])
    write_bin(Path(target), blob)
    write_gltf(path, doc, blob, urllib.parse.quote(name))
