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

Angles are compared modulo a full turn (the difference wrapped to
``[-pi, pi)``): a pose is the same after a joint spins once. Methods get the
keys the way they are read from a file of keys (rotations): the ARNN reads
each key's angles within ``[-pi, pi)`` (:func:`keys_as_read`); the
``linear`` and ``cubic`` methods of ``keyfill complete`` interpolate the
rotations themselves, so between two keys more than half a turn apart they
turn the short way. ``cubic-variables`` is the animator's spline: a C1 cubic
through each animation variable (keys read like the ARNN's, tangents as in
:func:`keyfill.interpolate.cubic`).

Methods: the spline baselines (``linear``, ``cubic``; they go through
:func:`keyfill.learn.registry.complete` like ``keyfill complete`` does, and hit
their keys exactly) and trained lamp models (raw network output, or with the
exact-keys correction that ``keyfill complete`` applies by default).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from keyfill.errors import DataError
from keyfill.learn.lamp_data import LampSequence, Normalizer, wrap_angles

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


def keys_as_read(sequence: LampSequence) -> LampSequence:
    """``sequence`` with its keys' angles as ``keyfill complete --method arnn`` reads them (within ``[-pi, pi)``).

    Other frames are left as they are (no method reads them).
    """
    values = sequence.values.copy()
    values[sequence.keys] = wrap_angles(values[sequence.keys])
    return LampSequence(values, sequence.keys, sequence.name)


def score(sequences: list[LampSequence], predictions: list[np.ndarray], normalizer: Normalizer) -> Scores:
    """Scores of ``predictions`` (each ``(T, 6)``, first to last key) against ``sequences``."""
    from keyfill.characters.lamp import VARIABLE_NAMES

    key_err, frame_err, sq = [], [], []
    for s, p in zip(sequences, predictions):
        truth = s.span
        if p.shape != truth.shape:
            raise DataError(f"{s.name}: a prediction of shape {p.shape} for {truth.shape} frames")
        diff = p - truth
        diff[:, 2:] = (diff[:, 2:] + np.pi) % (2 * np.pi) - np.pi  # angles modulo a full turn
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
    from keyfill.characters.lamp import from_variables, to_variables
    from keyfill.learn.registry import complete
    from keyfill.motion import Keys

    out = []
    for s in sequences:
        keys = Keys(s.keys)
        filled = complete(from_variables(s.values, 30.0), keys, method).motion
        out.append(to_variables(filled)[s.keys[0]: s.keys[-1] + 1])
    return out


def variable_spline_predictions(sequences: list[LampSequence]) -> list[np.ndarray]:
    """``cubic-variables``: a C1 cubic Hermite spline through the keys of each animation variable.

    Tangents at inner keys are the segment slopes averaged with the other
    segment's length as weight, at the end keys the end segment's slope (the
    rule of :func:`keyfill.interpolate.cubic`).
    """
    from scipy.interpolate import CubicHermiteSpline

    out = []
    for s in sequences:
        k = s.keys.astype(np.float64)
        v = s.values[s.keys]
        h = np.diff(k)[:, None]
        slopes = np.diff(v, axis=0) / h
        tangents = np.empty_like(v)
        tangents[0], tangents[-1] = slopes[0], slopes[-1]
        tangents[1:-1] = (h[1:] * slopes[:-1] + h[:-1] * slopes[1:]) / (h[:-1] + h[1:])
        out.append(CubicHermiteSpline(k, v, tangents, axis=0)(np.arange(s.keys[0], s.keys[-1] + 1)))
    return out


