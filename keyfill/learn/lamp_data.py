"""The hopping lamp's sequences as the learned side reads them: variables, keys, splits, standardisation.

A lamp sequence is its ``(F, 6)`` animation variables (:mod:`keyfill.characters.lamp`:
base_x, base_y, base_angle, leg_angle, neck_angle, head_angle; m and rad) and
its key frames (:class:`LampSequence`, read from a ``keyfill simulate`` folder by
:func:`read_sequences`). The lamp ARNN (:mod:`keyfill.learn.arnn`) and the lamp's
``keys`` protocol (:mod:`keyfill.learn.protocols.keys`) share them, with

* :func:`split`: the fixed training / held-out / test split of a dataset;
* :func:`wrap_angles`: key angles as a file of keys gives them, within ``[-pi, pi)``;
* :class:`Normalizer`: per-variable standardisation of sequences made relative
  to their first key (:func:`origin`, :func:`relative`): ``base_x`` relative to
  the first key's, so the same keys give the same motion wherever the lamp
  stands, and each angle without the whole turns that bring the first key's
  into ``[-pi, pi)``.
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
    def fit(cls, sequences: list[LampSequence]) -> Normalizer:
        """Statistics over every frame from first to last key of ``sequences``."""
        if not sequences:
            raise DataError("no sequences to compute normalisation statistics from")
        frames = np.concatenate([relative(s.span) for s in sequences])
        std = frames.std(axis=0)
        return cls(frames.mean(axis=0), np.where(std > MIN_STD, std, 1.0))

    def to_json(self) -> dict:
        return {"mean": [float(v) for v in self.mean], "std": [float(v) for v in self.std]}

    @classmethod
    def from_json(cls, data: dict) -> Normalizer:
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


def split(sequences: list, test_fraction: float = 0.2, val_fraction: float = 0.1) -> dict[str, list]:
    """Fixed split by position: the last 20 % is ``test``, the 10 % before it ``val``, the rest ``train``.

    For the 300 sequences of ``keyfill simulate --count 300`` this is the
    paper's 240 training / 60 test sequences, with 30 of the 240 held out to
    watch training.
    """
    n = len(sequences)
    if n < 3:
        raise DataError(f"{n} sequences cannot be split into training, held-out and test parts (need 3 or more)")
    n_test = max(1, round(test_fraction * n))
    n_val = max(1, round(val_fraction * n))
    n_train = n - n_test - n_val
    if n_train < 1:
        raise DataError(f"{n} sequences leave none for training")
    return {
        "train": sequences[:n_train],
        "val": sequences[n_train: n_train + n_val],
        "test": sequences[n_train + n_val:],
    }
