"""USD files (``.usda``, ``.usdc``, ``.usd``) through UsdSkel.

Layout keyfill writes::

    /<Root>                 SkelRoot, the stage's defaultPrim
    /<Root>/Skeleton        Skeleton: joints (paths), jointNames, restTransforms
                            (local), bindTransforms (world); SkelBindingAPI with
                            skel:animationSource -> <name>
    /<Root>/Skeleton/<name> SkelAnimation: rotations and translations as time
                            samples, one per frame (time code = frame index);
                            translations that are the same at every frame are
                            one default value instead, and scales are one default
                            (1, 1, 1) per joint; named after the output file (its
                            stem as an identifier)

Stage metadata: ``timeCodesPerSecond`` = ``framesPerSecond`` = fps,
``startTimeCode`` 0, ``endTimeCode`` F-1, ``upAxis``, ``metersPerUnit``. The
Skeleton's ``customData["keyfill"]`` keeps what USD has no place for, so that
BVH -> USD -> BVH gives the same file: original joint names (USD joint paths
must be identifiers), BVH channel layouts and End Sites, and the keys. Partial
keys (:attr:`keyfill.motion.Keys.partial`) add ``keyMask`` (int[], ``K x J``
row-major in the skeleton's joint order, 1 where a joint is keyed) and
``keyGiven`` (``"pose"``, ``"position"``, or a view plane ``"XY"``, ``"XZ"``,
``"YZ"``), so a keyframe file can say "only the root's path" or "only the legs".

Reading accepts any UsdSkel file: the first Skeleton under the default prim (or
anywhere) and its animation source (or the first SkelAnimation). The
animation's joint order is remapped onto the skeleton's; joints it does not
animate keep their rest transform. An attribute with a default value and no
samples holds that value at every frame. When the animation's samples are sparse
(fewer sample times than frames in the stage's time range), frames in between
are USD's interpolation of the samples and the sample times become the keys of
the motion.

USD stores translations and rotations as 32-bit floats: a round trip through
USD keeps about 7 significant digits. Translations are written without
negative zeros and read back as the shortest decimal that rounds to the
stored float (:func:`keyfill.io.usd_samples.shortest_decimal`): ``-0.2399``
comes back as ``-0.2399``, so BVH -> USD -> BVH writes the input's own numbers.

Long takes: time and memory are linear in frames. The *writer* builds the
stage in memory (USD writes a layer whole): the 32-bit copies of the arrays
are made :data:`~keyfill.io.usd_samples.BLOCK` frames at a time and go straight
into the layer's time samples in one change block, so beside the motion it
holds the layer, about half the motion's float64 arrays plus some 100 bytes a
sample, and USD then writes the file in one go. The *reader* lets USD open the
layer whole (a ``.usdc`` is memory-mapped; a ``.usda`` is parsed from its whole
text, about 1.5x the file's bytes at the parser's peak, freed before keyfill
reads a value), allocates the motion's arrays once and fills them a block of
frames at a time (:mod:`keyfill.io.usd_samples`: one ``Usd.AttributeQuery.Get``
a sample into a block, checks and shortest decimals in numpy, worked out once
for each coordinate that holds still over the block); beside the stage it holds
the motion's arrays and a few MB. Measured on a 2-core VM at 100,000 frames of
22 joints (the motion's arrays 117 MiB), CPU and peak memory above the
interpreter's: reading about 17 us/frame and 1.8x the arrays (``.usdc``),
50 us/frame and 2.5x (``.usda``, the text parser's peak); writing 16 us/frame
and 1.2x (``.usdc``), 37 us/frame and 0.8x (``.usda``); BVH in the same run
read in 48 us/frame and wrote in 53. 1,000,000 frames cost 14 and 52 us/frame
to read (``.usdc``, ``.usda``), 19 and 50 to write.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from keyfill import limits, progress
from keyfill.errors import DataError, FormatError, KeyfillError
from keyfill.io.usd_layers import composed_layers
from keyfill.io.usd_samples import BLOCK, decimals, resolve, samples
from keyfill.kinematics import fk
from keyfill.motion import FULL_CHANNELS, FULL_ROOT_CHANNELS, Keys, Motion, Skeleton

CUSTOM_KEY = "keyfill"


def _pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt
    except ImportError as e:  # pragma: no cover - usd-core is a dependency
        raise FormatError(f"USD support needs the usd-core package ({e})") from None
    return Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt


def _identifier(name: str) -> str:
    ident = re.sub(r"[^A-Za-z0-9_]", "_", name)
    if not ident or ident[0].isdigit():
        ident = "_" + ident
    return ident


def joint_paths(skeleton: Skeleton) -> list[str]:
    """UsdSkel joint paths (``"Hips/Spine"``): names made identifiers, unique among siblings."""
    paths: list[str] = []
    used: set[str] = set()
    for j, name in enumerate(skeleton.names):
        base = _identifier(name)
        p = skeleton.parents[j]
        prefix = paths[p] + "/" if p >= 0 else ""
        cand, n = prefix + base, 1
        while cand in used:
            cand, n = f"{prefix}{base}_{n}", n + 1
        used.add(cand)
        paths.append(cand)
    return paths


def _quat_to_xyzw(q: np.ndarray) -> np.ndarray:
    return _float32(q[..., [1, 2, 3, 0]])


def _float32(values: np.ndarray) -> np.ndarray:
    """``values`` as the 32-bit floats USD stores, with no negative zero (USD's text would write ``-0``)."""
    return np.ascontiguousarray(values, dtype=np.float32) + np.float32(0.0)


def _matrices(Gf, Vt, rot: np.ndarray, pos: np.ndarray):
    """Vt.Matrix4dArray of row-vector transforms from quaternions (J,4) and translations (J,3)."""
    out = []
    for q, t in zip(rot, pos):
        m = Gf.Matrix4d(1.0)
        m.SetRotateOnly(Gf.Quatd(float(q[0]), Gf.Vec3d(*map(float, q[1:]))))
        m.SetTranslateOnly(Gf.Vec3d(*map(float, t)))
        out.append(Gf.Matrix4d(*[v + 0.0 for row in m for v in row]))  # no -0 in the text
    return Vt.Matrix4dArray(out)


def write(motion: Motion, path: str | Path, sparse: bool = False, root_name: str = "Root",
          name: str | None = None) -> None:
    """Write ``motion`` to a new USD file (format from the suffix); :func:`keyfill.io.save` writes through
    :func:`keyfill.io.usd_stage.write`, which keeps the stage of a USD source instead.

    Args:
        sparse: author time samples only at ``motion.keys`` (a keyframe file);
            readers then see the keys as the motion's keys.
        root_name: name of the SkelRoot prim.
        name: name of the SkelAnimation prim, made an identifier (letters,
            digits and ``_``, not starting with a digit; :func:`keyfill.io.save`
            gives the output's stem); None: ``Animation``.
    """
    stage = stage_of(motion, sparse, root_name, name)  # held: the layer goes with the stage
    stage.GetRootLayer().Export(str(path))


def stage_of(motion: Motion, sparse: bool = False, root_name: str = "Root", name: str | None = None):
    """The in-memory ``Usd.Stage`` that :func:`write` (same arguments) exports; a curves file
    (:func:`keyfill.io.usd_curves.write`) adds its curves to it before it is written."""
    Gf, _Sdf, Usd, UsdGeom, UsdSkel, Vt = _pxr()
    sk = motion.skeleton
    limits.check_values(motion)
    stage = Usd.Stage.CreateInMemory()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if sk.up_axis == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, float(sk.meters_per_unit))
    stage.SetTimeCodesPerSecond(motion.fps)
    stage.SetFramesPerSecond(motion.fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(max(motion.num_frames - 1, 0))

    root = UsdSkel.Root.Define(stage, "/" + _identifier(root_name))
    stage.SetDefaultPrim(root.GetPrim())
    skel = UsdSkel.Skeleton.Define(stage, root.GetPath().AppendChild("Skeleton"))
    anim = UsdSkel.Animation.Define(stage, skel.GetPath().AppendChild("Animation" if name is None else _identifier(name)))
    paths = Vt.TokenArray(joint_paths(sk))
    skel.CreateJointsAttr(paths)
    skel.CreateJointNamesAttr(Vt.TokenArray([p.rsplit("/", 1)[-1] for p in paths]))
    ident = np.zeros((sk.num_joints, 4))
    ident[:, 0] = 1
    skel.CreateRestTransformsAttr(_matrices(Gf, Vt, ident, sk.offsets))
    world_rot, world_pos = fk(ident, sk.offsets, sk.parents)
    skel.CreateBindTransformsAttr(_matrices(Gf, Vt, world_rot, world_pos))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])

    skel.GetPrim().SetCustomDataByKey(CUSTOM_KEY, custom_of(motion))

    anim.CreateJointsAttr(paths)
    t_attr = anim.CreateTranslationsAttr()
    r_attr = anim.CreateRotationsAttr()
    s_attr = anim.CreateScalesAttr()
    s_attr.Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * sk.num_joints))
    write_samples(stage.GetRootLayer(), t_attr.GetPath(), r_attr.GetPath(), motion, written_frames(motion, sparse))
    return stage