def model_predictions(model, sequences: list[LampSequence], exact_keys: bool = False) -> list[np.ndarray]:
    """Completions by a trained lamp model (a :class:`keyfill.learn.arnn.model.LampModel`).

    With ``exact_keys`` the residual at the keys is removed as ``keyfill complete`` does.
    """
    preds = model.predict(sequences)
    if not exact_keys:
        return preds
    from keyfill.characters.lamp import from_variables, to_variables
    from keyfill.learn.exact_keys import snap_to_keys
    from keyfill.motion import Keys

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
        method: ``"linear"``, ``"cubic"``, ``"cubic-variables"``, or a label for ``model``.
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
        given = [keys_as_read(s) for s in seqs]
        if method == "cubic-variables":
            preds = variable_spline_predictions(given)
        elif model is None:
            preds = spline_predictions(method, given)
        else:
            preds = model_predictions(model, given, exact_keys)
        report.scores[condition] = score(seqs, preds, normalizer)
    return report


def resolve(method_or_model: str):
    """``(label, model or None)`` for ``linear``, ``cubic``, ``cubic-variables``, ``arnn`` (the shipped model)
    or a model folder."""
    from keyfill.learn import registry

    if method_or_model in ("linear", "cubic", "cubic-variables"):
        return method_or_model, None
    label, _, model = registry.load_model(method_or_model)
    return (label if label in registry.METHODS else f"{model.arch} ({method_or_model})"), model


def protocol(method_or_model: str, folder, baselines: bool = True, seed: int = 0) -> tuple[list[Report], dict]:
    """The lamp protocol on the test split of a ``keyfill simulate`` folder.

    Scores ``method_or_model`` (a model twice: raw, and with the exact-keys
    correction) and, with ``baselines``, ``linear``, ``cubic`` and
    ``cubic-variables``. Returns the
    reports and a summary of the data.
    """
    from keyfill.learn.lamp_data import read_sequences, split

    sequences = read_sequences(folder)
    parts = split(sequences)
    test = parts["test"]
    label, model = resolve(method_or_model)
    if model is None:
        reports = [evaluate(label, test, seed=seed)]
    else:
        reports = [evaluate(label, test, model, seed=seed),
                   evaluate(label + " + exact keys", test, model, exact_keys=True, seed=seed)]
    if baselines:
        reports += [evaluate(name, test, seed=seed) for name in ("linear", "cubic", "cubic-variables")
                    if name != label]
    info = {"data": str(folder), "sequences": len(sequences), "test_sequences": len(test),
            "test_first": test[0].name, "test_last": test[-1].name, "deletion_seed": seed}
    return reports, info


def run(method_or_model: str, data, baselines: bool = True, **lafan1_options):
    """The keys protocol as ``keyfill evaluate`` runs it: an :class:`~keyfill.learn.protocols.Evaluation`.

    ``data`` is one folder made by ``keyfill simulate``; ``lafan1_options`` (test patterns, lengths, ...) do not apply.
    """
    from keyfill.errors import UsageError
    from keyfill.learn.protocols import Evaluation

    if len(data) != 1:
        raise UsageError("the keys protocol takes one dataset folder made by 'keyfill simulate'")
    reports, info = protocol(method_or_model, data[0], baselines=baselines)
    line = (f"keys: {info['test_sequences']} test sequences of {info['data']} ({info['test_first']} .. "
            f"{info['test_last']}), completed with all keys and with 1-2 keys deleted; losses on standardised "
            f"variables (total = key + frame)")
    return Evaluation("keys", method_or_model, info, {r.method: r.as_dict() for r in reports}, [line],
                      format_table(reports))


def format_table(reports: list[Report]) -> str:
    """The scores as a text table: key, frame and total loss with all keys and with 1-2 keys deleted."""
    width = max(len(r.method) for r in reports) + 2
    head = f"{'':<{width}}{'all keys':^30}  {'1-2 keys deleted':^30}"
    cols = f"{'method':<{width}}" + "  ".join(f"{'key':>9} {'frame':>9} {'total':>9}" for _ in CONDITIONS)
    lines = [head, cols]
    for r in reports:
        cells = "  ".join(f"{r.scores[c].key:9.5f} {r.scores[c].frame:9.5f} {r.scores[c].total:9.5f}"
                          for c in CONDITIONS)
        lines.append(f"{r.method:<{width}}{cells}")
    return "\n".join(lines)
