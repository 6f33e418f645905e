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

NUM_VARIABLES = 6


@dataclass(frozen=True, eq=False)
class LampSequence:
    """One lamp animation and its keys.

    Attributes:
        values: ``(F, 6)`` animation variables (m, rad), every frame.
        keys: ``(K,)`` strictly increasing key frames, ``K >= 2``.
        name: where it came from (for messages).
    """

    values: np.ndarray
    keys: np.ndarray
    name: str = ""

    def __post_init__(self):
        values = np.asarray(self.values, dtype=np.float64)
        keys = np.asarray(self.keys, dtype=np.int64).reshape(-1)
        if values.ndim != 2 or values.shape[1] != NUM_VARIABLES:
            raise DataError(f"{self.name or 'a lamp sequence'}: variables must be (frames, 6), got {values.shape}")
        if len(keys) < 2:
            raise DataError(f"{self.name or 'a lamp sequence'}: at least 2 keys are needed, got {len(keys)}")
        if np.any(np.diff(keys) <= 0) or keys[0] < 0 or keys[-1] >= len(values):
            raise DataError(f"{self.name or 'a lamp sequence'}: keys {keys.tolist()} are not increasing frames "
                            f"of its {len(values)} frames")
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "keys", keys)

    @property
    def span(self) -> np.ndarray:
        """``(T, 6)`` the frames from the first to the last key."""
        return self.values[self.keys[0]: self.keys[-1] + 1]


def sequence_from_motion(motion, keys=None, name: str = "") -> LampSequence:
    """A :class:`LampSequence` from a lamp :class:`~keyfill.motion.Motion` (keys: ``keys`` or ``motion.keys``)."""
    from keyfill.characters.lamp import to_variables

    keys = keys if keys is not None else motion.keys
    if keys is None:
        raise DataError(f"{name or 'the motion'} records no keys")
    return LampSequence(to_variables(motion), np.asarray(keys.frames), name)


def wrap_angles(values: np.ndarray) -> np.ndarray:
    """``values (..., 6)`` with the four angles wrapped into ``[-pi, pi)`` (positions unchanged).

    This is how lamp keys are read from a file: a key stores rotations, not
    turn counts, and the lamp's hinges stay within half a turn of straight
    (in the simulated data every angle is within +-2.7 rad), whereas two keys
    may well be more than half a turn apart (a neck swinging from -1.5 to
    2.0 rad), so wrapping each key beats unwrapping from key to key.
    """
    out = np.array(values, dtype=np.float64)
    out[..., 2:] = (out[..., 2:] + np.pi) % (2 * np.pi) - np.pi
    return out


def read_sequences(folder) -> list[LampSequence]:
    """Every sequence of a ``keyfill simulate`` dataset folder, in run order."""
    from keyfill.io.hops import read_dataset

    return [sequence_from_motion(s.motion, name=s.id) for s in read_dataset(folder)]


#: smallest standard deviation a variable is divided by (a variable that varies less is not scaled)
MIN_STD = 1e-6