def custom_of(motion: Motion) -> dict:
    """The Skeleton's ``customData["keyfill"]`` for ``motion``: what USD has no place for (module docstring)."""
    Gf, _Sdf, _Usd, _UsdGeom, _UsdSkel, Vt = _pxr()
    sk = motion.skeleton
    custom = {
        "names": Vt.StringArray(list(sk.names)),
        "channels": Vt.StringArray([" ".join(c) for c in sk.channels]),
        "endSiteJoints": Vt.IntArray([j for j, _ in sk.end_sites]),
        "endSiteOffsets": Vt.Vec3dArray([Gf.Vec3d(*(float(v) + 0.0 for v in o)) for _, o in sk.end_sites]),
    }
    if motion.keys is not None:
        custom["keys"] = Vt.IntArray(motion.keys.to_list())
        if motion.keys.partial:
            custom["keyGiven"] = motion.keys.given
            custom["keyMask"] = Vt.IntArray(motion.keys.joint_mask(sk.num_joints).astype(int).ravel().tolist())
    return custom


def written_frames(motion: Motion, sparse: bool) -> np.ndarray:
    """The frames a USD file of ``motion`` has samples at: every frame, or with ``sparse`` the keys."""
    if not sparse:
        return np.arange(motion.num_frames)
    if motion.keys is None:
        raise DataError("a sparse USD file needs keys")
    return motion.keys.frames


