"""Folders of BVH files as arrays for training and benchmarks.

A :class:`Corpus` holds every clip of a folder (or list of files) as two
concatenated arrays, the representation the LaFAN1 protocol and the learned
models use:

* ``quats (N, J, 4)``: local unit quaternions of all ``N`` frames of all clips,
  with quaternion signs made continuous along each clip;
* ``root (N, 3)``: the root joint's position (file units);

plus ``starts (C + 1,)`` clip boundaries and one :class:`~keyfill.motion.Skeleton`
whose ``offsets`` are the constant bone offsets (the local positions of joints
1.. on the first frame of the first clip, as the reference benchmark takes them).
Other joints' translations are assumed constant, which is what every skeleton
of a mocap corpus does; files whose bones differ are refused.

Folding the root: Bandai-Namco files carry a static top joint ``joint_Root``
above ``Hips``. With ``fold_root`` the top joint takes the hips' global
rotation and position and the hips get the identity and a zero offset, so the
animated root of the corpus is the real pelvis (the protocol's facing direction
and XZ centring need that). ``fold_root=None`` folds when the top joint is
static with a single child.

Loading 2,500 Bandai clips takes about 20 s; the arrays are cached under
:func:`keyfill.files.cache_dir` (``KEYFILL_CACHE``, else ``~/.cache/keyfill``; keyed by the
files' paths, sizes and modification times; about 240 MB for dataset-2), so
later loads take about a second. Writing an entry is told as a
:func:`keyfill.progress.note`.

Corpora from ``../shared/data/corpora`` are found (and unpacked once into the
checkout's git-ignored ``data/`` folder, see :func:`data_dir`) by :func:`locate`.
"""

from __future__ import annotations

import dataclasses
import fnmatch
import hashlib
import json
import os
import shutil
import tarfile
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill import rotations as R
from keyfill.errors import DataError, ModelError
from keyfill.files import cache_dir
from keyfill.learn.mirror import Mirror, find_mirror, mirror_pairs  # noqa: F401 (their old home: still importable here)
from keyfill.motion import Motion, Skeleton
from keyfill.progress import note

CACHE_VERSION = 1
CACHE_AFTER_S = 1.0  #: only corpora that take longer than this to read are cached

#: known corpora: name -> (archive in ../shared/data/corpora, folder under data/, BVH folder inside it)
CORPORA = {
    "bandai1": (
        "bandai_namco_motiondataset1.tar.xz",
        "bandai1",
        "Bandai-Namco-Research-Motiondataset-1/data",
    ),
    "bandai2": (
        "bandai_namco_motiondataset2_no_youthful.tar.xz",
        "bandai2",
        "bandai_namco_motiondataset2/data",
    ),
}


# --- where data lives ------------------------------------------------------------


def checkout() -> Path | None:
    """The source checkout that holds the ``keyfill`` package, or None when keyfill is installed as a wheel."""
    root = Path(__file__).resolve().parents[2]
    return root if (root / "pyproject.toml").is_file() and (root / "keyfill").is_dir() else None


def shared_data_dir() -> Path:
    """``../shared/data`` beside the checkout (``KEYFILL_SHARED_DATA`` overrides it; needed for a wheel install)."""
    if "KEYFILL_SHARED_DATA" in os.environ:
        return Path(os.environ["KEYFILL_SHARED_DATA"])
    root = checkout()
    return root.parent / "shared" / "data" if root is not None else Path("shared") / "data"


def data_dir() -> Path:
    """Where corpora are unpacked: ``KEYFILL_DATA``, else the checkout's git-ignored ``data/``, else the user's
    data folder (``platformdirs``, e.g. ``~/.local/share/keyfill``) for a wheel install."""
    if "KEYFILL_DATA" in os.environ:
        return Path(os.environ["KEYFILL_DATA"])
    root = checkout()
    if root is not None:
        return root / "data"
    import platformdirs

    return Path(platformdirs.user_data_dir("keyfill"))


def locate(name: str) -> Path:
    """The folder of BVH files of corpus ``name`` (``"bandai1"`` or ``"bandai2"``).

    Uses the unpacked copy under :func:`data_dir` or unpacks the archive from
    ``../shared/data/corpora`` there (once, atomically). Raises a
    :class:`DataError` that says what is missing when neither exists.
    """
    if name not in CORPORA:
        raise DataError(f"unknown corpus {name!r}; known corpora: {', '.join(CORPORA)}")
    archive, folder, inner = CORPORA[name]
    target = data_dir() / folder
    bvh_dir = target / inner
    if bvh_dir.is_dir():
        return bvh_dir
    src = shared_data_dir() / "corpora" / archive
    if not src.is_file():
        raise DataError(f"corpus {name!r} is not unpacked in {target} and its archive {src} does not exist")
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=target.parent, prefix=f".{folder}."))
    try:
        with tarfile.open(src) as tar:
            tar.extractall(tmp, filter="data")
        os.replace(tmp, target)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if not bvh_dir.is_dir():
        raise DataError(f"{src} does not contain {inner}")
    return bvh_dir


