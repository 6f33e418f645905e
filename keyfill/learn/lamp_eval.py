"""Scoring lamp in-betweening the way the paper's Tables 1 and 2 do (Zhang & van de Panne 2018).

Every method completes each test sequence from its keys, twice: with all keys,
and with 1-2 interior keys deleted (the same deletions for every method, drawn
from ``seed``). The scores, on variables standardised by the evaluated
sequences' own mean and deviation (``base_x`` relative to the first key, as
the networks see it), are:

* ``key``: mean squared error at the keys given (except the first, the
  starting frame), per key and variable;
* ``frame``: mean squared error over every completed frame (1 .. T-1);
* ``total``: ``key + frame`` (the paper's "Total Loss");
* ``rmse``: per variable, the root mean squared error over the frames in the
  variable's own unit (m or rad), so numbers read physically.

Methods: the spline baselines (``linear``, ``cubic``; they go through
:func:`keyfill.learn.methods.complete` like ``keyfill complete`` does, and hit
their keys exactly) and trained lamp models (raw network output, or with the
exact-keys correction that ``keyfill complete`` applies by default).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from keyfill.errors import DataError
from keyfill.learn.lamp_features import LampSequence, Normalizer

CONDITIONS = ("all_keys", "deleted_keys")


@dataclass
class Scores:
    """Scores of one method under one condition (see the module docstring)."""

    key: float
    frame: float
    rmse: dict[str, float]
    sequences: int

    @property
    def total(self) -> float:
        return self.key + self.frame

    def as_dict(self) -> dict:
        return {"key": self.key, "frame": self.frame, "total": self.total, "rmse": self.rmse,
                "sequences": self.sequences}


@dataclass
class Report:
    """A method's scores per condition."""

    method: str
    scores: dict[str, Scores] = field(default_factory=dict)
    details: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"method": self.method, **self.details, **{c: s.as_dict() for c, s in self.scores.items()}}


def deleted_keys(sequences: list[LampSequence], seed: int = 0) -> list[LampSequence]:
    """The sequences with 1 or 2 interior keys deleted (count and keys uniform at random, from ``seed``)."""
    rng = np.random.default_rng(seed)
    out = []
    for s in sequences:
        interior = s.keys[1:-1]
        n = min(int(rng.integers(1, 3)), len(interior))
        drop = rng.choice(interior, size=n, replace=False) if n else []
        out.append(LampSequence(s.values, np.setdiff1d(s.keys, drop), s.name))
    return out


def score(sequences: list[LampSequence], predictions: list[np.ndarray], normalizer: Normalizer) -> Scores:
    """Scores of ``predictions`` (each ``(T, 6)``, first to last key) against ``sequences``."""
    from keyfill.sim.lamp import VARIABLE_NAMES

    key_err, frame_err, sq = [], [], []
    for s, p in zip(sequences, predictions):
        truth = s.span
        if p.shape != truth.shape:
            raise DataError(f"{s.name}: a prediction of shape {p.shape} for {truth.shape} frames")
        diff = p - truth
        sq.append(diff[1:] ** 2)
        z = diff / normalizer.std  # base_x relative or not: a difference is the same
        frame_err.append(z[1:] ** 2)
        key_err.append(z[s.keys[1:] - s.keys[0]] ** 2)
    frame = np.concatenate(frame_err)
    keys = np.concatenate(key_err)
    rmse = np.sqrt(np.concatenate(sq).mean(axis=0))
    return Scores(float(keys.mean()), float(frame.mean()), dict(zip(VARIABLE_NAMES, map(float, rmse))), len(sequences))


def spline_predictions(method: str, sequences: list[LampSequence]) -> list[np.ndarray]:
    """Completions by a spline baseline through the ``Motion`` pipeline of ``keyfill complete``."""
    from keyfill.learn.methods import complete
    from keyfill.motion import Keys
    from keyfill.sim.lamp import from_variables, to_variables

    out = []
    for s in sequences:
        keys = Keys(s.keys)
        filled = complete(from_variables(s.values, 30.0), keys, method).motion
        out.append(to_variables(filled)[s.keys[0]: s.keys[-1] + 1])
    return out


def model_predictions(model, sequences: list[LampSequence], exact_keys: bool = False) -> list[np.ndarray]:
    """Completions by a trained lamp model (a :class:`keyfill.learn.arnn.LampModel`).

    With ``exact_keys`` the residual at the keys is removed as ``keyfill complete`` does.
    """
    preds = model.predict(sequences)
    if not exact_keys:
        return preds
    from keyfill.learn.exact_keys import snap_to_keys
    from keyfill.motion import Keys
    from keyfill.sim.lamp import from_variables, to_variables

    out = []
    for s, p in zip(sequences, preds):
        k = s.keys - s.keys[0]
        source = from_variables(s.span, 30.0)
        snapped, _ = snap_to_keys(from_variables(p, 30.0), source, Keys(k))
        out.append(to_variables(snapped))
    return out


def evaluate(method: str, sequences: list[LampSequence], model=None, exact_keys: bool = False,
             seed: int = 0) -> Report:
    """Score ``method`` on ``sequences`` with all keys and with 1-2 keys deleted.

    Args:
        method: ``"linear"``, ``"cubic"``, or a label for ``model``.
        model: a loaded lamp model for learned methods (None for the splines).
        exact_keys: apply the exact-keys correction to the model's output.
        seed: seed of the key deletions.
    """
    if not sequences:
        raise DataError("no sequences to evaluate")
    normalizer = Normalizer.fit(sequences)
    report = Report(method)
    if model is not None:
        report.details = {"arch": model.arch, "model": model.path, "exact_keys": exact_keys}
    for condition, seqs in (("all_keys", sequences), ("deleted_keys", deleted_keys(sequences, seed))):
        if model is None:
            preds = spline_predictions(method, seqs)
        else:
            preds = model_predictions(model, seqs, exact_keys)
        report.scores[condition] = score(seqs, preds, normalizer)
    return report