def write_samples(layer, t_path, r_path, motion: Motion, frames: np.ndarray, start: float = 0.0) -> None:
    """Author ``motion``'s translations and rotations at ``frames`` as time samples ``start + frame`` of the
    attributes at ``t_path`` and ``r_path`` in ``layer`` (their specs exist there and hold no samples yet).

    Translations that are the same at every written frame (as 32-bit floats) are written once, as the
    attribute's default: USD resolves a default at every time, and the rotations' samples still give the
    frames (and, in a sparse file, the keys). Samples go straight into the layer, in one change block: the
    same file as attr.Set per frame, four times faster (no change notice per sample). The 32-bit copies are
    made a block of frames at a time (little memory beside the layer).
    """
    _Gf, Sdf, _Usd, _UsdGeom, _UsdSkel, Vt = _pxr()
    held = _held_translations(motion.positions, frames)
    if held is not None:
        layer.GetAttributeAtPath(t_path).default = Vt.Vec3fArray.FromNumpy(held)
    with progress.task("writing USD", len(frames), " frames") as update, Sdf.ChangeBlock():
        for a in range(0, len(frames), BLOCK):
            chunk = frames[a : a + BLOCK]
            rot = _quat_to_xyzw(motion.rotations[chunk])
            pos = _float32(motion.positions[chunk]) if held is None else None
            for k, f in enumerate(chunk.tolist()):
                if pos is not None:
                    layer.SetTimeSample(t_path, start + f, Vt.Vec3fArray.FromNumpy(pos[k]))
                layer.SetTimeSample(r_path, start + f, Vt.QuatfArray.FromNumpy(rot[k]))
            update(len(chunk))


def _held_translations(positions: np.ndarray, frames: np.ndarray) -> np.ndarray | None:
    """The 32-bit translations ``(J, 3)`` when ``positions (F, J, 3)`` hold them at every one of ``frames``,
    else None (also for no frames)."""
    if not len(frames):
        return None
    first = _float32(positions[frames[0]])
    for a in range(0, len(frames), BLOCK):
        if not (_float32(positions[frames[a : a + BLOCK]]) == first).all():
            return None
    return first