def bvh_files(paths: Iterable[str | os.PathLike], pattern: str | None = None) -> list[Path]:
    """The BVH files named by ``paths`` (files, or folders searched recursively), sorted.

    ``pattern`` (a shell pattern such as ``"*_normal_*"``) keeps the files whose
    name matches. Raises a :class:`DataError` when nothing is left.
    """
    found: list[Path] = []
    paths = [Path(p) for p in paths]
    for p in paths:
        if p.is_dir():
            found.extend(q for q in p.rglob("*") if q.suffix.lower() == ".bvh" and q.is_file())
        elif p.is_file():
            found.append(p)
        else:
            raise DataError(f"{p}: no such file or folder")
    files = sorted(set(found))
    where = ", ".join(str(p) for p in paths)
    if not files:
        raise DataError(f"no BVH files in {where}")
    if pattern is not None:
        files = [f for f in files if fnmatch.fnmatch(f.name, pattern)]
        if not files:
            raise DataError(f"no BVH file in {where} matches {pattern!r}")
    return files


# --- clips as arrays ---------------------------------------------------------------


def top_joint_is_static(motion: Motion) -> bool:
    """True when joint 0 has one child and neither rotates nor moves over the clip."""
    if motion.num_joints < 2 or len(motion.skeleton.children(0)) != 1:
        return False
    r, p = motion.rotations[:, 0], motion.positions[:, 0]
    return bool(np.allclose(r, r[:1], atol=1e-9) and np.allclose(p, p[:1], atol=1e-9))


