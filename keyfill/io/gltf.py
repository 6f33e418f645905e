"""glTF 2.0 files (``.glb``, ``.gltf``): a skin is the skeleton, an animation the motion.

Mapping (both ways; :mod:`keyfill.io.gltf_write` writes, this module reads):

* Joints are the nodes of a skin, in the skin's order when parents come first;
  names are the node names (a nameless node is ``node<N>``, whitespace becomes
  ``_``, a repeated name gets ``_1``, ``_2``). The rest offset is the node's
  translation. A joint's scale must be 1 (keyfill motions have no scale); so
  must every animated scale.
* The motion: per joint, a ``rotation`` (glTF's x-y-z-w, turned into keyfill's
  w-x-y-z) and a ``translation`` channel. Frames are the times of the samplers
  on a grid at the frame rate: ``extras.keyfill.fps`` of the animation when
  keyfill wrote it, else one over the smallest step between sample times. A
  sampler whose times are off that grid is resampled: STEP holds, LINEAR
  interpolates (slerp for rotations), CUBICSPLINE follows its Hermite tangents.
  Channels of other nodes, and ``weights``, are ignored.
* Units and axes: glTF is metres and Y-up. Nodes above the skeleton's roots
  that are not joints (Blender's ``Armature`` with its 0.01 scale and its
  rotation) are folded into the roots, and their uniform scale becomes
  :attr:`~keyfill.motion.Skeleton.meters_per_unit`. When the skin's
  ``extras.keyfill`` records the units and up axis of the file keyfill wrote
  it from, the motion is turned back into them: BVH (cm, Y-up) -> glTF -> BVH
  gives the centimetres back, a Z-up USD file its Z axis.
* ``extras.keyfill`` of the skin: ``metersPerUnit``, ``upAxis``, ``channels``
  (per joint, its BVH channel names joined by spaces: layout and Euler order),
  ``endSites`` (``[joint, x, y, z]`` in the source units). Of the animation:
  ``fps`` and the keys (``keys``; partial keys add ``keyMask``, K x J row-major,
  and ``keyGiven``), as the USD writer keeps them. Without a recorded layout,
  roots and joints whose translation moves get position channels and every
  joint ``Zrotation Xrotation Yrotation``.
* A file with several skins or animations gives the first (or the one named
  by ``skin`` / ``animation``), and says so through :func:`keyfill.progress.note`.

glTF stores animation in 32-bit floats: a round trip keeps about 7 significant
digits of every rotation and translation (rest offsets and the extras keep all
of theirs). See ``docs/formats.md``.

Memory (issue 44): the buffers are not held (each channel's accessor is read
from the file when it is resampled into the motion's arrays, one channel at a
time), and what runs over every frame afterwards runs a block of frames at a
time (:data:`~keyfill.io.gltf_buffers.BLOCK` bytes of rotations), so reading
holds little beside the motion's own arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from keyfill import limits, progress
from keyfill import rotations as R
from keyfill.errors import DataError, FormatError, KeyfillError
from keyfill.io.gltf_buffers import BLOCK, Document, load_document, read_accessor
from keyfill.motion import FULL_CHANNELS, FULL_ROOT_CHANNELS, Keys, Motion, Skeleton, unique_names

EXTRAS = "keyfill"
#: rotation that turns a Z-up world into glTF's Y-up one (-90 degrees about X), w-x-y-z
Z_TO_Y = np.array([np.sqrt(0.5), -np.sqrt(0.5), 0.0, 0.0])
INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
#: a sample time within this many frames of a frame is on that frame
ON_GRID = 1e-3


@dataclass
class Rig:
    """The skeleton of one skin, joints ordered parents first.

    ``nodes (J,)`` node index of each joint; ``parents (J,)``; ``names``;
    ``rest_rot (J, 4)`` and ``rest_pos (J, 3)`` the joints' node transforms
    (file units); per root joint, ``above[j] = (rotation (4,), translation (3,))``
    of the nodes above it, whose common uniform scale is ``scale``.
    """

    skin: int
    nodes: list[int]
    parents: np.ndarray
    names: list[str]
    rest_rot: np.ndarray
    rest_pos: np.ndarray
    above: dict[int, tuple[np.ndarray, np.ndarray]]
    scale: float


def pick(items: list[dict], wanted: str | int | None, what: str, label, note: bool = True) -> int:
    """The index of the ``what`` (skin, animation) to read: ``wanted`` (name or index) or the first (noted
    unless ``note`` is false)."""
    if wanted is None:
        if len(items) > 1 and note:
            name = items[0].get("name")
            progress.note(f"{label}: {len(items)} {what}s; reading the first"
                          f"{f' ({name!r})' if name else ''}")
        return 0
    for i, item in enumerate(items):
        if wanted == i or wanted == item.get("name"):
            return i
    names = ", ".join(repr(x.get("name", i)) for i, x in enumerate(items))
    raise FormatError(f"no {what} {wanted!r}; the file has {names or 'none'}", label)


def parent_nodes(doc: Document) -> np.ndarray:
    """``(N,)`` the parent of every node (-1 for none); refuses a node with two parents and cycles."""
    nodes = doc.items("nodes")
    parent = np.full(len(nodes), -1, dtype=np.int64)
    for i, node in enumerate(nodes):
        for c in node.get("children", []):
            if not 0 <= c < len(nodes):
                raise FormatError(f"node {i} has child {c}, which does not exist", doc.label)
            if parent[c] != -1 or c == i:
                raise FormatError(f"node {c} is a child of two nodes (or of itself)", doc.label)
            parent[c] = i
    depth = np.full(len(nodes), -1, dtype=np.int64)  # walk each chain once: no recursion, no loop forever
    for i in range(len(nodes)):
        chain, n = [], i
        while n != -1 and depth[n] < 0:
            depth[n] = len(nodes) + 1  # being visited
            chain.append(n)
            n = parent[n]
        if n != -1 and depth[n] == len(nodes) + 1:
            raise FormatError(f"node {n} is its own ancestor (the node hierarchy has a cycle)", doc.label)
        for m in chain:
            depth[m] = 0
    return parent


def node_transform(node: dict, i: int, label) -> np.ndarray:
    """The ``(4, 4)`` local matrix of a node (column vectors), from ``matrix`` or T, R, S."""
    return node_transforms([node], [i], label)[0]


def node_transforms(nodes: list[dict], ids: list[int], label) -> np.ndarray:
    """``(K, 4, 4)`` local matrices of ``nodes`` (numbered ``ids`` in errors), at once: a rig of thousands of
    joints is one array operation, not thousands."""
    limit = limits.max_abs()
    K = len(nodes)
    t, q, s = np.zeros((K, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (K, 1)), np.ones((K, 3))
    given, mats = [], []
    for k, (node, i) in enumerate(zip(nodes, ids)):
        for key, size in (("matrix", 16), ("translation", 3), ("rotation", 4), ("scale", 3)):
            if key in node and (len(node[key]) != size or not all(abs(v) <= limit for v in node[key])):
                raise FormatError(f"node {i}'s {key} is not {size} finite numbers within {limit:g}", label)
        if "matrix" in node:
            given.append(k)
            mats.append(node["matrix"])
            continue
        if "translation" in node:
            t[k] = node["translation"]
        if "rotation" in node:
            x, y, z, w = node["rotation"]
            q[k] = w, x, y, z
        if "scale" in node:
            s[k] = node["scale"]
    norm = np.linalg.norm(q, axis=1)
    if np.any(norm < 1e-6):
        raise FormatError(f"node {ids[int(np.argmax(norm < 1e-6))]}'s rotation is zero (not a quaternion)", label)
    m = np.broadcast_to(np.eye(4), (K, 4, 4)).copy()
    m[:, :3, :3] = R.quat_to_matrix(q / norm[:, None]) * s[:, None, :]
    m[:, :3, 3] = t
    if given:
        m[given] = np.array(mats, dtype=np.float64).reshape(-1, 4, 4).transpose(0, 2, 1)
    return m


def decompose(m: np.ndarray, what: str, label) -> tuple[np.ndarray, float, np.ndarray]:
    """``(rotation (4,), uniform scale, translation (3,))`` of a matrix; refuses shear, mirrors, uneven scale."""
    q, scale, t = decompose_all(m[None], [what], label)
    return q[0], float(scale[0]), t[0]


def decompose_all(m: np.ndarray, whats: list[str], label) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`decompose` of ``(K, 4, 4)`` matrices at once: ``(rotations (K, 4), scales (K,), translations
    (K, 3))``; ``whats[k]`` names matrix ``k`` in the error."""
    with np.errstate(all="ignore"):  # a degenerate or huge matrix: refused below, without numpy's warnings
        cols = np.linalg.norm(m[:, :3, :3], axis=1)
        scale = cols.mean(axis=1)
        rot = m[:, :3, :3] / np.maximum(scale, 1e-300)[:, None, None]
        bad = (~(scale > 0) | ~np.isfinite(rot).all(axis=(1, 2))
               | (np.abs(cols - scale[:, None]).max(axis=1) > 1e-6 * scale)
               | (np.abs(rot.transpose(0, 2, 1) @ rot - np.eye(3)).max(axis=(1, 2)) > 1e-6)
               | (np.linalg.det(np.nan_to_num(rot)) < 0))
    if bad.any():
        raise FormatError(f"{whats[int(np.argmax(bad))]} is scaled unevenly, sheared or mirrored; keyfill reads "
                          "rigid joints", label)
    return R.quat_from_matrix(rot), scale, m[:, :3, 3].copy()