# --- reading -----------------------------------------------------------------


def _find_skeleton(stage, UsdSkel, label):
    prims = []
    start = stage.GetDefaultPrim() or stage.GetPseudoRoot()
    for root in (start, stage.GetPseudoRoot()):
        prims = [p for p in _prims(root) if p.IsA(UsdSkel.Skeleton)]
        if prims:
            break
    if not prims:
        raise FormatError("no UsdSkel Skeleton in this file", label)
    return UsdSkel.Skeleton(prims[0])


def _prims(root):
    """All prims under ``root`` (included), depth first."""
    from pxr import Usd

    return Usd.PrimRange(root)


def _find_animation(stage, skel, UsdSkel, label):
    source = UsdSkel.BindingAPI(skel.GetPrim()).GetAnimationSourceRel().GetTargets()
    if source:
        prim = stage.GetPrimAtPath(source[0])
        if prim and prim.IsA(UsdSkel.Animation):
            return UsdSkel.Animation(prim)
        raise FormatError(f"the Skeleton's animation source {source[0]} is not a SkelAnimation", label)
    anims = [p for p in _prims(stage.GetPseudoRoot()) if p.IsA(UsdSkel.Animation)]
    if not anims:
        raise FormatError("no UsdSkel SkelAnimation in this file", label)
    return UsdSkel.Animation(anims[0])


def _rest_local(skel, joints: list[str], label) -> tuple[np.ndarray, np.ndarray]:
    """Rest ``(rotations (J,4), translations (J,3))`` from restTransforms (or bindTransforms)."""
    rest = _matrices_of(skel.GetRestTransformsAttr(), label)
    J = len(joints)
    if rest is None or len(rest) != J:
        bind = _matrices_of(skel.GetBindTransformsAttr(), label)
        if bind is None or len(bind) != J:
            raise FormatError("the Skeleton has neither restTransforms nor bindTransforms for its joints", label)
        # Local from world bind transforms.
        index = {p: i for i, p in enumerate(joints)}
        local = []
        for i, p in enumerate(joints):
            parent = p.rsplit("/", 1)[0] if "/" in p else None
            m = bind[i] if parent is None else bind[i] * bind[index[parent]].GetInverse()
            local.append(m)
        rest = local
    rot = np.empty((J, 4))
    pos = np.empty((J, 3))
    for i, m in enumerate(rest):
        q = m.ExtractRotationQuat()
        rot[i] = [q.GetReal(), *q.GetImaginary()]
        pos[i] = list(m.ExtractTranslation())
    return rot, pos


def _tokens(attr, label) -> list[str]:
    """The joint paths an attribute holds (``[]`` when it has no value), or a :class:`FormatError`."""
    value = attr.Get()
    if value is None:
        return []
    if type(value).__name__ != "TokenArray":
        raise FormatError(f"{attr.GetPath()} holds a {type(value).__name__}, not a token[] of joint paths", label)
    return [str(t) for t in value]


def _matrices_of(attr, label):
    """The matrix4d[] an attribute holds (None when it has no value), or a :class:`FormatError`."""
    value = attr.Get()
    if value is None:
        return None
    if type(value).__name__ != "Matrix4dArray":
        raise FormatError(f"{attr.GetPath()} holds a {type(value).__name__}, not a matrix4d[]", label)
    return value


def read(path: str | Path, label=None) -> Motion:
    """Read a UsdSkel animation into a :class:`Motion`; ``label`` names the file in errors.

    A keyfill curves file reads here as its stored SkelAnimation (32-bit
    floats, for viewers); :func:`keyfill.io.load` reads USD files through
    :func:`keyfill.io.usd_curves.read_motion`, which bakes the curves instead.
    """
    label = label if label is not None else path
    return read_stage(open_stage(path, label), label)