@dataclass(frozen=True)
class Normalizer:
    """Per-variable standardisation ``z = (v - mean) / std`` of encoded variables.

    Attributes:
        mean, std: ``(6,)`` in the variables' units (``base_x`` relative to the first key).
    """

    mean: np.ndarray
    std: np.ndarray

    @classmethod
    def fit(cls, sequences: list[LampSequence]) -> "Normalizer":
        """Statistics over every frame from first to last key of ``sequences``."""
        if not sequences:
            raise DataError("no sequences to compute normalisation statistics from")
        frames = np.concatenate([relative(s.span) for s in sequences])
        std = frames.std(axis=0)
        return cls(frames.mean(axis=0), np.where(std > MIN_STD, std, 1.0))

    def to_json(self) -> dict:
        return {"mean": [float(v) for v in self.mean], "std": [float(v) for v in self.std]}

    @classmethod
    def from_json(cls, data: dict) -> "Normalizer":
        """The statistics :meth:`to_json` wrote (``ValueError`` unless they are bounded as :meth:`fit` gives them)."""
        from keyfill.learn.modelfile import bounded_array

        return cls(bounded_array(data["mean"], "the normalisation means", (NUM_VARIABLES,)),
                   bounded_array(data["std"], "the normalisation deviations", (NUM_VARIABLES,), above=MIN_STD))

    def encode(self, span: np.ndarray) -> np.ndarray:
        """``(T, 6)`` frames starting at the first key -> standardised, relative to frame 0 (see :func:`origin`)."""
        return (relative(span) - self.mean) / self.std

    def decode(self, z: np.ndarray, origin: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`encode` for a sequence whose :func:`origin` is ``origin``."""
        return np.asarray(z, dtype=np.float64) * self.std + self.mean + origin


def origin(first: np.ndarray) -> np.ndarray:
    """``(6,)`` what :func:`relative` subtracts, from the first frame ``first (6,)``.

    ``base_x`` itself, and for each angle the whole turns that bring it into
    ``[-pi, pi)``: a joint that has spun once is in the same pose, and a file
    of keys (rotations) cannot tell the two apart.
    """
    out = np.zeros(NUM_VARIABLES)
    out[0] = first[0]
    out[2:] = 2 * np.pi * np.floor((np.asarray(first[2:]) + np.pi) / (2 * np.pi))
    return out


def relative(span: np.ndarray) -> np.ndarray:
    """``span (T, 6)`` minus its :func:`origin`: ``base_x`` from frame 0's, angles less frame 0's whole turns."""
    span = np.asarray(span, dtype=np.float64)
    return span - origin(span[0])


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

    frames: "torch.Tensor"  # noqa: F821
    is_key: "torch.Tensor"  # noqa: F821
    valid: "torch.Tensor"  # noqa: F821
    lengths: "torch.Tensor"  # noqa: F821

    def __len__(self) -> int:
        return self.frames.shape[0]

    def select(self, index) -> "Batch":
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
    gather = lambda idx: torch.gather(frames, 1, idx[..., None].expand(B, T - 1, frames.shape[-1]))  # noqa: E731
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
    gather = lambda idx: np.take_along_axis(frames, idx[..., None], axis=1)  # noqa: E731
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


def complete_lamp_many(jobs, options, get_model, builtin_name: str):
    """Complete lamp motions ``[(motion, keys), ...]`` with a lamp model: what ``complete --method arnn``
    does around the network, for any runtime (torch or onnxruntime) and without torch.

    Args:
        options: :class:`~keyfill.learn.completion.CompleteOptions` (``model`` None: the built-in model).
        get_model: ``() -> model`` with ``predict(sequences)``, ``config`` and ``arch`` (called once, if needed).
        builtin_name: the built-in model's name, for the report.

    Returns, per job, a :class:`~keyfill.learn.completion.Completion` or the
    :class:`~keyfill.errors.KeyfillError` that stopped it. All jobs that reach
    the network go through one ``predict`` call (one batch).
    """
    from keyfill.characters.lamp import from_variables, is_lamp, to_variables
    from keyfill.errors import KeyfillError, ModelError, UsageError
    from keyfill.learn.completion import Completion
    from keyfill.learn.exact_keys import snap_to_keys
    from keyfill.learn.modelfile import check_skeleton

    results: list = [None] * len(jobs)
    model = None
    ready = []
    for i, (motion, keys) in enumerate(jobs):
        try:
            if options.model is None and not is_lamp(motion.skeleton):
                raise UsageError(
                    f"the built-in ARNN model serves the hopping lamp (joints base, leg, neck, head); this motion has "
                    f"joints {', '.join(motion.skeleton.names[:6])}{', ...' if motion.num_joints > 6 else ''}; "
                    f"give --model with a model trained for it"
                )
            if model is None:
                model = get_model()
            check_skeleton(model.config, motion.skeleton, model.path)
            k = keys.frames
            try:
                key_values = wrap_angles(to_variables(motion.frames(k)))  # only the key frames are read
            except DataError as e:
                raise DataError(f"the ARNN completes lamp motions only: {e}") from None
            values = np.zeros((motion.num_frames, key_values.shape[1]))
            values[k] = key_values
            ready.append((i, motion, keys, key_values, LampSequence(values, k)))
        except KeyfillError as e:
            results[i] = e
    with np.errstate(over="ignore", invalid="ignore"):  # a damaged network's overflow is reported below
        spans = model.predict([r[-1] for r in ready]) if ready else []
    for (i, motion, keys, key_values, _), span in zip(ready, spans):
        if not np.isfinite(span).all():
            results[i] = ModelError(f"{model.path or builtin_name}: the network's output is not finite "
                                    "(are its weights damaged?)")
            continue
        k = keys.frames
        out = np.empty((motion.num_frames, NUM_VARIABLES))
        out[k[0]: k[-1] + 1] = span
        out[: k[0]] = span[0]  # hold; the exact-keys correction then moves them with their key
        out[k[-1] + 1:] = span[-1]
        positions = motion.positions.copy()
        positions[:, 0, :2] = out[:, :2]
        pred = motion.replace(rotations=from_variables(out, motion.fps).rotations, positions=positions, keys=keys)
        residual = np.abs(wrap_angles(span[k - k[0]] - key_values)).max(axis=0)  # angles modulo a turn
        residual = {"position_m": float(residual[:2].max()), "angle_rad": float(residual[2:].max())}
        label = f"built-in {builtin_name}" if options.model is None else str(options.model)
        info = {"model": label, "arch": model.arch, "exact_keys": bool(options.exact_keys)}
        if options.exact_keys:
            pred, _ = snap_to_keys(pred, motion, keys)
            info["key_residual_removed"] = residual
        else:
            info["key_residual_left"] = residual
        results[i] = Completion(pred, info)
    return results