def joint_names(nodes: list[dict], joints: list[int]) -> list[str]:
    """Joint names: node names without whitespace, ``node<N>`` when nameless, repeats numbered
    (:func:`keyfill.motion.unique_names`)."""
    return unique_names([nodes[n].get("name", "") for n in joints], [f"node{n}" for n in joints])


def rig_of(doc: Document, skin: str | int | None, note: bool = True) -> Rig:
    """The :class:`Rig` of the chosen skin (see :func:`pick`)."""
    label, nodes, skins = doc.label, doc.items("nodes"), doc.items("skins")
    if not skins:
        raise FormatError("no skin in this file: keyfill reads a skeleton from a glTF skin", label)
    s = pick(skins, skin, "skin", label, note)
    joints = skins[s].get("joints", [])
    if not joints:
        raise FormatError(f"skin {s} has no joints", label)
    if len(joints) > limits.max_joints():
        raise FormatError(f"{len(joints)} joints is more than keyfill reads ({limits.max_joints()}; "
                          "set KEYFILL_MAX_JOINTS to raise it)", label)
    if any(not 0 <= n < len(nodes) for n in joints) or len(set(joints)) != len(joints):
        raise FormatError(f"skin {s} lists a node that does not exist, or one node twice", label)
    if "inverseBindMatrices" in skins[s]:
        ibm = read_accessor(doc, skins[s]["inverseBindMatrices"], f"skin {s}'s inverseBindMatrices", ("MAT4",),
                            floats_only=True)
        if len(ibm) != len(joints):
            raise FormatError(f"skin {s} has {len(joints)} joints and {len(ibm)} inverse bind matrices", label)
    parent = parent_nodes(doc)
    index = {n: j for j, n in enumerate(joints)}
    between = _between(nodes, parent, index, label)
    parents, above_of = [], {}
    for n in joints:
        p = int(parent[n])
        up, still, m = (-1, True, None) if p == -1 else (p, True, None) if p in index else between[p]
        if up != -1 and not still:
            raise FormatError(f"joint node {n}'s parent node {p} is not a joint of skin {s} and moves it", label)
        parents.append(-1 if up == -1 else index[up])
        if up == -1:
            above_of[index[n]] = np.eye(4) if m is None else m
    order = _parents_first(parents)
    new = {old: j for j, old in enumerate(order)}
    joints = [joints[j] for j in order]
    parents = np.array([-1 if parents[j] < 0 else new[parents[j]] for j in order], dtype=np.int64)
    rest_rot, s_j, rest_pos = decompose_all(node_transforms([nodes[n] for n in joints], joints, label),
                                            [f"joint node {n}" for n in joints], label)
    if np.any(np.abs(s_j - 1) > 1e-3):
        k = int(np.argmax(np.abs(s_j - 1) > 1e-3))
        raise DataError(f"{label}: joint node {joints[k]} is scaled ({s_j[k]:g}); keyfill motions have no scale")
    above, scales = {}, []
    for old, m in above_of.items():
        q, scale, t = decompose(m, f"the nodes above joint node {joints[new[old]]}", label)
        above[new[old]] = (q, t)
        scales.append(scale)
    if max(scales) - min(scales) > 1e-6 * max(scales):
        raise FormatError(f"the roots of skin {s} sit under nodes of different scales", label)
    return Rig(s, joints, parents, joint_names(nodes, joints), rest_rot, rest_pos, above, float(scales[0]))


