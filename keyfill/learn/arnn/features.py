"""The hopping lamp's animation variables as network inputs and targets (ARNN, Zhang & van de Panne 2018).

A lamp sequence is its ``(F, 6)`` animation variables (:mod:`keyfill.characters.lamp`:
base_x, base_y, base_angle, leg_angle, neck_angle, head_angle; m and rad) and
its key frames. The networks see it *encoded*:

* ``base_x`` is taken relative to the first key's, so the same keys give the
  same motion wherever the lamp stands (the paper uses absolute positions
  rather than per-frame deltas; an offset fixed per sequence keeps that and
  adds horizontal invariance), and each angle loses the whole turns that
  bring the first key's into ``[-pi, pi)`` (:func:`origin`);
* every variable is standardised with the training set's mean and standard
  deviation (:class:`Normalizer`, stored in the model file).

A network predicts frames ``1 .. T-1`` of a sequence whose frame 0 is its
first key and frame ``T-1`` its last. For the frame ``t`` in the interval
``(T_K, T_{K+1}]`` it is given the keys ``X_K`` and ``X_{K+1}`` and
``t_rel = (t - T_K) / (T_{K+1} - T_K)`` (:func:`conditioning`), so a key's own
frame is predicted with ``t_rel = 1``. Sequences of different lengths are
padded into one batch (:class:`Batch`) with a mask of real frames; keys may be
any number >= 2 at any spacing. :func:`delete_keys` removes 0-2 interior keys
of each sequence at random, the paper's augmentation (section 5).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.errors import DataError
from keyfill.learn.lamp_data import NUM_VARIABLES, LampSequence, Normalizer


@dataclass
class Batch:
    """Padded, encoded sequences (torch tensors).

    Attributes:
        frames: ``(B, T, 6)`` float32 standardised frames (every frame for training data;
            only key frames are meaningful for completion); zero beyond a sequence's length.
        is_key: ``(B, T)`` bool, the frame is a key given to the network (frame 0 and the
            last frame of each sequence always are).
        valid: ``(B, T)`` bool, the frame belongs to the sequence.
        lengths: ``(B,)`` int64 frames per sequence.
    """

    frames: torch.Tensor  # noqa: F821
    is_key: torch.Tensor  # noqa: F821
    valid: torch.Tensor  # noqa: F821
    lengths: torch.Tensor  # noqa: F821

    def __len__(self) -> int:
        return self.frames.shape[0]

    def select(self, index) -> Batch:
        """The sequences ``index`` (a tensor of indices), trimmed to their longest length."""
        lengths = self.lengths[index]
        T = int(lengths.max())
        return Batch(self.frames[index, :T], self.is_key[index, :T], self.valid[index, :T], lengths)


def batch_arrays(sequences: list[LampSequence], normalizer: Normalizer):
    """Encode and pad ``sequences`` (each cut to its first..last key): numpy ``(frames (B, T, 6) float32,
    is_key (B, T), valid (B, T), lengths (B,) int64)``, the arrays of a :class:`Batch`."""
    if not sequences:
        raise DataError("no sequences to batch")
    T = max(int(s.keys[-1] - s.keys[0] + 1) for s in sequences)
    B = len(sequences)
    frames = np.zeros((B, T, NUM_VARIABLES), dtype=np.float32)
    is_key = np.zeros((B, T), dtype=bool)
    valid = np.zeros((B, T), dtype=bool)
    for b, s in enumerate(sequences):
        n = int(s.keys[-1] - s.keys[0] + 1)
        frames[b, :n] = normalizer.encode(s.span)
        is_key[b, s.keys - s.keys[0]] = True
        valid[b, :n] = True
    return frames, is_key, valid, valid.sum(axis=1).astype(np.int64)


def make_batch(sequences: list[LampSequence], normalizer: Normalizer) -> Batch:
    """Encode and pad ``sequences`` (each cut to its first..last key) into one :class:`Batch`."""
    import torch

    return Batch(*(torch.from_numpy(a) for a in batch_arrays(sequences, normalizer)))


def conditioning(frames, is_key):
    """The key inputs for frames ``1 .. T-1`` (numpy arrays or torch tensors).

    Args:
        frames: ``(B, T, 6)`` frames (only those at keys are read).
        is_key: ``(B, T)`` bool keys; frame 0 must be a key.

    Returns:
        ``(x_prev (B, T-1, 6), x_next (B, T-1, 6), t_rel (B, T-1, 1), target_is_key (B, T-1))``:
        for frame ``t`` in ``(T_K, T_{K+1}]``, the keys ``X_K`` and ``X_{K+1}`` and
        ``(t - T_K) / (T_{K+1} - T_K)``. Past a sequence's last key (padding) the
        last key is used for both and ``t_rel`` is 1.
    """
    if isinstance(frames, np.ndarray):
        return _conditioning_np(frames, is_key)
    import torch

    B, T = is_key.shape
    t = torch.arange(T).expand(B, T)
    # last key at or before each frame; the key strictly before frame t is that of frame t-1
    at_or_before = torch.cummax(torch.where(is_key, t, torch.full_like(t, -1)), dim=1).values
    prev_idx = at_or_before[:, :-1]
    # first key at or after each frame (T where none): a reversed running minimum
    after = torch.where(is_key, t, torch.full_like(t, T))
    at_or_after = torch.flip(torch.cummin(torch.flip(after, [1]), dim=1).values, [1])[:, 1:]
    next_idx = torch.where(at_or_after >= T, prev_idx, at_or_after)
    gather = lambda idx: torch.gather(frames, 1, idx[..., None].expand(B, T - 1, frames.shape[-1]))
    span = (next_idx - prev_idx).clamp(min=1).to(frames.dtype)
    t_rel = torch.where(next_idx > prev_idx, (t[:, 1:] - prev_idx).to(frames.dtype) / span,
                        torch.ones_like(span))
    return gather(prev_idx), gather(next_idx), t_rel[..., None], is_key[:, 1:]


def _conditioning_np(frames: np.ndarray, is_key: np.ndarray):
    """:func:`conditioning` in numpy, step for step (the runtime of exported lamp models imports no torch)."""
    B, T = is_key.shape
    t = np.broadcast_to(np.arange(T), (B, T))
    prev_idx = np.maximum.accumulate(np.where(is_key, t, -1), axis=1)[:, :-1]
    at_or_after = np.minimum.accumulate(np.where(is_key, t, T)[:, ::-1], axis=1)[:, ::-1][:, 1:]
    next_idx = np.where(at_or_after >= T, prev_idx, at_or_after)
    gather = lambda idx: np.take_along_axis(frames, idx[..., None], axis=1)
    span = np.maximum(next_idx - prev_idx, 1).astype(frames.dtype)
    t_rel = np.where(next_idx > prev_idx, (t[:, 1:] - prev_idx).astype(frames.dtype) / span,
                     np.ones_like(span))
    return gather(prev_idx), gather(next_idx), t_rel[..., None], is_key[:, 1:]


def delete_keys(is_key, valid, generator, max_deleted: int = 2, min_deleted: int = 0):
    """Remove ``min_deleted`` .. ``max_deleted`` interior keys of each sequence at random.

    The count is uniform over that range (capped by the interior keys there
    are), the keys uniform among the interior ones; the first and last key
    always stay. Returns a new ``(B, T)`` bool mask.
    """
    import torch

    B, T = is_key.shape
    lengths = valid.sum(dim=1)
    interior = is_key.clone()
    interior[:, 0] = False
    interior[torch.arange(B), lengths - 1] = False
    count = torch.randint(min_deleted, max_deleted + 1, (B,), generator=generator)
    count = torch.minimum(count, interior.sum(dim=1))
    score = torch.rand((B, T), generator=generator)
    score = torch.where(interior, score, torch.full_like(score, 2.0))
    rank = torch.argsort(torch.argsort(score, dim=1), dim=1)
    return is_key & ~(interior & (rank < count[:, None]))
