"""USD files (``.usda``, ``.usdc``, ``.usd``) through UsdSkel.

Layout keyfill writes::

    /<Root>                 SkelRoot, the stage's defaultPrim
    /<Root>/Skeleton        Skeleton: joints (paths), jointNames, restTransforms
                            (local), bindTransforms (world); SkelBindingAPI with
                            skel:animationSource -> <name>
    /<Root>/Skeleton/<name> SkelAnimation: translations, rotations, scales as
                            time samples, one per frame (time code = frame index);
                            named after the output file (its stem as an identifier)

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
animate keep their rest transform. When the animation's samples are sparse
(fewer sample times than frames in the stage's time range), frames in between
are USD's interpolation of the samples and the sample times become the keys of
the motion.

USD stores translations and rotations as 32-bit floats: a round trip through
USD keeps about 7 significant digits. Translations are written without
negative zeros and read back as the shortest decimal that rounds to the
stored float (:func:`shortest_decimal`): ``-0.2399`` comes back as ``-0.2399``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from keyfill import limits, progress
from keyfill.errors import DataError, FormatError, KeyfillError
from keyfill.kinematics import fk
from keyfill.motion import POSITION_CHANNELS, Keys, Motion, Skeleton

CUSTOM_KEY = "keyfill"
_DEFAULT_ROOT_CHANNELS = POSITION_CHANNELS + ("Zrotation", "Xrotation", "Yrotation")
_DEFAULT_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")


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


def shortest_decimal(values: np.ndarray) -> np.ndarray:
    """The 32-bit floats ``values`` (read from USD) as the doubles of their shortest decimals: ``-0.2399``
    stored as float32 reads back as the double ``-0.2399``, not ``-0.239899992943``, so a round trip writes
    the number that went in. Each value is the double nearest to the decimal of fewest significant digits
    (1 to 9) that rounds to the same float32; no negative zero."""
    x = np.asarray(values, dtype=np.float64)
    x32 = x.astype(np.float32)
    out = x.copy()
    todo = np.isfinite(x) & (x != 0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        exponent = np.floor(np.log10(np.abs(np.where(todo, x, 1.0)))).astype(np.int64)
        for digits in range(1, 10):
            if not todo.any():
                break
            k = digits - 1 - exponent  # decimal places
            up = np.where(k >= 0, k, 0)
            down = np.where(k < 0, -k, 0)
            # one correctly rounded operation on exact operands: the double nearest to the decimal
            candidate = np.where(k >= 0, np.round(x * 10.0 ** up) / 10.0 ** up, np.round(x / 10.0 ** down) * 10.0 ** down)
            hit = todo & (candidate.astype(np.float32) == x32)
            out[hit] = candidate[hit]
            todo &= ~hit
    return out + 0.0


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
    """Write ``motion`` to a USD file (format from the suffix).

    Args:
        sparse: author time samples only at ``motion.keys`` (a keyframe file);
            readers then see the keys as the motion's keys.
        root_name: name of the SkelRoot prim.
        name: name of the SkelAnimation prim, made an identifier (letters,
            digits and ``_``, not starting with a digit; :func:`keyfill.io.save`
            gives the output's stem); None: ``Animation``.
    """
    Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt = _pxr()
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
    skel.GetPrim().SetCustomDataByKey(CUSTOM_KEY, custom)

    anim.CreateJointsAttr(paths)
    t_attr = anim.CreateTranslationsAttr()
    r_attr = anim.CreateRotationsAttr()
    s_attr = anim.CreateScalesAttr()
    s_attr.Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * sk.num_joints))
    frames = list(range(motion.num_frames))
    if sparse:
        if motion.keys is None:
            raise DataError("a sparse USD file needs keys")
        frames = motion.keys.to_list()
    # Samples go straight into the layer, in one change block: the same file as
    # attr.Set per frame, four times faster (no change notice per sample). The
    # 32-bit copies are made a block of frames at a time (little memory beside the layer).
    layer, t_path, r_path = stage.GetRootLayer(), t_attr.GetPath(), r_attr.GetPath()
    block = 4096
    with progress.task("writing USD", len(frames), " frames") as update, Sdf.ChangeBlock():
        for a in range(0, len(frames), block):
            chunk = frames[a : a + block]
            rot = _quat_to_xyzw(motion.rotations[chunk])
            pos = _float32(motion.positions[chunk])
            for k, f in enumerate(chunk):
                layer.SetTimeSample(t_path, f, Vt.Vec3fArray.FromNumpy(pos[k]))
                layer.SetTimeSample(r_path, f, Vt.QuatfArray.FromNumpy(rot[k]))
            update(len(chunk))
    stage.GetRootLayer().Export(str(path))


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


def _sample_times(attrs) -> list[float]:
    times: set[float] = set()
    for a in attrs:
        times.update(a.GetTimeSamples())
    return sorted(times)


def read(path: str | Path, label=None) -> Motion:
    """Read a UsdSkel animation into a :class:`Motion`; ``label`` names the file in errors.

    A keyfill curves file reads here as its stored SkelAnimation (32-bit
    floats, for viewers); :func:`keyfill.io.load` reads USD files through
    :func:`keyfill.io.usd_curves.read_motion`, which bakes the curves instead.
    """
    label = label if label is not None else path
    return read_stage(open_stage(path, label), label)


def open_stage(path: str | Path, label=None):
    """The ``Usd.Stage`` of ``path``; :class:`FormatError` (naming ``label``) when it is not USD."""
    Usd = _pxr()[2]
    label = label if label is not None else path
    try:
        stage = Usd.Stage.Open(str(path))
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
    times = _sample_times([t_attr, r_attr])
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

    rot = np.broadcast_to(rest_rot, (num_frames, len(joints), 4)).copy()
    pos = np.broadcast_to(rest_pos, (num_frames, len(joints), 3)).copy()
    n = len(anim_joints)
    held = stage.GetInterpolationType() == Usd.InterpolationTypeHeld
    frame_times = start + np.arange(num_frames, dtype=np.float64)
    samples = sum(max(1, attr.GetNumTimeSamples()) for attr in (t_attr, r_attr, s_attr))
    with progress.task("reading USD", samples, " samples") as update:
        for attr, out, width in ((t_attr, pos, 3), (r_attr, rot, 4)):
            values = _resolved(attr, frame_times, n, width, held, Usd, label, update)
            if values is not None:  # translations as the decimals that went in (float32 noise off)
                out[:, to_skel] = values[..., [3, 0, 1, 2]] if width == 4 else shortest_decimal(values)
            del values
        scales = _samples(s_attr, 3, Usd, label, update)
        if scales is not None:
            t_s, v_s = scales
            dev = np.array([np.abs(v - 1).max(initial=0.0) for v in v_s])
            if np.any(dev > 1e-3):
                t = t_s[int(np.flatnonzero(dev > 1e-3)[0])]
                raise DataError(f"{label}: joints are scaled at time {t:g}; keyfill motions have no scale")
    norms = np.linalg.norm(rot, axis=-1, keepdims=True)
    if np.any(norms < 1e-6):
        raise FormatError("a rotation is zero (not a quaternion)", label)
    rot /= norms

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
            frames = np.array([t - start for t in times])
            if np.any(np.abs(frames - np.round(frames)) > 1e-6):
                raise DataError(f"{label}: animation samples at fractional time codes cannot be keys")
            keys = Keys(np.round(frames).astype(np.int64))
        return Motion(skeleton, fps, rot, pos, keys=keys)
    except FormatError:
        raise
    except KeyfillError as e:  # keys or arrays that do not fit: bad data in this file, not bad usage
        raise FormatError(str(e).removeprefix(f"{label}: "), label) from None


def _samples(attr, width: int, Usd, label, update) -> tuple[np.ndarray, list[np.ndarray]] | None:
    """``(times (T,), values)``: an attribute's time samples (or its default value at time 0), or None.

    Each value is checked: an array of ``width``-vectors, every number finite and within the limits.
    """
    times = list(attr.GetTimeSamples())
    codes = [Usd.TimeCode(t) for t in times] if times else [Usd.TimeCode.Default()]
    limit = limits.max_abs()
    out = []
    for t, code in zip(times or [0.0], codes):
        v = attr.Get(code)
        if v is None:
            if times:
                raise FormatError(f"{attr.GetName()} has a blocked time sample at {t:g}", label)
            return None
        try:
            a = np.asarray(v, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.ndim != 2 or a.shape[1] != width:
            raise FormatError(f"{attr.GetName()} at time {t:g} is not an array of {width}-vectors", label)
        if not (np.abs(a) <= limit).all():
            raise FormatError(f"{attr.GetName()} at time {t:g} holds a value that is not finite or beyond {limit:g}", label)
        out.append(a)
        update(1)
    return np.array(times or [0.0]), out


def _resolved(attr, frame_times: np.ndarray, n: int, width: int, held: bool, Usd, label, update) -> np.ndarray | None:
    """``(F, n, width)``: the attribute's value at every frame, as USD resolves it, or None (no value).

    Only the samples are read from USD; frames between them are interpolated here
    as USD does (linear for vectors, GfSlerp for quaternions; held before the
    first and after the last sample, and everywhere when the stage's
    interpolation is held), so a file with two samples far apart costs no more
    than its frames.
    """
    got = _samples(attr, width, Usd, label, update)
    if got is None:
        return None
    times, vals = got
    for t, a in zip(times, vals):
        if a.shape[0] != n:
            raise FormatError(f"{attr.GetName()} at time {t:g} holds {len(a)} values for {n} animated joints", label)
    samples = np.stack(vals)  # (T, n, width)
    del vals
    T = len(times)
    lo = np.clip(np.searchsorted(times, frame_times, side="right") - 1, 0, T - 1)
    out = samples[lo]
    if held or T == 1:
        return out
    hi = np.minimum(lo + 1, T - 1)
    inside = (frame_times > times[lo]) & (frame_times < times[hi])
    if not inside.any():
        return out
    k = np.flatnonzero(inside)
    u = ((frame_times[k] - times[lo[k]]) / (times[hi[k]] - times[lo[k]]))[:, None, None]
    a, b = samples[lo[k]], samples[hi[k]]
    if width == 3:
        out[k] = a + u * (b - a)
        return out
    # GfSlerp on (x, y, z, w) quaternions: the shorter way round, linear when nearly equal
    cos = np.sum(a * b, axis=-1, keepdims=True)
    flip = cos < 0
    cos = np.abs(cos)
    theta = np.arccos(np.clip(cos, -1.0, 1.0))
    sin = np.sin(theta)
    near = 1.0 - cos <= 1e-5
    safe = np.where(near, 1.0, sin)
    s0 = np.where(near, 1.0 - u, np.sin((1.0 - u) * theta) / safe)
    s1 = np.where(near, u, np.sin(u * theta) / safe)
    out[k] = s0 * a + np.where(flip, -s1, s1) * b
    return out


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
        moving = np.abs(pos - rest_pos).max(axis=0, initial=0.0).max(axis=-1) > 1e-6 * max(1.0, np.abs(rest_pos).max())
        channels = [
            _DEFAULT_ROOT_CHANNELS if parents[j] < 0 or moving[j] else _DEFAULT_CHANNELS for j in range(J)
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
