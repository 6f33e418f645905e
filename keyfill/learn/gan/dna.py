"""Motion DNA data (numpy): the bank of representative poses, how many poses a sequence gets (Appendix D), a model's DNA.

A Motion DNA is a set of representative poses (:mod:`keyfill.learn.representative`:
root-free, in metres here), which the generator's DNA encoder turns into the
style vector joined to every latent step (section 3.5.1).

* :class:`DnaBank`: the representative poses of a set of clips, one per second of
  each clip (at least one), and the clip each came from. Training draws from the
  bank of its training clips; a model folder keeps that bank, so ``complete``
  without a DNA file draws its poses from it by the seed.
* :func:`key_dna`: the default DNA of a model trained with its windows' own DNA
  (``GanConfig.dna_source`` ``"own"``): the keys' own poses, since a DNA drawn
  from another clip would steer the in-betweens towards that clip's motion.
* :func:`dna_count`: Appendix D's number of poses for a key layout: one per 3 s
  of each gap between keys (``floor(gap / 3 s)`` summed; at least one).
* :func:`draw_dna`: ``count`` poses of one random clip of a bank (the stand-in
  for the paper's "motion class": a clip is one kind of motion), or of a given
  clip (an in-clip window's own, ``GanConfig.dna_source`` ``"own"``); drawn
  without repetition while the clip has enough, with repetition beyond.
* :func:`dna_poses`: the DNA ``complete`` gives a model: from a motion file, the
  bank or the keys; one for the whole take, however many windows fill it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.errors import DataError, UsageError
from keyfill.learn.gan.long_takes import windows
from keyfill.learn.representative import pick_frames, root_free_poses, rotation_change
from keyfill.limits import check_count


@dataclass(frozen=True, eq=False)
class DnaBank:
    """Representative poses of clips.

    Attributes:
        poses: ``(P, J - 1, 3)`` float32, root-free, metres.
        clips: ``(P,)`` int64, the clip (an index into the clips the bank was built from) of each pose.
    """

    poses: np.ndarray
    clips: np.ndarray

    def __len__(self) -> int:
        return len(self.poses)


def build_bank(corpus, clips, per_second: float = 1.0) -> DnaBank:
    """The :class:`DnaBank` of ``clips`` (indices) of a :class:`~keyfill.learn.corpus.Corpus`.

    Each clip of ``F`` frames gives its ``max(1, round(per_second * F / fps))``
    representative frames.
    """
    s = corpus.skeleton
    off = s.offsets * s.meters_per_unit
    poses, owner = [], []
    for n, i in enumerate(int(c) for c in clips):
        q = corpus.clip(i)[0]
        frames = pick_frames(rotation_change(q), max(1, round(per_second * len(q) / corpus.fps)))
        poses.append(root_free_poses(q[frames], off, s.parents).astype(np.float32))
        owner.append(np.full(len(frames), n, dtype=np.int64))
    if not poses:
        return DnaBank(np.zeros((0, s.num_joints - 1, 3), np.float32), np.zeros(0, np.int64))
    return DnaBank(np.concatenate(poses), np.concatenate(owner))


def dna_count(key_frames, fps: float, seconds: float = 3.0) -> int:
    """Appendix D: one representative pose per ``seconds`` of every gap between the ``key_frames``, at least one."""
    gaps = np.diff(np.asarray(key_frames, dtype=np.int64))
    return max(1, int(np.sum(gaps // max(round(seconds * fps), 1))))


def key_dna(key_quats: np.ndarray, offsets: np.ndarray, parents, count: int) -> np.ndarray:
    """``([B,] P, J - 1, 3)`` float32: root-free poses of keys ``key_quats ([B,] K, J, 4)`` (local rotations; ``offsets``
    in metres), the ``P = min(count, K)`` most representative of them (:func:`~keyfill.learn.representative.pick_frames`
    over the keys in order), per window when batched."""
    q = np.asarray(key_quats, dtype=np.float64)
    if q.ndim == 4:
        return np.stack([key_dna(w, offsets, parents, count) for w in q])
    picked = pick_frames(rotation_change(q), count)
    return root_free_poses(q[picked], offsets, parents).astype(np.float32)


def draw_dna(bank: DnaBank, rng: np.random.Generator, count: int, clip: int | None = None) -> np.ndarray:
    """``(count, J - 1, 3)`` poses of one random clip of ``bank``, or of clip ``clip`` (see the module docstring)."""
    if len(bank) == 0:
        raise DataError("the Motion DNA bank holds no poses")
    if clip is None:
        owners = np.unique(bank.clips)
        clip = owners[int(rng.integers(len(owners)))]
    rows = np.flatnonzero(bank.clips == clip)
    if len(rows) == 0:
        raise DataError(f"the Motion DNA bank holds no pose of clip {clip}")
    pick = rng.choice(rows, size=count, replace=len(rows) < count)
    return bank.poses[pick]


def pad_dna(sets) -> tuple[np.ndarray, np.ndarray]:
    """``(poses (B, P, J - 1, 3) float32, valid (B, P) bool)``: sets of poses of different sizes, padded with zeros."""
    P = max(len(s) for s in sets)
    shape = sets[0].shape[1:]
    poses = np.zeros((len(sets), P, *shape), np.float32)
    valid = np.zeros((len(sets), P), bool)
    for b, s in enumerate(sets):
        poses[b, : len(s)] = s
        valid[b, : len(s)] = True
    return poses, valid


def dna_poses(model, source=None, frames=None, count: int | None = None, key_frames=None,
              seed: int = 0, key_quats=None) -> np.ndarray:
    """The Motion DNA for :func:`keyfill.learn.gan.model.generate`: ``(P, J - 1, 3)`` root-free poses in metres.

    ``model`` is a :class:`~keyfill.learn.gan.model.GanModel` with Motion DNA.

    Args:
        source: a :class:`~keyfill.motion.Motion` of the model's skeleton to take the poses from,
            or None for the model's bank of its training clips' representative poses.
        frames: the frames of ``source`` to use (None: its ``count`` representative frames).
        count: how many poses (None: Appendix D's count for ``key_frames``, one per 3 s of gap; for a key
            range of several windows, :func:`~keyfill.learn.gan.long_takes.windows`, the largest count of a window's keys).
        key_frames: the keys, for the default count.
        seed: the draw from the bank (``numpy.random.default_rng(seed)``).
        key_quats: ``([B,] K, J, 4)`` the keys' rotations in the model's hierarchy: without a ``source``, a
            model trained on its windows' own DNA (``dna_source`` ``"own"``) takes its DNA from them
            (:func:`~keyfill.learn.gan.dna.key_dna`) instead of the bank.
    """
    from keyfill.learn.corpus import model_hierarchy

    cfg = model.config
    if not cfg.dna:
        raise UsageError("this gan model has no Motion DNA encoder (it was trained without --dna)")
    if count is None:
        count = 1 if key_frames is None else max(dna_count(key_frames[i : j + 1], model.fps, cfg.dna_seconds)
                                                 for i, j in windows(key_frames, cfg.max_frames))
    check_count("count", count, cfg.max_frames)  # at most a pose per frame the model fills at once
    m = model.skeleton.meters_per_unit
    if source is None and key_quats is not None and cfg.dna_source == "own":
        return key_dna(key_quats, model.skeleton.offsets * m, model.skeleton.parents, int(count))
    if source is None:
        return draw_dna(model.bank, np.random.default_rng(int(seed)), int(count))
    q, _ = model_hierarchy(model.skeleton, model.folded, source.skeleton, source.rotations, source.positions,
                           what="the DNA motion")
    if frames is None:
        frames = pick_frames(rotation_change(q), int(count))
    frames = np.asarray(frames, dtype=np.int64)
    bad = frames[(frames < 0) | (frames >= len(q))]
    if len(bad):
        raise UsageError(f"DNA frame {int(bad[0])} is outside the motion (frames 0-{len(q) - 1})")
    return root_free_poses(q[frames], model.skeleton.offsets * m, model.skeleton.parents).astype(np.float32)


def parse_dna(text: str) -> tuple[str, list[int] | None]:
    """``"FILE[:FRAMES]"`` (``CompleteOptions.dna``) -> ``(file, frames or None)``; a file name holding ``:`` is
    read whole when it exists. Errors name the option ``dna``."""
    import os

    if os.path.exists(text) or ":" not in text:
        return text, None
    path, _, listed = text.rpartition(":")
    try:
        frames = [int(t) for t in listed.split(",") if t.strip()]
    except ValueError:
        raise UsageError(f"dna takes FILE or FILE:FRAMES with frames separated by commas; got {text!r}",
                         params="dna") from None
    if not frames:
        raise UsageError(f"dna {text!r} lists no frames", params="dna")
    return path, frames