def _between(nodes: list[dict], parent: np.ndarray, index: dict[int, int], label) -> dict:
    """Per node that is no joint (of ``index``) and lies above one: ``(the nearest joint above it or -1, whether
    it and the other nodes up to that joint are at rest (identity), their product (4, 4))``.

    Each node is walked and multiplied once, whatever the number of joints under it: a chain of thousands of
    such nodes costs as much as its length (it used to be walked again for every joint, quadratic).
    """
    out: dict[int, tuple[int, bool, np.ndarray]] = {}
    for n in index:
        chain, p = [], int(parent[n])
        while p != -1 and p not in index and p not in out:
            chain.append(p)
            p = int(parent[p])
        if not chain:
            continue
        mats = node_transforms([nodes[b] for b in chain], chain, label)
        for b, m in zip(reversed(chain), mats[::-1]):  # from the top down
            q = int(parent[b])
            up, still, above = (-1, True, np.eye(4)) if q == -1 else (q, True, np.eye(4)) if q in index else out[q]
            out[b] = (up, still and np.abs(m - np.eye(4)).max() <= 1e-9, above @ m)
    return out


def _parents_first(parents: list[int]) -> list[int]:
    """The joints in their own order when parents come first, else depth first from the roots."""
    if all(p < j for j, p in enumerate(parents)):
        return list(range(len(parents)))
    kids: dict[int, list[int]] = {}
    for j, p in enumerate(parents):
        kids.setdefault(p, []).append(j)
    order, stack = [], list(reversed(kids.get(-1, [])))
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(kids.get(j, [])))
    return order


