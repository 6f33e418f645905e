"""The transformer started from a matched in-between instead of its pre-fill (issue 46, "long gaps from a
matched start"), against match alone and the transformer as shipped, before any training on such starts.

The shipped transformer (``bandai2-transformer``) learned to correct its pre-fill (the interpolation plus the
fading velocity beside a gap). Here its weights (or ``--model``'s, e.g. a model trained on matched starts,
``matched_starts`` in docs/transformer.md) are handed, as the frames between the keys, the raw output of
``--method match`` with the shipped library (its feet free, seed 0), and add their correction to it
(:func:`keyfill.learn.transformer.model.complete_motions`' ``starts``); keys are then made exact as in every
completion. ``transformer`` is the same model from its pre-fill. Held-out clips and figures as ``bench_match.py`` (6 s clips of dataset-2 ``normal`` and of
dataset-1 ``sad`` / ``feminine``, keys every 30 and 60 frames; foot skating cm/s against the true clip's floor,
jitter m/s^3, gap error cm), the guard off for every method so that each is scored as it fills.

    .venv/bin/python benchmarks/bench_transformer_start.py            # --clips 24 per set
    .venv/bin/python benchmarks/bench_transformer_start.py --clips 4 --no-record
    .venv/bin/python benchmarks/bench_transformer_start.py --model data/models/bandai12-transformer-starts --smoothing 4

Without the corpora it says ``skipped`` and exits 0. The run is recorded in
``benchmarks/results/transformer_start-<model folder>.json``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys

import results
from bench_match import quality, run_method, style_sets

from keyfill.errors import DataError
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.transformer import model as T

SETS = ("normal (dataset-2)", "sad, feminine (dataset-1)")
METHODS = ("cubic", "transformer", "match raw", "match", "transformer from match")  # the transformer: --model


def transformer(model: T.CompletionModel, m, keys, start=None):
    """``model``'s completion of ``m`` between ``keys`` (keys made exact), from its pre-fill or from ``start``."""
    (done,) = T.complete_motions(model, [(m, keys)], batch=False, starts=None if start is None else [start])
    if isinstance(done, Exception):
        raise done
    return T._finish(done, m, keys, CompleteOptions()).motion


def fill(method: str, model: T.CompletionModel, m, keys):
    if method == "transformer":
        return transformer(model, m, keys)
    if method == "transformer from match":
        return transformer(model, m, keys, run_method("match raw", m, keys).motion)
    return run_method(method, m, keys).motion


def goals(figures: dict) -> list[dict]:
    """Issue 46's long-gap goals (keys every 60) for the transformer started from a match."""
    g = []
    for name in SETS:
        q = figures["quality"][name]
        row, real = q["60"], q["real"]
        t = row["transformer from match"]
        g.append(results.goal(46, f"{name}, keys every 60, started from a match: gap error below match's",
                              f"{t['gap_error_cm']:.2f} cm against {row['match']['gap_error_cm']:.2f} "
                              f"(raw {row['match raw']['gap_error_cm']:.2f})",
                              t["gap_error_cm"] < row["match"]["gap_error_cm"]))
        skate = t["foot_skating_cm_s"] / real["foot_skating_cm_s"]
        g.append(results.goal(46, f"{name}, keys every 60, started from a match: foot skating at most 1.5x real",
                              f"{skate:.2f}x", skate <= 1.5))
        jit = t["jitter_m_s3"] / real["jitter_m_s3"]
        g.append(results.goal(46, f"{name}, keys every 60, started from a match: jitter 0.67x-1.5x real",
                              f"{jit:.2f}x", 0.67 <= jit <= 1.5))
    return g


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=24, help="clips per style set (default 24)")
    ap.add_argument("--model", help="a transformer model folder (default: the shipped bandai2-transformer)")
    ap.add_argument("--smoothing", type=int, default=None,
                    help="score with this output_smoothing (inference only); the record is named MODEL-sN")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    try:
        sets = style_sets(args.clips)
    except DataError as e:
        print(f"skipped: {e}")
        return 0
    path = T.model_path(CompleteOptions(model=args.model))
    model, name = T.load(path), path.name
    if args.smoothing is not None:
        model = dataclasses.replace(model, config=dataclasses.replace(model.config, output_smoothing=args.smoothing))
        name += f"-s{args.smoothing}"
    held_out = {k: sets[k] for k in SETS}
    figures = {"clips": {k: len(v) for k, v in held_out.items()}, "model": name,
               "quality": quality(held_out, METHODS, lambda method, m, keys: fill(method, model, m, keys))}
    record = bench.record(f"transformer_start-{name}", figures, goals(figures), write=not args.no_record)
    results.print_goals(record)
    print(results.summary(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