def open_stage(path: str | Path, label=None):
    """The ``Usd.Stage`` of ``path``; :class:`FormatError` (naming ``label``) when it is not USD or composes a
    layer that is not a regular file (:func:`~keyfill.io.usd_layers.composed_layers`)."""
    Usd = _pxr()[2]
    label = label if label is not None else path
    try:
        held = composed_layers(path, label)  # checked, and parsed once: the stage reuses them
        stage = Usd.Stage.Open(str(path))
        del held
    except FormatError:
        raise
    except Exception as e:  # noqa: BLE001 - pxr raises Tf.ErrorException (and others) with a multi-line text
        try:
            text = str(e)
        except UnicodeError:  # a message that cannot be decoded (a file that is not UTF-8)
            text = "not UTF-8 text"
        first = text.strip().splitlines()
        raise FormatError(f"not a readable USD file ({first[-1].strip() if first else 'parse error'})", label) from None
    if stage is None:
        raise FormatError("not a readable USD file", label)
    return stage


def read_stage(stage, label) -> Motion:
    """The UsdSkel animation of an open stage as a :class:`Motion` (see the module docstring)."""
    from pxr import Tf

    try:
        return _read_stage(stage, label)
    except Tf.ErrorException as e:  # USD refusing what the file composes to (e.g. a relationship that is not one)
        try:
            text = " ".join(str(e).split())
        except UnicodeError:  # a message that is not UTF-8
            text = "an error in the file's content"
        raise FormatError(f"USD cannot read this file: {text[-300:]}", label) from None