def extras_of(item: dict, what: str, label) -> dict:
    """``item["extras"]["keyfill"]`` (``{}`` when absent; extras of another kind are not keyfill's)."""
    extras = item.get("extras")
    if not isinstance(extras, dict) or EXTRAS not in extras:
        return {}
    if not isinstance(extras[EXTRAS], dict):
        raise FormatError(f"the {what}'s extras.{EXTRAS} is not an object", label)
    return extras[EXTRAS]


@dataclass
class Track:
    """One channel: joint ``joint``, ``path`` (translation, rotation, scale), sample ``times`` (seconds, or
    frames once placed on the grid) and interpolation; :meth:`values` reads its samples again when asked."""

    joint: int
    path: str
    times: np.ndarray
    interpolation: str
    doc: Document
    output: int  #: the accessor of its values
    what: str

    def values(self) -> np.ndarray:
        """``(S, W)`` float64 (``3S`` rows for CUBICSPLINE: in-tangent, value, out-tangent), rotations as w, x,
        y, z: read from the file's buffer each time, so a long take holds one track's values at a time."""
        values = read_accessor(self.doc, self.output, self.what + " output",
                               ("VEC4",) if self.path == "rotation" else ("VEC3",), floats_only=self.path != "rotation")
        return values[:, [3, 0, 1, 2]] if self.path == "rotation" else values