def fold_root(quats: np.ndarray, positions: np.ndarray, parents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fold joint 0 into its only child: joint 0 takes the child's global transform.

    ``quats (F, J, 4)``, ``positions (F, J, 3)`` local; returns new arrays in which
    the child has the identity rotation and a zero translation, so every joint's
    global transform is unchanged.
    """
    children = np.flatnonzero(np.asarray(parents) == 0)
    if len(children) != 1:
        raise DataError(f"cannot fold the top joint into its child: it has {len(children)} children")
    c = int(children[0])
    q, p = quats.copy(), positions.copy()
    q[:, 0] = R.quat_mul(quats[:, 0], quats[:, c])
    p[:, 0] = positions[:, 0] + R.quat_rotate(quats[:, 0], positions[:, c])
    q[:, c] = (1.0, 0.0, 0.0, 0.0)
    p[:, c] = 0.0
    return q, p


@dataclass(frozen=True, eq=False)
class Corpus:
    """Clips of one skeleton as concatenated arrays (see the module docstring).

    Attributes:
        skeleton: the shared skeleton; ``offsets`` are the constant bone offsets.
        files: ``C`` clip file names (as given).
        quats: ``(N, J, 4)`` local quaternions, continuous along each clip.
        root: ``(N, 3)`` root positions.
        starts: ``(C + 1,)`` int, clip ``i`` is frames ``starts[i]:starts[i + 1]``.
        fps: frames per second.
        folded: whether the top joint was folded into its child.
    """

    skeleton: Skeleton
    files: tuple[str, ...]
    quats: np.ndarray
    root: np.ndarray
    starts: np.ndarray
    fps: float
    folded: bool

    def __len__(self) -> int:
        return len(self.files)

    @property
    def lengths(self) -> np.ndarray:
        return np.diff(self.starts)

    def clip(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """``(quats (F, J, 4), root (F, 3))`` of clip ``i``."""
        a, b = self.starts[i], self.starts[i + 1]
        return self.quats[a:b], self.root[a:b]

    def subset(self, keep: Sequence[int] | np.ndarray) -> Corpus:
        """The corpus of the clips with indices ``keep`` (in that order)."""
        keep = [int(i) for i in keep]
        parts_q = [self.clip(i)[0] for i in keep]
        parts_r = [self.clip(i)[1] for i in keep]
        starts = np.concatenate([[0], np.cumsum([len(q) for q in parts_q])]).astype(np.int64)
        J = self.skeleton.num_joints
        return dataclasses.replace(
            self,
            files=tuple(self.files[i] for i in keep),
            quats=np.concatenate(parts_q) if parts_q else np.zeros((0, J, 4)),
            root=np.concatenate(parts_r) if parts_r else np.zeros((0, 3)),
            starts=starts,
        )

    def matching(self, pattern: str | None, invert: bool = False) -> Corpus:
        """The clips whose file name matches (or, with ``invert``, does not match) ``pattern``."""
        if pattern is None:
            return self
        hit = [fnmatch.fnmatch(Path(f).name, pattern) != invert for f in self.files]
        return self.subset(np.flatnonzero(hit))

    def select(self, include: Sequence[str] = (), exclude: Sequence[str] = ()) -> Corpus:
        """The clips whose file name matches one of ``include`` (all when empty) and none of ``exclude``."""
        names = [Path(f).name for f in self.files]
        keep = [i for i, n in enumerate(names) if (not include or any(fnmatch.fnmatch(n, p) for p in include))
                and not any(fnmatch.fnmatch(n, p) for p in exclude)]
        if not keep:
            raise DataError(f"no clip is left after include {list(include)} and exclude {list(exclude)}",
                            params=("include", "exclude"))
        return self.subset(keep) if len(keep) < len(names) else self

    def windows(self, length: int, offset: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Sliding windows as the reference benchmark cuts them.

        Window starts are ``0, offset, 2 * offset, ...`` while ``start + length``
        is *less than* the clip length (so a clip needs at least ``length + 1``
        frames).

        Returns:
            ``(quats (W, length, J, 4), root (W, length, 3), clip index (W,), skipped)``
            where ``skipped`` counts clips too short for a single window.
        """
        frames, clip_of, skipped = self.window_frames(length, offset)
        J = self.skeleton.num_joints
        if len(frames) == 0:
            return np.zeros((0, length, J, 4)), np.zeros((0, length, 3)), clip_of, skipped
        return self.quats[frames], self.root[frames], clip_of, skipped

    def window_frames(self, length: int, offset: int) -> tuple[np.ndarray, np.ndarray, int]:
        """The frames of :meth:`windows`: ``(frames (W, length) int64 indices into quats / root, clip index
        (W,), skipped)``, to cut per-frame arrays of the corpus (contact labels) as the windows are cut."""
        idx, clip_of, skipped = [], [], 0
        for c in range(len(self)):
            a, n = int(self.starts[c]), int(self.starts[c + 1] - self.starts[c])
            s = np.arange(0, max(n - length, 0), offset)
            if len(s) == 0:
                skipped += 1
            idx.extend(a + s)
            clip_of.extend([c] * len(s))
        frames = np.asarray(idx, dtype=np.int64).reshape(-1, 1) + np.arange(length)
        return frames, np.asarray(clip_of, dtype=np.int64), skipped


def load_corpus(
    paths: Iterable[str | os.PathLike],
    pattern: str | None = None,
    fold: bool | None = None,
    cache: bool = True,
    progress=None,
) -> Corpus:
    """Read every BVH file under ``paths`` into a :class:`Corpus`.

    Args:
        paths: files or folders (searched recursively for ``*.bvh``).
        pattern: keep only files whose name matches this shell pattern.
        fold: fold the top joint into its child (``None``: when it is static).
        cache: read the preprocessed arrays from :func:`keyfill.files.cache_dir`, and write
            them there when reading the files took more than a second.
        progress: optional wrapper for the file iterator (e.g. a tqdm bar).

    Raises:
        DataError: no BVH files; files of different skeletons (naming the first
        difference) or frame rates.
    """
    files = bvh_files(paths, pattern)
    key = _cache_key(files, fold)
    cached = cache_dir() / f"corpus-{key}.npz"
    if cache and cached.is_file():
        try:
            return _read_cache(cached)
        except (OSError, ValueError, KeyError):
            pass  # a damaged cache entry is rebuilt below
    t0 = time.perf_counter()
    corpus = _load(files, fold, progress)
    if cache and time.perf_counter() - t0 > CACHE_AFTER_S:
        _write_cache(corpus, cached)
    return corpus


def _load(files: list[Path], fold: bool | None, progress) -> Corpus:
    from keyfill import io

    ref: Skeleton | None = None
    ref_file = None
    fps = None
    qs, roots = [], []
    iterator = progress(files) if progress is not None else files
    for f in iterator:
        m = io.load(f)
        if ref_file is None:
            ref_file, fps = f, m.fps
            if fold is None:
                fold = top_joint_is_static(m)
        if m.fps != fps:
            raise DataError(f"{f}: {m.fps:g} fps, but {ref_file} has {fps:g} fps; a corpus needs one frame rate")
        q, p = m.rotations, m.positions
        if fold:
            try:
                q, p = fold_root(q, p, m.skeleton.parents)
            except DataError as e:
                raise DataError(f"{f}: {e}") from None
        skel = m.skeleton.replace(offsets=p[0])
        if ref is None:
            ref = skel
        else:
            diff = bone_difference(ref, skel)
            if diff is not None:
                hint = " (try folding the top joint into the hips)" if not fold and "offset" in diff else ""
                raise DataError(f"{f}: another skeleton than {ref_file}: {diff}{hint}")
        qs.append(R.quat_continuous_np(q, axis=0))
        roots.append(p[:, 0])
    offsets = ref.offsets.copy()
    offsets[0] = 0.0
    starts = np.concatenate([[0], np.cumsum([len(q) for q in qs])]).astype(np.int64)
    return Corpus(
        skeleton=ref.replace(offsets=offsets),
        files=tuple(str(f) for f in files),
        quats=np.concatenate(qs),
        root=np.concatenate(roots),
        starts=starts,
        fps=float(fps),
        folded=bool(fold),
    )


def bone_difference(a: Skeleton, b: Skeleton) -> str | None:
    """The first difference of joints, parents or bone offsets (joints 1..; 1% of the longest bone).

    Exports of one mocap skeleton differ by fractions of a millimetre; another
    skeleton differs by centimetres.
    """
    scale = max(float(np.abs(a.offsets[1:]).max(initial=0.0)), 1e-12)
    aa = a.replace(offsets=np.vstack([np.zeros(3), a.offsets[1:]]))
    bb = b.replace(offsets=np.vstack([np.zeros(3), b.offsets[1:]]))
    return aa.difference(bb, atol=1e-2 * scale)


def model_hierarchy(model_skeleton: Skeleton, folded: bool, skeleton: Skeleton, quats: np.ndarray,
                    positions: np.ndarray, frame: int = 0, what: str = "the motion",
                    hint: str = "") -> tuple[np.ndarray, np.ndarray]:
    """A motion's ``(quats (F, J, 4), positions (F, J, 3))`` in the hierarchy of a model's corpus, checked.

    When the model's corpus folded a static top joint into the hips (``folded``),
    the motion's top joint is folded too (:func:`fold_root`). The motion's bone
    offsets at ``frame`` must then match ``model_skeleton`` (:func:`bone_difference`).

    Raises:
        ModelError: ``"{what} has another skeleton than the model (...): the model's vs {what}'s: {first
        difference}{hint}"`` (the difference names the model's side first); ``hint`` (e.g. the command that trains
        a model for the user's clips) ends the line.
    """
    def mismatch(diff):
        return ModelError(f"{what} has another skeleton than the model ({model_skeleton.num_joints} joints, "
                          f"top joint {model_skeleton.names[0]!r}): the model's vs {what}'s: {diff}{hint}")

    if folded:
        if len(skeleton.children(0)) != 1:
            raise mismatch(bone_difference(model_skeleton, skeleton)
                           or f"{skeleton.names[0]!r} has {len(skeleton.children(0))} children, the model's one")
        quats, positions = fold_root(quats, positions, skeleton.parents)
    diff = bone_difference(model_skeleton, skeleton.replace(offsets=np.vstack([np.zeros(3), positions[frame, 1:]])))
    if diff is not None:
        raise mismatch(diff)
    return quats, positions


def _cache_key(files: list[Path], fold: bool | None) -> str:
    h = hashlib.sha1()
    h.update(json.dumps({"v": CACHE_VERSION, "fold": fold}).encode())
    for f in files:
        st = f.stat()
        h.update(f"{f.resolve()}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return h.hexdigest()[:20]


def _write_cache(corpus: Corpus, path: Path) -> None:
    from keyfill.files import atomic_output

    s = corpus.skeleton
    meta = {
        "names": list(s.names),
        "channels": [list(c) for c in s.channels],
        "end_sites": [[j, o.tolist()] for j, o in s.end_sites],
        "meters_per_unit": s.meters_per_unit,
        "up_axis": s.up_axis,
        "files": list(corpus.files),
        "fps": corpus.fps,
        "folded": corpus.folded,
    }
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, quats=corpus.quats, root=corpus.root, starts=corpus.starts, parents=s.parents,
                     offsets=s.offsets, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
    except OSError:
        return  # caching is an optimisation; a read-only checkout still works
    note(f"cached the clips' arrays in {path} ({path.stat().st_size / 2**20:.0f} MiB; later reads take about a "
         f"second; KEYFILL_CACHE chooses the folder, deleting it is safe)")


def _read_cache(path: Path) -> Corpus:
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(z["meta"].tobytes().decode())
        skel = Skeleton(
            names=meta["names"], parents=z["parents"], offsets=z["offsets"],
            channels=[tuple(c) for c in meta["channels"]],
            end_sites=[(j, np.asarray(o)) for j, o in meta["end_sites"]],
            meters_per_unit=meta["meters_per_unit"], up_axis=meta["up_axis"],
        )
        return Corpus(skel, tuple(meta["files"]), z["quats"], z["root"], z["starts"], meta["fps"], meta["folded"])

