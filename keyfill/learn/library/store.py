"""A motion library on disk: clips of real motion on one humanoid skeleton, ready to be searched.

A library is a folder::

    LIB/library.json      the manifest: format, version, skeleton, frame rate, the clips (name, SHA-256 of
                          the source file's bytes, frame count), the arrays (dtype, shape, SHA-256) and the
                          library's own spread (see :mod:`keyfill.learn.library.index`)
    LIB/<array>.npy       one numpy array each (below), memory-mapped on load, never unpickled

Arrays, ``N`` frames of all clips one after another, ``J`` joints, ``D = J * 3``:

* ``rotations (N, J, 4)``: local joint rotations, except the hips' entry, which is the hips' *world* rotation
  (the joints above the hips are at rest in a library);
* ``hips (N, 3)``: the hips' world position (skeleton units);
* ``features (N, D)``: pose features (:mod:`keyfill.learn.library.features`, meters);
* ``ground (N, 2)``: the hips' point on the ground (meters); ``heading (N,)``: radians;
* ``roughness (N,)``: the source's own jitter at each frame (the norm of the third difference of the
  features, m/s^3), so that a search can prefer smooth sources;
* ``mean (D,)``, ``basis (D, d)``: the principal axes of the features; the search's tree works on
  ``(features - mean) @ basis``.

``rotations`` and ``features`` are float16 or float32 (``precision``); the others float32 (a ground point
in float16 would round to centimetres). Loading checks every field of the manifest and every array's dtype,
shape and hash (a hash is computed once per file and state of the file: :func:`keyfill.files.verified`).

Building (:func:`build`) reads each clip (any format keyfill reads), brings it onto the library's skeleton
through the rig bridge (:mod:`keyfill.learn.rig_bridge`) when it has another humanoid rig, resamples it to
the library's frame rate, and describes every frame. A re-build into an existing library reads only the
clips whose bytes are new; the library then holds exactly the clips given (other files of its folder, such
as a licence, stay).
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill import rotations as R
from keyfill.errors import DataError, ModelError, UsageError
from keyfill.files import sha256_file, verified
from keyfill.learn.library.features import Frames, describe, hips_world, pose_world
from keyfill.motion import Motion, Skeleton

FORMAT = "keyfill-library"
VERSION = 1
MANIFEST = "library.json"
#: arrays of a library and their dtype when not set by the precision
ARRAYS = ("rotations", "hips", "features", "ground", "heading", "roughness", "mean", "basis")
_PRECISE = ("hips", "ground", "heading", "roughness", "mean", "basis")
#: a clip needs this many frames (the source's jitter is a third difference)
MIN_CLIP_FRAMES = 4
MAX_MANIFEST_BYTES = 64 << 20
PRECISIONS = {"half": "float16", "single": "float32"}


@dataclass(frozen=True, eq=False)
class Clip:
    """One clip of a library: its source's ``name`` (the file name), the ``sha256`` of the source's bytes,
    and its frames ``start:stop`` in the arrays."""

    name: str
    sha256: str
    start: int
    stop: int


@dataclass(frozen=True, eq=False)
class Library:
    """A loaded motion library (the module docstring): its ``skeleton``, ``fps``, joint ``frames`` (which
    joint is the hips, ...), ``clips`` and the arrays as attributes (read-only memory maps), plus
    ``clip_of (N,)`` int32 (each frame's clip) and ``spread`` (meters: the typical distance of a library pose to
    the nearest pose of another clip, among the poses of its pose index; :mod:`keyfill.learn.library.index`)."""

    path: Path
    skeleton: Skeleton
    fps: float
    frames: Frames
    clips: tuple[Clip, ...]
    rotations: np.ndarray
    hips: np.ndarray
    features: np.ndarray
    ground: np.ndarray
    heading: np.ndarray
    roughness: np.ndarray
    mean: np.ndarray
    basis: np.ndarray
    clip_of: np.ndarray
    spread: float
    precision: str

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def name(self) -> str:
        return self.path.name

    def starts(self) -> np.ndarray:
        """``(C + 1,)`` first frame of each clip, then ``N``."""
        return np.array([c.start for c in self.clips] + [self.num_frames], dtype=np.int64)

    def info(self) -> dict:
        """A JSON-ready summary (``keyfill library info``)."""
        size = sum(f.stat().st_size for f in self.path.iterdir() if f.is_file())
        return {"library": str(self.path), "clips": len(self.clips), "frames": self.num_frames,
                "seconds": self.num_frames / self.fps, "fps": self.fps, "joints": self.skeleton.num_joints,
                "skeleton_top": self.skeleton.names[0], "hips": self.skeleton.names[self.frames.hips],
                "precision": self.precision, "spread_m": self.spread, "bytes": size}


# --- building ------------------------------------------------------------------------------------


def describe_motion(motion: Motion, frames: Frames) -> dict[str, np.ndarray]:
    """The library arrays of one clip on the library's skeleton and frame rate: ``rotations``, ``hips``,
    ``features``, ``ground``, ``heading``, ``roughness`` (float64; see the module docstring)."""
    sk = motion.skeleton
    q = R.quat_continuous_np(np.asarray(motion.rotations, dtype=np.float64), axis=0)
    hq, hp = hips_world(q, motion.positions, sk, frames)
    rot = q.copy()
    rot[:, frames.hips] = R.quat_continuous_np(hq, axis=0)
    world = pose_world(rot, hp, sk, frames)
    feats, ground, head = describe(world, frames)
    third = np.zeros(len(feats))
    if len(feats) >= 4:
        d3 = feats[3:] - 3 * feats[2:-1] + 3 * feats[1:-2] - feats[:-3]
        per = np.linalg.norm(d3.reshape(len(d3), -1, 3), axis=-1).mean(axis=-1) * motion.fps**3
        third[1:-2] = per
        third[0], third[-2:] = per[0], per[-1]
    return {"rotations": rot, "hips": hp, "features": feats, "ground": ground, "heading": np.unwrap(head),
            "roughness": third}


def on_library(motion: Motion, skeleton: Skeleton, fps: float, rig_map: dict | None = None,
               what: str = "the motion") -> Motion:
    """``motion`` on a library's ``skeleton`` (the rig bridge) and frame rate ``fps`` (resampled); a
    :class:`DataError` or :class:`ModelError` naming ``what`` when its rig cannot be brought there."""
    from keyfill import interpolate
    from keyfill.learn.rig_bridge import on_model_skeleton

    motion = on_model_skeleton(motion, served_by(skeleton, fps), rig_map, what=what)
    if abs(motion.fps - fps) > 1e-9 * fps:
        t = np.arange(0.0, (motion.num_frames - 1) / motion.fps + 1e-9, 1.0 / fps) * motion.fps
        rot, pos = interpolate.at_times(R.quat_continuous_np(motion.rotations, axis=0), motion.positions, t)
        motion = Motion(motion.skeleton, fps, rot, pos)
    return motion.replace(skeleton=skeleton)


def _clip_arrays(path: str, skeleton_json: dict, rig_map: dict | None, fps: float) -> dict:
    """One clip of a build (a worker's job): its arrays on the library's skeleton and frame rate."""
    from keyfill import io

    skeleton = Skeleton.from_json(skeleton_json)
    try:
        motion = on_library(io.load(path).replace(keys=None), skeleton, fps, rig_map, what=f"{Path(path).name}")
    except (DataError, ModelError) as e:
        raise DataError(f"{path}: cannot join the library: {e}") from None
    if motion.num_frames < MIN_CLIP_FRAMES:
        return {"skipped": f"{motion.num_frames} frames (a clip needs {MIN_CLIP_FRAMES})"}
    return describe_motion(motion, frames_of(skeleton))


def with_clip(lib: Library, motion: Motion, name: str) -> Library:
    """``lib`` with one more clip, ``motion`` (on its skeleton and frame rate, :func:`on_library`; at least
    :data:`MIN_CLIP_FRAMES` frames), in memory (nothing is written): a Motion DNA clip whose own stretches join
    the search (:func:`keyfill.learn.gan.matched_base.matched_start`)."""
    a = describe_motion(motion, lib.frames)
    n, N = motion.num_frames, lib.num_frames
    arrays = {k: np.concatenate([np.asarray(getattr(lib, k)), a[k].astype(getattr(lib, k).dtype)])
              for k in ("rotations", "hips", "features", "ground", "heading", "roughness")}
    clip_of = np.concatenate([lib.clip_of, np.full(n, len(lib.clips), dtype=lib.clip_of.dtype)])
    return dataclasses.replace(lib, clips=(*lib.clips, Clip(name, "", N, N + n)), clip_of=clip_of, **arrays)


def served_by(skeleton: Skeleton, fps: float):
    """What a library of ``skeleton`` at ``fps`` serves, as the rig bridge compares motions with it
    (:class:`keyfill.learn.rig_bridge.Served`): a motion fits when its bones match, whatever its hips'
    translation; a single top joint above the hips (Bandai's ``joint_Root``) is folded into them for the
    comparison, as the human models' corpora fold it."""
    from keyfill.learn.rig_bridge import Served

    frames = frames_of(skeleton)
    folded = frames.ancestors == (0,) and len(skeleton.children(0)) == 1
    if folded:
        offsets = skeleton.offsets.copy()
        offsets[frames.hips] = 0.0
        skeleton = skeleton.replace(offsets=offsets)
    return Served(skeleton, fps, folded)


def frames_of(skeleton: Skeleton) -> Frames:
    """The :class:`Frames` of a library skeleton (:class:`DataError` when it is no humanoid the mapper
    resolves by itself: a library's skeleton needs no rig map; its clips may)."""
    from keyfill.learn.rig_bridge import _rig

    return Frames.of(_rig(skeleton, label="the library's skeleton"))


def build(paths, out: str | os.PathLike, *, include=(), exclude=(), every: int = 1, rig_map: dict | None = None,
          fps: float | None = None, precision: str = "single", workers: int | None = 1,
          scheduler: str | None = None, progress=None) -> dict:
    """Build (or update) the library ``out`` from the clips ``paths`` (files or folders, any format).

    Args:
        paths: clip files or folders (searched recursively for files keyfill reads).
        include, exclude, every: which of them (:func:`clip_files`).
        out: the library folder; an existing library keeps its skeleton and frame rate and reuses the clips
            whose bytes it already holds.
        rig_map: role -> joint name(s) for clips of other humanoid rigs (:mod:`keyfill.characters.humanoid`).
        fps: the library's frame rate (new libraries; default: the first clip's).
        precision: ``"single"`` or ``"half"`` for rotations and features.
        workers, scheduler: where clips are read (:func:`keyfill.parallel.executor`).
        progress: a callable ``(done, total)`` or None.

    Returns a report: ``clips``, ``added``, ``reused``, ``removed``, ``skipped`` (name -> why), ``frames``.
    """
    from keyfill.parallel import executor

    if precision not in PRECISIONS:
        raise UsageError(f"precision is {' or '.join(PRECISIONS)}, not {precision!r}", params="precision")
    files = clip_files(paths, include, exclude, every)
    out = Path(out)
    old = load(out) if (out / MANIFEST).is_file() else None
    if old is None and out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise UsageError(f"{out}: exists and is not a keyfill library; refusing to replace it")
    hashes = [sha256_file(f) for f in files]
    if len(set(hashes)) < len(hashes):
        dup = next(h for h in hashes if hashes.count(h) > 1)
        same = [str(f) for f, h in zip(files, hashes) if h == dup]
        raise DataError(f"the same clip is given twice: {same[0]} and {same[1]}")
    if old is not None:
        skeleton, rate = old.skeleton, old.fps
        if fps is not None and abs(fps - rate) > 1e-9 * rate:
            raise UsageError(f"{out} is a library at {rate:g} fps; fps {fps:g} needs a new library", params="fps")
    else:
        from keyfill import io

        first = io.load(files[0])
        skeleton, rate = first.skeleton, float(fps or first.fps)
    frames = frames_of(skeleton)
    have = {c.sha256: c for c in old.clips} if old is not None else {}
    todo = [i for i, h in enumerate(hashes) if h not in have]
    results: dict[int, dict] = {}
    ex, inflight = executor(workers, scheduler)
    try:
        pending, queue, done = {}, list(todo), 0
        while queue or pending:
            while queue and len(pending) < inflight:
                i = queue.pop(0)
                pending[ex.submit(_clip_arrays, str(files[i]), skeleton.to_json(), rig_map, rate)] = i
            for fut in ex.wait(list(pending)):
                results[pending.pop(fut)] = fut.result()
                done += 1
                if progress is not None:
                    progress(done, len(todo))
    finally:
        ex.close(cancel=True)
    parts, clips, skipped, start = {k: [] for k in ARRAYS[:6]}, [], {}, 0
    for i, (f, h) in enumerate(zip(files, hashes)):
        if h in have:
            c = have[h]
            arrays = {k: np.asarray(getattr(old, k)[c.start:c.stop]) for k in parts}
        elif "skipped" in results[i]:
            skipped[f.name] = results[i]["skipped"]
            continue
        else:
            arrays = results[i]
        n = len(arrays["rotations"])
        for k, part in parts.items():
            part.append(arrays[k])
        clips.append(Clip(f.name, h, start, start + n))
        start += n
    if not clips:
        raise DataError("no clip is long enough for a library" + (f" ({next(iter(skipped.values()))})"
                                                                   if skipped else ""))
    arrays = {k: np.concatenate(v) for k, v in parts.items()}
    _save(out, skeleton, rate, frames, clips, arrays, PRECISIONS[precision])
    kept = {c.sha256 for c in clips}
    return {"library": str(out), "clips": len(clips), "frames": start, "added": len(clips) - len(
        [h for h in hashes if h in have]), "reused": len([h for h in hashes if h in have]),
        "removed": len([h for h in have if h not in kept]), "skipped": skipped}


def clip_files(paths, include=(), exclude=(), every: int = 1) -> list[Path]:
    """The motion files under ``paths`` (files, or folders searched recursively for every suffix keyfill
    reads), sorted, whose names match one of ``include`` (all when empty) and none of ``exclude`` (shell
    patterns), then every ``every``-th of them; a :class:`DataError` when a path is missing or nothing is
    left."""
    import fnmatch

    from keyfill.io import FORMATS
    from keyfill.limits import check_count

    check_count("every", every, 1 << 30)
    suffixes = {s for fmt in FORMATS.values() for s in fmt.suffixes}
    found: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found.extend(q for q in p.rglob("*") if q.suffix.lower() in suffixes and q.is_file())
        elif p.is_file():
            found.append(p)
        else:
            raise DataError(f"{p}: no such file or folder")
    if not found:
        raise DataError(f"no motion files in {', '.join(map(str, paths))}")
    kept = [f for f in sorted(set(found)) if (not include or any(fnmatch.fnmatch(f.name, p) for p in include))
            and not any(fnmatch.fnmatch(f.name, p) for p in exclude)]
    if not kept:
        raise DataError(f"no clip is left after include {list(include)} and exclude {list(exclude)}",
                        params=("include", "exclude"))
    return kept[::every]


def _save(out: Path, skeleton: Skeleton, fps: float, frames: Frames, clips: list[Clip], arrays: dict,
          dtype: str) -> None:
    """Write the library folder atomically (a new folder beside ``out``, then renamed over it)."""
    from keyfill.learn.library.index import TREE_DIMS, principal_axes, subsampled

    mean, basis = principal_axes(arrays["features"], TREE_DIMS)
    arrays = dict(arrays, mean=mean, basis=basis)
    clip_of = np.repeat(np.arange(len(clips), dtype=np.int32), [c.stop - c.start for c in clips])
    parent = out.parent if str(out.parent) else Path(".")
    if not parent.is_dir():
        raise UsageError(f"{out}: the folder {str(parent)!r} does not exist")
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=parent))
    try:
        described = {}
        for name in ARRAYS:
            a = np.ascontiguousarray(arrays[name], dtype="float32" if name in _PRECISE else dtype)
            np.save(tmp / f"{name}.npy", a, allow_pickle=False)
            described[name] = {"dtype": str(a.dtype), "shape": list(a.shape),
                               "sha256": sha256_file(tmp / f"{name}.npy")}
        manifest = {
            "format": FORMAT, "version": VERSION, "skeleton": skeleton.to_json(), "fps": fps,
            "hips": skeleton.names[frames.hips], "precision": dtype,
            "spread_m": subsampled(arrays["features"], clip_of, out.name).spread,
            "clips": [{"name": c.name, "sha256": c.sha256, "frames": c.stop - c.start} for c in clips],
            "arrays": described,
        }
        (tmp / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)
        for f in tmp.iterdir():
            os.chmod(f, 0o666 & ~umask)
        old = None
        if out.exists():
            own = {MANIFEST} | {f"{name}.npy" for name in ARRAYS}
            for f in out.iterdir():  # what else the folder holds (a licence, a card) stays in it
                if f.name not in own and not f.name.startswith("."):
                    shutil.copy2(f, tmp / f.name) if f.is_file() else shutil.copytree(f, tmp / f.name)
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=parent))
            os.replace(out, old / "library")
        os.replace(tmp, out)
        if old is not None:
            shutil.rmtree(old)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