def tracks_of(doc: Document, anim: dict, a: int, rig: Rig) -> list[Track]:
    """The channels of animation ``a`` that move joints of ``rig``, checked (their values read once, to check
    them, and let go: :meth:`Track.values` reads them again where they are used)."""
    label, samplers = doc.label, anim.get("samplers", [])
    index = {n: j for j, n in enumerate(rig.nodes)}
    tracks, seen, times_of = [], set(), {}
    for c, channel in enumerate(anim.get("channels", [])):
        target = channel.get("target", {})
        node, path = target.get("node"), target.get("path")
        if node not in index or path not in ("translation", "rotation", "scale"):
            continue
        if (node, path) in seen:
            raise FormatError(f"animation {a} has two {path} channels for node {node}", label)
        seen.add((node, path))
        s = channel.get("sampler")
        if s is None or not 0 <= s < len(samplers):
            raise FormatError(f"animation {a}'s channel {c} names sampler {s!r}, which does not exist", label)
        sampler = samplers[s]
        interp = sampler.get("interpolation", "LINEAR")
        if interp not in INTERPOLATIONS:
            raise FormatError(f"animation {a}'s sampler {s} has interpolation {interp!r}; expected "
                              f"{', '.join(INTERPOLATIONS)}", label)
        what = f"animation {a} sampler {s}"
        if sampler.get("input") not in times_of:  # samplers share their times (keyfill's: one accessor for all)
            times_of[sampler.get("input")] = read_accessor(doc, sampler.get("input"), what + " input", ("SCALAR",),
                                                           floats_only=True)[:, 0]
        times = times_of[sampler.get("input")]
        values = read_accessor(doc, sampler.get("output"), what + " output",
                               ("VEC4",) if path == "rotation" else ("VEC3",), floats_only=path != "rotation")
        per_key = 3 if interp == "CUBICSPLINE" else 1
        if len(values) != per_key * len(times):
            raise FormatError(f"{what} has {len(times)} times and {len(values)} values (expected "
                              f"{per_key * len(times)} for {interp})", label)
        if np.any(np.diff(times) < 0):
            raise FormatError(f"{what}'s times are not in increasing order", label)
        del values
        tracks.append(Track(index[node], path, times, interp, doc, sampler.get("output"), what))
    return tracks


def guess_fps(tracks: list[Track]) -> float:
    """One over the smallest step between sample times, snapped to a whole rate (or a NTSC one) when close."""
    steps = [np.diff(t)[np.diff(t) > 1e-6] for t in {id(tr.times): tr.times for tr in tracks}.values() if len(t) > 1]
    steps = [s.min() for s in steps if len(s)]
    if not steps:
        return 30.0
    fps = 1.0 / min(steps)
    for nice in (round(fps), round(fps * 1.001) / 1.001):
        if nice > 0 and abs(fps - nice) <= 1e-3 * nice:
            return float(nice)
    return float(fps)


def grid_tolerance(times: np.ndarray, fps: float) -> np.ndarray:
    """``(S,)`` frames: how far a sample at ``times`` (seconds) may be from a frame and still be on it.

    :data:`ON_GRID`, plus one step of 32-bit floats at that time (glTF's times are 32-bit: at 120 fps they
    are that coarse beyond about two minutes, so a long take's frames would otherwise fall off the grid and be
    resampled between their neighbours).
    """
    return ON_GRID + fps * np.spacing(np.abs(times).astype(np.float32)).astype(np.float64)


def resample(track: Track, x: np.ndarray, seconds: float, near: np.ndarray) -> np.ndarray:
    """``(F, W)``: the track's value at frames ``x (F,)``; its ``times`` are in frames too, of ``seconds`` each.

    Frames within ``near`` (``(S,)`` frames per sample: :func:`grid_tolerance`) of a sample take its value
    exactly; those between samples follow the sampler's interpolation (CUBICSPLINE tangents are per second);
    before the first and after the last sample the value is held.
    """
    values = track.values()
    keys = values[1::3] if track.interpolation == "CUBICSPLINE" else values
    t = track.times
    k = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 1)
    out = keys[k]  # indexed: a new array
    if len(t) == 1:
        return out
    hi = np.minimum(k + 1, len(t) - 1)
    span = t[hi] - t[k]
    at_hi = (hi != k) & (t[hi] - x <= near[hi])
    out[at_hi] = keys[hi[at_hi]]
    mid = ~at_hi & (x - t[k] > near[k]) & (x < t[hi])
    if track.interpolation == "STEP" or not mid.any():
        return out
    i = np.flatnonzero(mid)
    m = ((x[i] - t[k[i]]) / span[i])[:, None]
    a, b = keys[k[i]], keys[hi[i]]
    if track.interpolation == "CUBICSPLINE":
        dt = span[i][:, None] * seconds
        out_tan, in_tan = values[2::3][k[i]], values[0::3][hi[i]]
        out[i] = ((2 * m**3 - 3 * m**2 + 1) * a + (m**3 - 2 * m**2 + m) * dt * out_tan
                  + (-2 * m**3 + 3 * m**2) * b + (m**3 - m**2) * dt * in_tan)
    elif track.path == "rotation":
        out[i] = R.quat_slerp(R.quat_normalize(a), R.quat_normalize(b), m[:, 0])
    else:
        out[i] = (1 - m) * a + m * b
    return out


