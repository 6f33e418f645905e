"""The matched set a gan on a matched base trains on (``GanConfig.matched_set``, issue 45;
:mod:`keyfill.learn.gan.matched_base`): one ``.npz`` read without pickles, built by
``benchmarks/gan_matched_set.py`` with :func:`match_rows`.

Per training clip a few in-clip windows, laid out as
:func:`keyfill.learn.gan.sampling.window_layout` lays them, whose frames between the keys are matched (seed 0)
from a library that does not hold the clip (the search would find the clip itself). Arrays, ``N`` rows:

* ``clips (C,)`` the clip file names (no folder), ``row_clip (N,)`` each row's clip, ``row_start (N,)`` its
  first frame in the clip, ``row_length (N,)`` its frames ``L``, ``row_keys (N, K)`` its key frames from 0
  (padded with -1);
* ``quats (sum L, J, 4)`` float32 the matched in-betweens' local rotations in the model's hierarchy (signs
  continuous), ``root (sum L, 3)`` float32 their root positions (skeleton units), rows one after another.

Shapes: ``L`` frames, ``J`` joints, ``K`` keys; rotations unit quaternions ``(w, x, y, z)``.
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from keyfill.errors import DataError, UsageError

#: a matched row's rotations at its keys must be the corpus clip's within this angle (radians), its root
#: within this distance (metres): else the set was built from other clips or another hierarchy
KEY_ANGLE, KEY_METRES = 1e-3, 1e-4


def match_rows(matcher, files: list[Path], model_skeleton, folded: bool, cfg, per_clip: int, seed: int = 0,
               progress: Callable[[int, int], None] | None = None) -> dict[str, np.ndarray]:
    """The arrays of a matched set (the module docstring) for ``per_clip`` windows of each clip of ``files`` (on
    the library's skeleton and frame rate), laid out by ``cfg`` (a :class:`~keyfill.learn.gan.config.GanConfig`)
    with ``numpy.random.default_rng([seed, crc32(name), row])`` and matched by ``matcher`` (a library that holds
    none of them)."""
    from keyfill import io
    from keyfill.learn.gan.sampling import window_layout
    from keyfill.learn.windows import model_take
    from keyfill.motion import Keys

    names, rows, quats, roots = [], [], [], []
    for n, f in enumerate(files):
        motion = io.load(f).replace(keys=None)
        if abs(motion.fps - matcher.library.fps) > 1e-6:
            raise DataError(f"{f}: {motion.fps:g} fps, the library {matcher.library.fps:g}")
        name = Path(f).name
        names.append(name)
        for r in range(per_clip):
            rng = np.random.default_rng([seed, zlib.crc32(name.encode()), r])
            s, L, keys = window_layout(rng, motion.num_frames, cfg)
            filled, _ = matcher.fill(motion.frames(slice(s, s + L)), Keys(keys), seed=0)
            q, p, _ = model_take(model_skeleton, folded, filled, np.arange(L), slerped=np.arange(0), continuous=True)
            rows.append((n, s, L, keys))
            quats.append(q.astype(np.float32))
            roots.append(p[:, 0].astype(np.float32))
        if progress is not None:
            progress(n + 1, len(files))
    K = max((len(k) for *_, k in rows), default=0)
    row_keys = np.full((len(rows), K), -1, dtype=np.int64)
    for i, (*_, k) in enumerate(rows):
        row_keys[i, : len(k)] = k
    J = model_skeleton.num_joints
    return {"clips": np.array(names, dtype=str),
            "row_clip": np.array([r[0] for r in rows], dtype=np.int64),
            "row_start": np.array([r[1] for r in rows], dtype=np.int64),
            "row_length": np.array([r[2] for r in rows], dtype=np.int64),
            "row_keys": row_keys,
            "quats": np.concatenate(quats) if quats else np.zeros((0, J, 4), np.float32),
            "root": np.concatenate(roots) if roots else np.zeros((0, 3), np.float32)}


def save(arrays: dict[str, np.ndarray], path: str | os.PathLike) -> None:
    """Write a matched set (uncompressed ``.npz``)."""
    np.savez(path, **arrays)


def load_rows(path: str | os.PathLike, corpus, groups, meters_per_unit: float) -> tuple[tuple, ...]:
    """For each group of corpus clips (indices; the file is read once for all), the matched rows of its clips,
    one tuple per clip (empty where the set has none) of ``(start, key frames, quats (L, J, 4) float32, root (L, 3)
    float64 metres)``: the :attr:`~keyfill.learn.gan.poses.ClipPool.matched` of their pool (``()`` for an empty
    group). A :class:`UsageError` naming the setting ``matched_set`` when the file is no matched set of this corpus
    (its rows must start where the clip is at every key, :data:`KEY_ANGLE`, :data:`KEY_METRES`) or holds no row for
    the clips of a group."""

    from keyfill.files import read_arrays

    what = f"GAN setting 'matched_set' {path}"
    a = read_arrays(path, what, "a matched set")
    need = ("clips", "row_clip", "row_start", "row_length", "row_keys", "quats", "root")
    J = corpus.skeleton.num_joints
    if any(k not in a for k in need) or a["quats"].shape[1:] != (J, 4) or len(a["root"]) != len(a["quats"]) \
            or a["row_length"].sum() != len(a["quats"]) or a["clips"].dtype.kind != "U":
        raise UsageError(f"{what}: not a matched set of {J} joints' clips")
    offsets = np.concatenate([[0], np.cumsum(a["row_length"])])
    by_name: dict[str, list[int]] = {}
    for i, c in enumerate(a["row_clip"]):
        by_name.setdefault(str(a["clips"][c]), []).append(i)

    def rows_of(c: int) -> tuple:
        name = Path(corpus.files[c]).name
        q_clip, r_clip = corpus.clip(c)
        rows = []
        for i in by_name.get(name, ()):
            s, L = int(a["row_start"][i]), int(a["row_length"][i])
            keys = a["row_keys"][i][a["row_keys"][i] >= 0]
            q = a["quats"][offsets[i] : offsets[i] + L]
            r = a["root"][offsets[i] : offsets[i] + L].astype(np.float64)
            if s + L > len(q_clip) or keys[-1] >= L:
                raise UsageError(f"{what}: a row of {name} runs past the clip's {len(q_clip)} frames")
            d = np.abs(np.sum(q[keys] * q_clip[s + keys], axis=-1))
            angle = 2 * np.arccos(np.clip(d, 0.0, 1.0)).max()
            moved = np.abs(r[keys] - r_clip[s + keys]).max() * meters_per_unit
            if angle > KEY_ANGLE or moved > KEY_METRES:
                raise UsageError(f"{what}: a row of {name} is not the clip at its keys ({angle:.3g} rad, "
                                 f"{moved:.3g} m): built from other clips or another hierarchy")
            rows.append((s, keys, q, r * meters_per_unit))
        return tuple(rows)

    out = []
    for clips in groups:
        group = tuple(rows_of(int(c)) for c in clips)
        if len(group) and not any(group):
            raise UsageError(f"{what}: no row for these clips")
        out.append(group)
    return tuple(out)
