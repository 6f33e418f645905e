"""Nearest poses: the search tree of a library and the pose index that says how familiar a pose is.

Both work on pose features (:mod:`keyfill.learn.library.features`: joint positions in the pose's own ground
frame, meters). Distances between poses are root-mean-square joint distances (the Euclidean distance of the
features divided by ``sqrt(J)``), in meters.

* :func:`principal_axes` and :class:`Tree`: scipy's ``cKDTree`` over the features projected on their first
  principal axes (16 of 66 for a 22-joint body keep about 99 % of the variance), for the library search's
  candidates; each candidate's full cost is computed afterwards from the full features.
* :func:`spread`: a library's own density, the median distance from a sample of its poses to the nearest
  pose of *another* clip. A pose is unfamiliar when it lies many spreads from every known pose.
* :class:`PoseIndex`: the poses a model or library knows (a model folder's ``pose_index.npz``, or a
  library's features), with :meth:`PoseIndex.familiarity`: distance to the nearest known pose in spreads.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill.errors import ModelError

#: poses sampled for :func:`spread`
SPREAD_SAMPLE = 2000
#: the file of a model folder's pose index, and its arrays
POSE_INDEX = "pose_index.npz"
_INDEX_FIELDS = ("features", "spread", "threshold", "mean", "basis")
#: a gap whose largest distance to the known poses exceeds this many spreads is unfamiliar (the guard's,
#: :mod:`keyfill.learn.library.guard`; calibrated in docs/match.md)
THRESHOLD = 12.0
#: principal axes of a tree (16 of 66 for a 22-joint body keep about 99 % of the variance)
TREE_DIMS = 16
#: nearest poses on the principal axes among which :meth:`PoseIndex.familiarity` takes the nearest in full
CANDIDATES = 16
#: at most this many poses in a pose index (evenly spaced frames of its corpus or library)
MAX_INDEX_POSES = 30_000
#: rows a pose index's principal axes are computed on (a library's: 50,000): a tenth of the SVD's time at
#: start-up, for candidates that differ only where the nearest pose was a near tie anyway
INDEX_AXES_ROWS = 5_000
#: :meth:`Tree.query` compares every query with every point (numpy, no scipy import, no tree to build) until
#: it has compared this many query-point pairs in all; then it builds scipy's tree once (the same neighbours)
BRUTE_FORCE_PAIRS = 2_000_000


def principal_axes(features: np.ndarray, dims: int, rows: int = 50_000) -> tuple[np.ndarray, np.ndarray]:
    """``(mean (D,), basis (D, d))`` of ``features (N, D)``: the first ``d = min(dims, D)`` principal axes
    (computed on at most about ``rows`` evenly spaced rows)."""
    x = np.asarray(features[:: max(1, len(features) // rows)], dtype=np.float64)
    mean = x.mean(axis=0)
    _, _, vt = np.linalg.svd(x - mean, full_matrices=False)
    return mean.astype(np.float32), np.ascontiguousarray(vt[: min(dims, x.shape[1])].T, dtype=np.float32)


def spread(features: np.ndarray, clip_of: np.ndarray, sample: int = SPREAD_SAMPLE) -> float:
    """The median RMS joint distance (m) from ``sample`` evenly spaced poses of ``features (N, D)`` to the
    nearest pose of another clip (``clip_of (N,)``); with one clip, to the nearest pose at least one second
    (30 frames) away."""
    from scipy.spatial import cKDTree

    f = np.asarray(features, dtype=np.float32)
    J = f.shape[1] // 3
    pick = np.unique(np.linspace(0, len(f) - 1, min(sample, len(f))).round().astype(np.int64))
    tree = cKDTree(f)
    k = min(len(f), 64)
    dist, idx = tree.query(f[pick], k=k)
    dist, idx = dist.reshape(len(pick), k), idx.reshape(len(pick), k)
    one_clip = len(np.unique(clip_of)) == 1
    other = (np.abs(idx - pick[:, None]) >= 30) if one_clip else (clip_of[idx] != clip_of[pick][:, None])
    best = np.where(other, dist, np.inf).min(axis=1)
    best = best[np.isfinite(best)]
    if len(best) == 0:  # every sampled pose's 64 nearest are its own clip's: a sparse library
        best = dist[:, -1]
    return float(max(np.median(best) / np.sqrt(J), 1e-4))


class Tree:
    """Features projected on principal axes (``mean``, ``basis``); :meth:`query` gives the ``k`` nearest rows
    of the projected features for each of ``queries (Q, D)``: by comparing with every row for a few queries
    (a short clip's, at start-up), else through a ``cKDTree`` built on first need."""

    def __init__(self, features: np.ndarray, mean: np.ndarray, basis: np.ndarray):
        self.mean, self.basis = np.asarray(mean, np.float32), np.asarray(basis, np.float32)
        self.points = self.project(features)
        self.tree = None
        self.compared = 0  # query-point pairs compared by brute force so far

    def _kd_tree(self):
        if self.tree is None:
            from scipy.spatial import cKDTree

            self.tree = cKDTree(self.points, balanced_tree=False)  # median splits: 10x slower to build, no faster
        return self.tree

    def project(self, features: np.ndarray) -> np.ndarray:
        """``(Q, d)`` float32 coordinates of ``features (Q, D)`` on the principal axes (in chunks)."""
        out = np.empty((len(features), self.basis.shape[1]), dtype=np.float32)
        for a in range(0, len(features), 65_536):
            chunk = np.asarray(features[a: a + 65_536], dtype=np.float32)
            out[a: a + 65_536] = (chunk - self.mean) @ self.basis
        return out

    def query(self, queries: np.ndarray, k: int) -> np.ndarray:
        """``(Q, k')`` int64 rows nearest to each query, nearest first (``k' = min(k, N)``)."""
        k = min(k, len(self.points))
        q = self.project(queries)
        self.compared += len(q) * len(self.points)
        if self.tree is not None or self.compared > BRUTE_FORCE_PAIRS:
            _, idx = self._kd_tree().query(q, k=k)
            return np.asarray(idx, dtype=np.int64).reshape(len(queries), k)
        points = self.points.astype(np.float64)
        d2 = (np.square(q.astype(np.float64)).sum(1)[:, None] - 2 * q.astype(np.float64) @ points.T
              + np.square(points).sum(1)[None, :])  # (Q, N) squared distances
        near = np.argpartition(d2, k - 1, axis=1)[:, :k] if k < len(self.points) else np.tile(np.arange(k), (len(q), 1))
        order = np.argsort(np.take_along_axis(d2, near, axis=1), axis=1, kind="stable")
        return np.take_along_axis(near, order, axis=1).astype(np.int64)


@dataclass(frozen=True, eq=False)
class PoseIndex:
    """Poses a model or library knows: ``features (M, D)`` (meters), the corpus's ``spread`` (m) and the
    ``threshold`` (in spreads) beyond which a pose is unfamiliar; ``name`` says whose poses they are."""

    features: np.ndarray
    spread: float
    threshold: float
    name: str
    #: the tree's ``(mean (D,), basis (D, d))`` as :meth:`axes` computes them, when a file holds them
    stored_axes: tuple[np.ndarray, np.ndarray] | None = None

    def axes(self) -> tuple[np.ndarray, np.ndarray]:
        """The principal axes of :attr:`features` the candidates are searched on (:func:`principal_axes` on
        :data:`INDEX_AXES_ROWS` rows; a model folder's file keeps them, saving the SVD at start-up)."""
        if self.stored_axes is not None:
            return self.stored_axes
        return principal_axes(self.features, TREE_DIMS, rows=INDEX_AXES_ROWS)

    def _tree(self) -> Tree:
        tree = self.__dict__.get("_cached_tree")
        if tree is None:
            tree = Tree(self.features, *self.axes())
            object.__setattr__(self, "_cached_tree", tree)
        return tree

    def familiarity(self, features: np.ndarray) -> np.ndarray:
        """``(Q,)`` distance of each of ``features (Q, D)`` to the nearest known pose, in spreads (RMS joint
        distance over :attr:`spread`): about 1 for a pose like the corpus's own, large for one it lacks.

        The nearest pose is searched among the :data:`CANDIDATES` nearest on the principal axes (the tree's),
        by the full distance: a pose far from every known one stays far; a familiar one may score a little
        high when its true nearest pose is not among them."""
        q = np.asarray(features, dtype=np.float32)
        J = self.features.shape[1] // 3
        near = self._tree().query(q, CANDIDATES)  # (Q, k)
        d2 = ((self.features[near] - q[:, None, :]) ** 2).sum(-1)
        return np.sqrt(d2.min(axis=1).astype(np.float64)) / np.sqrt(J) / self.spread

    def save(self, folder: str | os.PathLike) -> Path:
        """Write ``pose_index.npz`` into a model folder: float16 features and the float32 axes the loader's
        features give (:meth:`axes`), uncompressed (read in 2 ms at every start-up, not 18), no pickles."""
        path = Path(folder) / POSE_INDEX
        half = np.asarray(self.features, dtype=np.float16)
        mean, basis = PoseIndex(half.astype(np.float32), self.spread, self.threshold, self.name).axes()
        np.savez(path, features=half, spread=np.float64(self.spread), threshold=np.float64(self.threshold),
                 mean=mean, basis=basis)
        return path


def load_pose_index(folder: str | os.PathLike, name: str) -> PoseIndex | None:
    """The pose index of the model folder ``folder`` (None when it has none); a :class:`ModelError` when the
    file is damaged or not of the expected fields, shapes and types (read without pickles)."""
    path = Path(folder) / POSE_INDEX
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            if set(z.files) not in ({"features", "spread", "threshold"}, set(_INDEX_FIELDS)):
                raise ValueError(f"fields {sorted(z.files)}")
            feats, spread_m, threshold = z["features"], float(z["spread"]), float(z["threshold"])
            axes = (z["mean"], z["basis"]) if "mean" in z.files else None  # files before 2026-12-03 lack them
    except (OSError, ValueError, EOFError, KeyError) as e:
        raise ModelError(f"{path}: damaged pose index ({' '.join(str(e).split())[:200]})") from None
    if feats.dtype != np.float16 or feats.ndim != 2 or feats.shape[1] % 3 or not len(feats):
        raise ModelError(f"{path}: damaged pose index (features {feats.dtype} {feats.shape})")
    if not (np.isfinite(spread_m) and spread_m > 0 and np.isfinite(threshold) and threshold > 0):
        raise ModelError(f"{path}: damaged pose index (spread {spread_m}, threshold {threshold})")
    feats = feats.astype(np.float32)  # checked as float32: numpy's float16 arithmetic is 8x slower
    if not np.isfinite(feats).all():
        raise ModelError(f"{path}: damaged pose index (features that are not finite)")
    D = feats.shape[1]
    if axes is not None and not (axes[0].dtype == axes[1].dtype == np.float32 and axes[0].shape == (D,)
                                 and axes[1].shape == (D, min(TREE_DIMS, D)) and np.isfinite(axes[1]).all()
                                 and np.isfinite(axes[0]).all()):
        raise ModelError(f"{path}: damaged pose index (axes {axes[0].dtype} {axes[0].shape}, "
                         f"{axes[1].dtype} {axes[1].shape})")
    return PoseIndex(feats, spread_m, threshold, name, axes)


def library_index(library) -> PoseIndex:
    """The pose index of a loaded library (:mod:`keyfill.learn.library.store`): the poses :func:`subsampled`
    keeps, with the spread the build measured among them; built once per library and process."""
    cached = library.__dict__.get("_pose_index")
    if cached is None:
        cached = PoseIndex(np.asarray(library.features[::index_step(library.num_frames)], dtype=np.float32),
                           library.spread, THRESHOLD, library.name)
        object.__setattr__(library, "_pose_index", cached)
    return cached


def index_step(frames: int) -> int:
    """Every how many frames a pose index of ``frames`` frames keeps one (at most :data:`MAX_INDEX_POSES`)."""
    return max(1, int(np.ceil(frames / MAX_INDEX_POSES)))


def subsampled(features: np.ndarray, clip_of: np.ndarray, name: str) -> PoseIndex:
    """The pose index of ``features (N, D)`` of clips ``clip_of (N,)``: evenly spaced frames, at most
    :data:`MAX_INDEX_POSES`, their spread measured among themselves (so that an index of every 10th frame and
    one of every frame score a pose alike), the guard's threshold."""
    step = index_step(len(features))
    feats = np.asarray(features[::step], dtype=np.float32)
    clips = np.asarray(clip_of[::step])
    return PoseIndex(feats, spread(feats, clips), THRESHOLD, name)