def to_source(rig: Rig, rot: np.ndarray, pos: np.ndarray, rest: np.ndarray, mpu: float, up: str) -> None:
    """Fold the nodes above the roots into them and turn glTF's units and Y axis into ``mpu`` and ``up``, in place.

    ``rot (F, J, 4)``, ``pos (F, J, 3)``, ``rest (J, 3)``; see :func:`keyfill.io.gltf_write.from_source`.
    """
    for j, (q, t) in rig.above.items():
        rot[:, j] = R.quat_mul(q, rot[:, j])
        pos[:, j] = R.quat_rotate(q, pos[:, j]) + t / rig.scale
        rest[j] = R.quat_rotate(q, rest[j]) + t / rig.scale
    k = rig.scale / mpu
    pos *= k
    rest *= k
    if up == "Z":
        back = R.quat_conjugate(Z_TO_Y)
        for j in rig.above:
            rot[:, j] = R.quat_mul(back, rot[:, j])
            pos[:, j] = R.quat_rotate(back, pos[:, j])
            rest[j] = R.quat_rotate(back, rest[j])


def read(path: str | Path, label=None, skin: str | int | None = None, animation: str | int | None = None) -> Motion:
    """Read a glTF skin and animation into a :class:`Motion` (see the module docstring).

    Args:
        label: names the file in errors (default ``path``).
        skin, animation: name or index of the one to read (default: the first, noted when there are more).
    """
    label = path if label is None else label
    doc = load_document(Path(path), label)
    rig = rig_of(doc, skin)
    layout = extras_of(doc.items("skins")[rig.skin], "skin", label)
    anims = doc.items("animations")
    a = pick(anims, animation, "animation", label) if anims else None
    timing = extras_of(anims[a], "animation", label) if anims else {}
    tracks = tracks_of(doc, anims[a], a, rig) if anims else []
    fps = timing.get("fps", guess_fps(tracks))
    if type(fps) not in (int, float):
        raise FormatError(f"extras.{EXTRAS}.fps is not a number", label)
    problem = limits.check_fps(fps)
    if problem:
        raise FormatError(f"the animation's frame rate: {problem}", label)
    start = min((tr.times[0] for tr in tracks), default=0.0)
    end = max((tr.times[-1] for tr in tracks), default=0.0)
    span = float(end - start) * fps
    num_frames = round(span) + 1 if span < 1e15 else limits.max_frames() + 1
    problem = limits.check_size(num_frames, len(rig.nodes), doc.size)
    if problem:
        raise FormatError(f"the animation runs {end - start:g} s at {fps:g} fps: {problem}", label)
    frames = np.arange(num_frames, dtype=np.float64)
    rot = np.broadcast_to(rig.rest_rot, (num_frames, len(rig.nodes), 4)).copy()
    pos = np.broadcast_to(rig.rest_pos, (num_frames, len(rig.nodes), 3)).copy()
    sampled: set[int] = set()
    on_grid = True
    placed: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # per times array (tracks share them): frames, tolerance
    for tr in tracks:
        if id(tr.times) not in placed:
            x = (tr.times - start) * fps
            tol = grid_tolerance(tr.times, fps)
            near = np.abs(x - np.round(x)) <= tol
            on_grid &= bool(near.all())
            sampled.update(np.round(x[near]).astype(np.int64).tolist())
            placed[id(tr.times)] = x, tol
        x, tol = placed[id(tr.times)]
        values = resample(replace(tr, times=x), frames, 1.0 / fps, tol)
        if tr.path == "scale":
            dev = np.abs(values - 1).max(axis=1)
            if np.any(dev > 1e-3):
                raise DataError(f"{label}: joint {rig.names[tr.joint]!r} is scaled at frame "
                                f"{int(np.argmax(dev > 1e-3))}; keyfill motions have no scale")
        else:
            (rot if tr.path == "rotation" else pos)[:, tr.joint] = values
    step = _block_frames(len(rig.nodes))
    for a in range(0, num_frames, step):
        block = rot[a: a + step]
        norms = np.linalg.norm(block, axis=-1, keepdims=True)
        if np.any(norms < 1e-6):
            raise FormatError("a rotation is zero (not a quaternion)", label)
        block /= norms
    rest = rig.rest_pos.copy()
    mpu, up = layout.get("metersPerUnit", rig.scale), layout.get("upAxis", "Y")
    if type(mpu) not in (int, float) or not 0 < mpu < 1e12 or up not in ("Y", "Z"):
        raise FormatError(f"extras.{EXTRAS}: metersPerUnit must be a positive number and upAxis Y or Z", label)
    to_source(rig, rot, pos, rest, float(mpu), up)
    try:
        skeleton = _skeleton(layout, rig, rest, rot, pos, float(mpu), up, label)
        keys = _keys(timing, skeleton.num_joints, label)
        if keys is None and on_grid and tracks and len(sampled) < num_frames:
            keys = Keys(np.array(sorted(sampled), dtype=np.int64))
        return Motion(skeleton, float(fps), rot, pos, keys=keys)
    except FormatError:
        raise
    except KeyfillError as e:  # keys or arrays that do not fit: bad data in this file
        raise FormatError(str(e).removeprefix(f"{label}: "), label) from None