# --- loading -------------------------------------------------------------------------------------


def _bad(path: Path, why: str) -> ModelError:
    return ModelError(f"{path}: not a usable keyfill library ({why})")


def load(path: str | os.PathLike) -> Library:
    """The library in folder ``path``, its arrays memory-mapped; a :class:`ModelError` naming what is wrong
    for a missing, foreign, truncated, tampered or wrong-typed library (nothing is unpickled)."""
    path = Path(path)
    man = path / MANIFEST
    if not path.is_dir() or not man.is_file():
        raise ModelError(f"{path}: not a keyfill library (expected a folder with {MANIFEST}; "
                         f"make one with 'keyfill library build')")
    if man.stat().st_size > MAX_MANIFEST_BYTES:
        raise _bad(path, f"{MANIFEST} is larger than {MAX_MANIFEST_BYTES} bytes")
    from keyfill.learn.modelfile import _finite, _int64, _no_constant

    try:
        m = json.loads(man.read_bytes().decode("utf-8"), parse_constant=_no_constant, parse_int=_int64,
                       parse_float=_finite)
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise _bad(path, f"{MANIFEST}: {' '.join(str(e).split())[:200]}") from None
    if not isinstance(m, dict) or m.get("format") != FORMAT:
        raise _bad(path, f"{MANIFEST} has no format {FORMAT!r}")
    if m.get("version") != VERSION:
        raise _bad(path, f"version {m.get('version')!r}; this keyfill reads {VERSION}")
    try:
        skeleton = Skeleton.from_json(m["skeleton"])
        fps = float(m["fps"])
        precision = m["precision"]
        spread_m = float(m["spread_m"])
        clips_json = m["clips"]
        described = m["arrays"]
        if precision not in PRECISIONS.values() or not (fps > 0 and np.isfinite(fps)) or not spread_m > 0:
            raise ValueError("precision, fps or spread_m out of range")
        if not isinstance(clips_json, list) or not clips_json or not isinstance(described, dict):
            raise ValueError("no clips" if not clips_json else "arrays is not an object")
        clips, start = [], 0
        for c in clips_json:
            n = c["frames"]
            if not (isinstance(n, int) and n >= MIN_CLIP_FRAMES and isinstance(c["name"], str)
                    and isinstance(c["sha256"], str) and len(c["sha256"]) == 64):
                raise ValueError(f"clip entry {str(c)[:80]}")
            clips.append(Clip(c["name"], c["sha256"], start, start + n))
            start += n
    except (KeyError, TypeError, ValueError, DataError) as e:
        raise _bad(path, f"{MANIFEST}: {e}") from None
    frames = frames_of(skeleton)
    if skeleton.names[frames.hips] != m.get("hips"):
        raise _bad(path, f"its hips joint is {m.get('hips')!r}, the skeleton's {skeleton.names[frames.hips]!r}")
    N, J = start, skeleton.num_joints
    shapes = {"rotations": (N, J, 4), "hips": (N, 3), "features": (N, J * 3), "ground": (N, 2), "heading": (N,),
              "roughness": (N,), "mean": (J * 3,), "basis": (J * 3, None)}
    loaded = {}
    for name in ARRAYS:
        spec = described.get(name)
        f = path / f"{name}.npy"
        if not isinstance(spec, dict) or not f.is_file():
            raise _bad(path, f"the array {name!r} is missing")
        want = "float32" if name in _PRECISE else precision
        try:
            a = np.load(f, mmap_mode="r", allow_pickle=False)
        except (OSError, ValueError, EOFError) as e:
            raise _bad(path, f"{f.name}: {' '.join(str(e).split())[:200]}") from None
        shape = shapes[name]
        if str(a.dtype) != want or a.ndim != len(shape) or any(s is not None and s != t
                                                               for s, t in zip(shape, a.shape)):
            raise _bad(path, f"{f.name} is {a.dtype} {tuple(a.shape)}, expected {want} "
                             f"{tuple('d' if s is None else s for s in shape)}")
        if spec.get("dtype") != str(a.dtype) or spec.get("shape") != list(a.shape):
            raise _bad(path, f"{f.name} does not agree with {MANIFEST}")
        if not isinstance(spec.get("sha256"), str) or not verified(f, spec["sha256"]):
            raise _bad(path, f"{f.name} has changed since the library was built (its SHA-256 differs)")
        loaded[name] = a
    if not 0 < loaded["basis"].shape[1] <= J * 3:
        raise _bad(path, "basis has no principal axes")
    clip_of = np.repeat(np.arange(len(clips), dtype=np.int32), [c.stop - c.start for c in clips])
    return Library(path, skeleton, fps, frames, tuple(clips), clip_of=clip_of, spread=spread_m,
                   precision="half" if precision == "float16" else "single", **loaded)