def _read_stage(stage, label) -> Motion:
    _Gf, _Sdf, Usd, UsdGeom, UsdSkel, Vt = _pxr()
    skel = _find_skeleton(stage, UsdSkel, label)
    joints = _tokens(skel.GetJointsAttr(), label)
    if not joints:
        raise FormatError(f"the Skeleton {skel.GetPath()} has no joints", label)
    topo = UsdSkel.Topology(Vt.TokenArray(joints))
    ok, why = topo.Validate()
    if not ok:
        raise FormatError(f"the Skeleton's joints are not a valid hierarchy: {why}", label)
    parents = np.array(topo.GetParentIndices(), dtype=np.int64)
    if np.any(parents >= np.arange(len(joints))):
        raise FormatError("the Skeleton lists a joint before its parent", label)
    anim = _find_animation(stage, skel, UsdSkel, label)
    anim_joints = _tokens(anim.GetJointsAttr(), label)
    index = {p: i for i, p in enumerate(joints)}
    unknown = [p for p in anim_joints if p not in index]
    if unknown:
        raise FormatError(f"the animation's joint {unknown[0]!r} is not in the Skeleton", label)
    to_skel = np.array([index[p] for p in anim_joints], dtype=np.int64)
    if len(set(to_skel.tolist())) != len(to_skel):
        raise FormatError("the animation lists a joint twice", label)

    if len(joints) > limits.max_joints():
        raise FormatError(f"{len(joints)} joints is more than keyfill reads ({limits.max_joints()}; set KEYFILL_MAX_JOINTS)", label)
    rest_rot, rest_pos = _rest_local(skel, joints, label)
    t_attr, r_attr, s_attr = anim.GetTranslationsAttr(), anim.GetRotationsAttr(), anim.GetScalesAttr()
    t_times, r_times, s_times = (np.array(a.GetTimeSamples(), dtype=np.float64) for a in (t_attr, r_attr, s_attr))
    times = np.sort(np.concatenate((t_times, r_times)))  # their union (np.union1d would import numpy.ma)
    first = np.ones(len(times), dtype=bool)
    first[1:] = times[1:] != times[:-1]
    times = times[first].tolist()
    start, end = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    if not stage.HasAuthoredMetadata("startTimeCode") and times:
        start, end = times[0], times[-1]
    for what, t in (("startTimeCode", start), ("endTimeCode", end)) + tuple(("a time sample", t) for t in times[:1] + times[-1:]):
        if not abs(t) <= limits.MAX_TIME_CODE:
            raise FormatError(f"{what} {t:g} is not a time code keyfill reads (finite, at most {limits.MAX_TIME_CODE:g})", label)
    if times and (times[0] < start or times[-1] > end):
        start, end = min(start, times[0]), max(end, times[-1])
    if end < start:
        raise FormatError(f"endTimeCode {end:g} comes before startTimeCode {start:g}", label)
    num_frames = round(end - start) + 1 if times or stage.HasAuthoredMetadata("endTimeCode") else 1
    problem = limits.check_size(num_frames, len(joints), _file_size(stage.GetRootLayer().realPath))
    if problem:
        raise FormatError(f"time codes {start:g} to {end:g}: {problem}", label)
    fps = stage.GetTimeCodesPerSecond()
    problem = limits.check_fps(fps)
    if problem:
        raise FormatError(f"timeCodesPerSecond: {problem}", label)

    # The motion's own arrays, filled a block at a time; joints the animation leaves out keep their rest pose.
    rot = np.empty((num_frames, len(joints), 4))
    pos = np.empty((num_frames, len(joints), 3))
    animated = slice(None) if np.array_equal(to_skel, np.arange(len(joints))) else to_skel
    left_out = np.ones(len(joints), dtype=bool)
    left_out[to_skel] = False
    rot[:, left_out] = rest_rot[left_out]
    pos[:, left_out] = rest_pos[left_out]
    n = len(anim_joints)
    held = stage.GetInterpolationType() == Usd.InterpolationTypeHeld
    frame_times = start + np.arange(num_frames, dtype=np.float64)

    def put_translations(frames, values):  # the decimals that went in (float32 noise off)
        pos[frames, animated] = decimals(values)

    def put_rotations(frames, values):
        rot[frames, animated] = values[..., [3, 0, 1, 2]]

    total = sum(max(1, len(t)) for t in (t_times, r_times, s_times))
    with progress.task("reading USD", total, " samples") as update:
        resolve(t_attr, t_times, frame_times, n, 3, held, put_translations, label, update)
        resolve(r_attr, r_times, frame_times, n, 4, held, put_rotations, label, update)
        scales = samples(s_attr, s_times, None, 3, label, update)
        if scales is not None:
            times_s, blocks = scales
            for i, values in blocks:
                scaled = np.flatnonzero(np.abs(values - 1).max(axis=(1, 2), initial=0.0) > 1e-3)
                if scaled.size:
                    raise DataError(f"{label}: joints are scaled at time {times_s[i + scaled[0]]:g}; "
                                    "keyfill motions have no scale")
    for a in range(0, num_frames, BLOCK):
        block = rot[a : a + BLOCK]
        if not (np.abs(block) <= limits.max_abs()).all():  # before squaring: 1e200 overflows the norm
            raise FormatError(f"a rotation is not finite or beyond {limits.max_abs():g}", label)
        norms = np.linalg.norm(block, axis=-1, keepdims=True)
        if np.any(norms < 1e-6):
            raise FormatError("a rotation is zero (not a quaternion)", label)
        block /= norms

    from keyfill.io.usd_custom import SKELETON, checked

    custom = checked(skel.GetPrim().GetCustomDataByKey(CUSTOM_KEY), SKELETON, label)
    skeleton = _skeleton_from(custom, joints, parents, rest_pos, rot, pos, stage, UsdGeom, label)
    try:
        keys = None
        if "keys" in custom:
            frames = _int_list(custom["keys"], "keys", label)
            mask = None
            if "keyMask" in custom:
                flags = _int_list(custom["keyMask"], "keyMask", label)
                if not np.isin(flags, (0, 1)).all():
                    raise FormatError(f"customData {CUSTOM_KEY}.keyMask must hold 0 and 1 only", label)
                J = skeleton.num_joints
                if len(flags) != len(frames) * J:
                    raise DataError(f"{label}: keyMask holds {len(flags)} values for {len(frames)} keys of {J} joints")
                mask = np.array(flags, dtype=bool).reshape(len(frames), J)
            keys = Keys(frames, mask, str(custom.get("keyGiven", "pose")))
        elif times and len(times) < num_frames:
            frames = np.array(times) - start
            if np.any(np.abs(frames - np.round(frames)) > 1e-6):
                raise DataError(f"{label}: animation samples at fractional time codes cannot be keys")
            keys = Keys(np.round(frames).astype(np.int64))
        return Motion(skeleton, fps, rot, pos, keys=keys)
    except FormatError:
        raise
    except KeyfillError as e:  # keys or arrays that do not fit: bad data in this file, not bad usage
        raise FormatError(str(e).removeprefix(f"{label}: "), label) from None