def _block_frames(joints: int) -> int:
    """Frames of ``joints`` rotations in :data:`~keyfill.io.gltf_buffers.BLOCK` bytes (at least one)."""
    return max(1, BLOCK // (32 * joints))


def _skeleton(layout: dict, rig: Rig, rest, rot, pos, mpu: float, up: str, label) -> Skeleton:
    J = len(rig.nodes)
    channels = layout.get("channels")
    if channels is not None and (not isinstance(channels, list) or len(channels) != J
                                 or not all(isinstance(c, str) for c in channels)):
        raise FormatError(f"extras.{EXTRAS}.channels must be {J} strings, one per joint", label)
    if channels is None:
        move, step = np.zeros(J), _block_frames(J)
        for a in range(0, len(pos), step):
            move = np.maximum(move, np.abs(pos[a: a + step] - rest).max(axis=(0, 2)))
        moving = move > 1e-6 * max(1.0, np.abs(rest).max())
        channels = [FULL_ROOT_CHANNELS if rig.parents[j] < 0 or moving[j] else FULL_CHANNELS for j in range(J)]
    else:
        channels = [tuple(c.split()) for c in channels]
    ends = layout.get("endSites", [])
    limit = limits.max_abs()
    if not isinstance(ends, list) or not all(
            isinstance(e, list) and len(e) == 4 and type(e[0]) is int and 0 <= e[0] < J
            and all(type(v) in (int, float) and abs(v) <= limit for v in e[1:]) for e in ends):
        raise FormatError(f"extras.{EXTRAS}.endSites must be [joint, x, y, z] lists of joints of the skin", label)
    try:
        return Skeleton(names=tuple(rig.names), parents=rig.parents, offsets=rest, channels=tuple(channels),
                        end_sites=tuple((e[0], np.array(e[1:], dtype=np.float64)) for e in ends),
                        meters_per_unit=mpu, up_axis=up)
    except (DataError, ValueError) as e:  # ValueError: an unknown channel name
        raise FormatError(f"the skin's keyfill layout: {e}", label) from None


def _keys(timing: dict, num_joints: int, label) -> Keys | None:
    if "keys" not in timing:
        return None
    frames = timing["keys"]
    if not isinstance(frames, list) or not all(type(f) is int for f in frames):
        raise FormatError(f"extras.{EXTRAS}.keys must be a list of frame numbers", label)
    mask = None
    if "keyMask" in timing:
        flags = timing["keyMask"]
        if not isinstance(flags, list) or not all(f in (0, 1) and type(f) is int for f in flags):
            raise FormatError(f"extras.{EXTRAS}.keyMask must hold 0 and 1 only", label)
        if len(flags) != len(frames) * num_joints:
            raise FormatError(f"extras.{EXTRAS}.keyMask holds {len(flags)} values for {len(frames)} keys of "
                              f"{num_joints} joints", label)
        mask = np.array(flags, dtype=bool).reshape(len(frames), num_joints)
    given = timing.get("keyGiven", "pose")
    return Keys(np.array(frames, dtype=np.int64), mask, given if isinstance(given, str) else repr(given))
