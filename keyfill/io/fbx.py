"""FBX files (``.fbx``, binary or ASCII): read only, through ufbx (the ``fbx`` extra).

keyfill parses no FBX itself: ufbx (https://github.com/ufbx/ufbx, MIT, by Samuli Raivio; the ``ufbx``
Python binding, ``pip install 'keyfill[fbx]'``) loads the file and evaluates every node's local transform
(FBX's pivots, pre- and post-rotations and Euler orders composed) at a time. This module turns that into a
:class:`~keyfill.motion.Motion`:

* Joints are the bone nodes (``LimbNode``, ``Limb``, ``Root``: ufbx's bone attribute), depth first from the
  scene root, children in file order; names are the node names (whitespace becomes ``_``, a repeated name
  gets ``_1``, ``_2``). A joint's parent is its nearest bone ancestor. Meshes, skins, cameras and other
  nodes are not read.
* Nodes between two joints that are not bones are folded into the child joint; those above a root joint
  (Blender's ``Armature`` node, with its turn and its scale of 100) are folded into the root. Their uniform
  scale becomes the units: :attr:`~keyfill.motion.Skeleton.meters_per_unit` is the file's unit (ufbx's
  ``unit_meters``, FBX ``UnitScaleFactor`` cm) times that scale, as the glTF reader does, so the joints keep
  the numbers the file gives them (Blender's rig is read in metres). A joint scaled by the file or the
  animation (beyond 0.001), an uneven scale, a shear or a mirror above it, are refused: keyfill motions have
  no scale.
* The motion: the first animation stack (or the one named by ``animation``; several are noted), sampled at
  the file's frame rate (``frames_per_second``) from the stack's start to its end: frame ``i`` is at
  ``start + i / fps``. Every frame is sampled, so no keys are read.
* Axes: a right-handed Y-up or Z-up file keeps its axes, recorded as the skeleton's
  :attr:`~keyfill.motion.Skeleton.up_axis` (as USD's ``upAxis``); any other (X-up, left-handed) is turned
  into right-handed Y-up by ufbx on loading, and said in a note.
* Channels (what a BVH output writes): roots and joints whose translation moves get position channels;
  rotations follow the node's FBX rotation order (``eEulerXYZ`` = X first = ``Zrotation Yrotation
  Xrotation``).

The binding (``ufbx`` 0.0.5, the one on PyPI) returns scene elements taken from a list without a reference
of their own, and crashes the interpreter later when they are let go; :func:`_elements` adds the missing
reference, the module reads elements only through lists (no ``node.parent``), and frees the scene before
any error leaves :func:`_extract`. See docs/formats.md.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill import limits, progress
from keyfill import rotations as R
from keyfill.errors import DataError, FormatError, KeyfillError, UsageError
from keyfill.motion import POSITION_CHANNELS, Motion, Skeleton, unique_names

INSTALL = "pip install 'keyfill[fbx]'"
#: ufbx's RotationOrder (XYZ .. ZYX; 6, spheric, is read as XYZ) -> BVH rotation channels in keyfill's
#: intrinsic order: FBX applies the first letter first
EULER_CHANNELS = [tuple(f"{a}rotation" for a in reversed(order)) for order in ("XYZ", "XZY", "YZX", "YXZ", "ZXY",
                                                                             "ZYX")]
#: a scale this close to 1 is none
SCALE_TOL = 1e-3


def _ufbx(label):
    try:
        import ufbx
    except ImportError:
        raise UsageError(f"{label}: reading FBX needs ufbx, which the base install leaves out: {INSTALL}") from None
    return ufbx


_incref = ctypes.pythonapi.Py_IncRef
_incref.argtypes = [ctypes.py_object]
_incref.restype = None


def _elements(items) -> list:
    """The elements of a ufbx list, each given the reference the binding forgot to add (a leak of a few
    hundred bytes per element; without it, letting one go frees it while ufbx still holds it)."""
    out = []
    for i in range(len(items)):
        e = items[i]
        _incref(e)
        out.append(e)
    return out


@dataclass
class _Scene:
    """What keyfill takes from a ufbx scene: plain arrays, no ufbx objects.

    ``names``, ``parents`` and ``orders`` per joint; per joint its ``chain``: the indices into ``nodes``
    of the nodes from the one below its parent joint (or the scene's top) down to the joint itself;
    ``rest (N, 10)`` and ``frames (F, N, 10)``: per node its translation, rotation (w, x, y, z) and scale,
    at rest and at each frame.
    """

    names: list[str]
    parents: np.ndarray
    orders: list[int]
    chains: list[list[int]]
    rest: np.ndarray
    frames: np.ndarray
    fps: float
    unit_meters: float
    up: str


def _transform(t) -> list[float]:
    tr, q, s = t
    return [tr[0], tr[1], tr[2], q[3], q[0], q[1], q[2], s[0], s[1], s[2]]


def _axes(ufbx, axes) -> str | None:
    """``"Y"`` or ``"Z"`` for right-handed Y-up or Z-up axes, else None."""
    vec = {}
    for name in ("right", "up", "front"):
        a = int(getattr(axes, name))
        if a > 5:
            return None
        vec[name] = np.eye(3)[a // 2] * (-1 if a % 2 else 1)
    if not np.allclose(np.cross(vec["right"], vec["up"]), vec["front"]):
        return None
    up = int(axes.up)
    return {int(ufbx.CoordinateAxis.POSITIVE_Y): "Y", int(ufbx.CoordinateAxis.POSITIVE_Z): "Z"}.get(up)


def _load(ufbx, path: Path, label, **options):
    try:
        return ufbx.load_file(str(path), ignore_geometry=True, ignore_embedded=True, load_external_files=False,
                              file_format=ufbx.FileFormat.FBX, no_format_from_content=True,
                              no_format_from_extension=True, **options)
    except ufbx.UfbxError as e:
        reason = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise FormatError(f"not an FBX file that can be read ({reason})", label) from None


def _extract(path: Path, label, animation: str | int | None) -> _Scene:
    """Load ``path`` with ufbx and take what :func:`read` needs; the scene is freed before this returns or
    raises (an exception holding it would crash the interpreter when let go, see the module docstring)."""
    ufbx = _ufbx(label)
    scene = _load(ufbx, path, label)
    up = _axes(ufbx, scene.settings.axes)
    if up is None:
        scene.free()
        del scene
        progress.note(f"{label}: its axes are not right-handed Y-up or Z-up; read turned right-handed Y-up")
        scene = _load(ufbx, path, label, target_axes=ufbx.axes_right_handed_y_up,
                      space_conversion=ufbx.SpaceConversion.TRANSFORM_ROOT)
        up = "Y"
    try:
        result = _take(ufbx, scene, label, animation, up, path.stat().st_size)
    except Exception as e:  # noqa: BLE001 - a message only: the exception's frames hold the scene
        result = e if isinstance(e, KeyfillError) else FormatError(f"ufbx could not evaluate it ({e})", label)
    finally:
        scene.free()
        del scene
    if isinstance(result, Exception):
        result.__traceback__ = result.__context__ = result.__cause__ = None
        raise result
    return result


def _take(ufbx, scene, label, animation, up, size: int) -> _Scene:
    nodes = _elements(scene.nodes)
    index = {n.typed_id: i for i, n in enumerate(nodes)}
    kids = [[index[c.typed_id] for c in _elements(n.children)] for n in nodes]
    bone = [int(n.attrib_type) == int(ufbx.ElementType.BONE) for n in nodes]
    if not any(bone):
        raise FormatError("no skeleton: no bone (LimbNode) node in this file", label)
    joints, parents, chains = [], [], []
    top = [i for i, n in enumerate(nodes) if n.is_root]
    stack = [(i, -1, []) for i in reversed(top)]  # node, its parent joint, the non-bones since it
    while stack:
        i, pj, between = stack.pop()
        if bone[i]:
            joints.append(i)
            parents.append(pj)
            chains.append([*between, i])
            pj, between = len(joints) - 1, []
        else:  # the scene's root too: it holds the turn of axes that ufbx adds (TRANSFORM_ROOT)
            between = [*between, i]
        stack.extend((c, pj, between) for c in reversed(kids[i]))
    if len(joints) > limits.max_joints():
        raise FormatError(f"{len(joints)} joints is more than keyfill reads ({limits.max_joints()}; set "
                          "KEYFILL_MAX_JOINTS to raise it)", label)
    stacks = _elements(scene.anim_stacks)
    if not stacks:
        raise FormatError("no animation: the file has no animation stack", label)
    s = _pick(stacks, animation, label)
    settings = scene.settings
    fps = float(settings.frames_per_second)
    problem = limits.check_fps(fps)
    if problem:
        raise FormatError(f"the file's frame rate: {problem}", label)
    begin, end = float(s.time_begin), float(s.time_end)
    if not (np.isfinite(begin) and np.isfinite(end)) or end < begin:
        raise FormatError(f"animation stack {s.name!r} runs from {begin:g} s to {end:g} s", label)
    span = (end - begin) * fps
    num_frames = round(span) + 1 if span < 1e15 else limits.max_frames() + 1
    used = sorted({n for chain in chains for n in chain})
    problem = limits.check_size(num_frames, len(used), size)
    if problem:
        raise FormatError(f"the animation runs {end - begin:g} s at {fps:g} fps: {problem}", label)
    anim = s.anim
    rest = np.array([_transform(nodes[n].local_transform) for n in used]).reshape(len(used), 10)
    frames = np.empty((num_frames, len(used), 10))
    for f in range(num_frames):
        t = begin + f / fps
        frames[f] = [_transform(ufbx.evaluate_transform(anim, nodes[n], t)) for n in used]
    where = {n: k for k, n in enumerate(used)}
    return _Scene(names=[nodes[j].name for j in joints], parents=np.array(parents, dtype=np.int64),
                  orders=[int(nodes[j].rotation_order) for j in joints],
                  chains=[[where[n] for n in chain] for chain in chains], rest=rest, frames=frames, fps=fps,
                  unit_meters=float(settings.unit_meters), up=up)


def _pick(stacks: list, wanted, label):
    if wanted is None:
        if len(stacks) > 1:
            progress.note(f"{label}: {len(stacks)} animation stacks; reading the first ({stacks[0].name!r})")
        return stacks[0]
    for i, s in enumerate(stacks):
        if wanted == i or wanted == s.name:
            return s
    names = ", ".join(repr(s.name) for s in stacks)
    raise FormatError(f"no animation stack {wanted!r}; the file has {names}", label)


def _compose(chain: np.ndarray, label, what: str, scaled_ok: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(rotation (..., 4), translation (..., 3), scale (...,))`` of the nodes ``chain (..., n, 10)``
    composed from the top; each node's scale must be uniform, and 1 unless ``scaled_ok``."""
    rot = np.zeros(chain.shape[:-2] + (4,))
    rot[..., 0] = 1
    pos = np.zeros(chain.shape[:-2] + (3,))
    scale = np.ones(chain.shape[:-2])
    for k in range(chain.shape[-2]):
        t, q, s = chain[..., k, 0:3], chain[..., k, 3:7], chain[..., k, 7:10]
        if not (np.isfinite(chain[..., k, :]).all() and (np.abs(chain[..., k, :]) <= limits.max_abs()).all()):
            raise FormatError(f"{what}: a transform is not finite or beyond {limits.max_abs():g}", label)
        mean = s.mean(axis=-1)
        if np.any(mean <= 0) or np.any(np.abs(s - mean[..., None]) > SCALE_TOL * np.abs(mean[..., None])):
            raise FormatError(f"{what} is scaled unevenly or mirrored; keyfill reads rigid joints", label)
        if not scaled_ok and np.any(np.abs(mean - 1) > SCALE_TOL):
            raise DataError(f"{label}: {what} is scaled ({float(mean.flat[np.argmax(np.abs(mean - 1))]):g}); "
                            "keyfill motions have no scale")
        norm = np.linalg.norm(q, axis=-1, keepdims=True)
        if np.any(norm < 1e-6):
            raise FormatError(f"{what}: a rotation is zero (not a quaternion)", label)
        pos = pos + scale[..., None] * R.quat_rotate(rot, t)
        rot = R.quat_mul(rot, q / norm)
        scale = scale * mean
    return rot, pos, scale


def read(path: str | Path, label=None, animation: str | int | None = None) -> Motion:
    """Read the skeleton and animation of an FBX file into a :class:`Motion` (see the module docstring).

    Args:
        label: names the file in errors (default ``path``).
        animation: name or index of the animation stack to read (default: the first, noted when there are more).
    """
    label = path if label is None else label
    sc = _extract(Path(path), label, animation)
    J = len(sc.names)
    rot = np.empty((len(sc.frames), J, 4))
    pos = np.empty((len(sc.frames), J, 3))
    rest = np.empty((J, 3))
    unit = None
    for j, chain in enumerate(sc.chains):
        root = sc.parents[j] < 0
        name = sc.names[j]
        # the joint itself: no scale; the nodes above it (or between it and its parent joint): rigid, and above
        # a root a uniform scale, the same at every frame, that becomes the units
        above = (f"the nodes above joint {name!r}" if root else f"the nodes between joint {name!r} and its parent")
        _compose(sc.frames[:, chain[-1:]], label, f"joint {name!r}", scaled_ok=False)
        a_rot, a_pos, a_scale = _compose(sc.frames[:, chain[:-1]], label, above, scaled_ok=root)
        r_rot, r_pos, r_scale = _compose(sc.rest[None, chain[:-1]], label, above, scaled_ok=root)
        if root:
            s = float(a_scale[0])
            if np.abs(a_scale - s).max() > 1e-6 * s or abs(float(r_scale[0]) - s) > 1e-6 * s:
                raise FormatError(f"{above} change their scale during the animation", label)
            if unit is not None and abs(s - unit) > 1e-6 * unit:
                raise FormatError("the root joints sit under nodes of different scales", label)
            unit = s
        k = 1.0 / float(a_scale[0])
        q, t = sc.frames[:, chain[-1], 3:7], sc.frames[:, chain[-1], 0:3]
        rot[:, j] = R.quat_mul(a_rot, q / np.linalg.norm(q, axis=-1, keepdims=True))
        pos[:, j] = k * a_pos + R.quat_rotate(a_rot, t)
        rest[j] = k * r_pos[0] + R.quat_rotate(r_rot[0], sc.rest[chain[-1], 0:3])
    moving = np.abs(pos - rest).max(axis=(0, 2), initial=0.0) > 1e-6 * max(1.0, float(np.abs(rest).max(initial=0)))
    channels = tuple((POSITION_CHANNELS if sc.parents[j] < 0 or moving[j] else ())
                     + EULER_CHANNELS[sc.orders[j] if sc.orders[j] < 6 else 0] for j in range(J))
    names = unique_names(sc.names, [f"joint{j}" for j in range(J)])
    try:
        skeleton = Skeleton(names=tuple(names), parents=sc.parents, offsets=rest, channels=channels,
                            meters_per_unit=sc.unit_meters * (unit or 1.0), up_axis=sc.up)
        return Motion(skeleton, sc.fps, rot, pos)
    except FormatError:
        raise
    except KeyfillError as e:  # arrays that do not make a motion: bad data in this file
        raise FormatError(str(e).removeprefix(f"{label}: "), label) from None