def _file_size(path) -> int:
    try:
        return Path(path).stat().st_size
    except OSError:
        return 0


def _int_list(value, what: str, label) -> np.ndarray:
    """``value`` (a customData array) as whole numbers, or a :class:`FormatError`."""
    try:
        items = list(value)
    except TypeError:
        raise FormatError(f"customData {CUSTOM_KEY}.{what} is not a list", label) from None
    if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) and abs(v) < 2**62 for v in items):
        raise FormatError(f"customData {CUSTOM_KEY}.{what} must hold whole numbers", label)
    return np.array(items, dtype=np.int64)


def _skeleton_from(custom, joints, parents, rest_pos, rot, pos, stage, UsdGeom, label) -> Skeleton:
    J = len(joints)
    names = _str_list(custom.get("names", []), "names", label)
    if len(names) != J:
        names = [p.rsplit("/", 1)[-1] for p in joints]
    channels_text = _str_list(custom.get("channels", []), "channels", label)
    if len(channels_text) == J:
        channels = [tuple(c.split()) for c in channels_text]
    else:
        # No layout recorded: roots and joints whose translation moves get
        # position channels, every joint gets three rotation channels.
        moving = _largest_move(pos, rest_pos) > 1e-6 * max(1.0, np.abs(rest_pos).max())
        channels = [
            FULL_ROOT_CHANNELS if parents[j] < 0 or moving[j] else FULL_CHANNELS for j in range(J)
        ]
    end_joints = _int_list(custom.get("endSiteJoints", []), "endSiteJoints", label)
    try:
        end_offsets = np.array([list(o) for o in custom.get("endSiteOffsets", [])], dtype=np.float64).reshape(-1, 3)
    except (TypeError, ValueError):
        raise FormatError(f"customData {CUSTOM_KEY}.endSiteOffsets is not a list of 3-vectors", label) from None
    if len(end_joints) != len(end_offsets) or np.any((end_joints < 0) | (end_joints >= J)):
        raise FormatError(f"customData {CUSTOM_KEY}: the End Sites do not match the joints", label)
    if not (np.abs(end_offsets) <= limits.max_abs()).all():
        raise FormatError(f"customData {CUSTOM_KEY}: an End Site offset is not finite or beyond {limits.max_abs():g}", label)
    if not (np.abs(rest_pos) <= limits.max_abs()).all():
        raise FormatError(f"a rest translation is not finite or beyond {limits.max_abs():g}", label)
    up = str(UsdGeom.GetStageUpAxis(stage)).upper()
    mpu = UsdGeom.GetStageMetersPerUnit(stage)
    try:
        return Skeleton(
            names=tuple(names),
            parents=parents,
            offsets=rest_pos,
            channels=tuple(channels),
            end_sites=tuple((int(j), o) for j, o in zip(end_joints, end_offsets)),
            meters_per_unit=float(mpu) if 0 < mpu < float("inf") else 0.01,
            up_axis=up if up in ("Y", "Z") else "Y",
        )
    except (DataError, ValueError) as e:  # ValueError: an unknown channel name
        raise FormatError(f"the Skeleton's keyfill layout: {e}" if isinstance(e, ValueError) else str(e), label) from None


def _largest_move(pos: np.ndarray, rest_pos: np.ndarray) -> np.ndarray:
    """``(J,)``: each joint's largest distance along an axis from its rest translation over the frames of
    ``pos (F, J, 3)``, a block of frames at a time."""
    move = np.zeros(len(rest_pos))
    for a in range(0, len(pos), BLOCK):
        move = np.maximum(move, np.abs(pos[a : a + BLOCK] - rest_pos).max(axis=(0, 2)))
    return move


def _str_list(value, what: str, label) -> list[str]:
    """``value`` (a customData array) as strings, or a :class:`FormatError`."""
    if isinstance(value, str):
        raise FormatError(f"customData {CUSTOM_KEY}.{what} is not a list of strings", label)
    try:
        items = list(value)
    except TypeError:
        raise FormatError(f"customData {CUSTOM_KEY}.{what} is not a list", label) from None
    if not all(isinstance(v, str) for v in items):
        raise FormatError(f"customData {CUSTOM_KEY}.{what} must hold strings", label)
    return items
