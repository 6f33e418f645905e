"""Quality of a trained transformer on Bandai-Namco dataset-2 against the baselines and SSMCT's goal.

The tables of docs/benchmarks.md (transformer section), from a model trained with the
`normal` style held out::

    .venv/bin/keyfill train transformer data/bandai2/bandai_namco_motiondataset2/data \\
        --exclude '*_normal_*' -o data/models/bandai2-transformer \\
        --config benchmarks/bench_transformer_bandai2.json --seed 0
    .venv/bin/python benchmarks/bench_transformer_quality.py data/models/bandai2-transformer

1. LaFAN1 in-betweening (Harvey et al. 2020) on the `normal` clips (test
   windows 65/40), statistics from the other styles (50/20), root folded into
   the hips, facing axis +Y: zero-velocity, interpolation, cubic and the model
   at transition lengths 5, 15, 30, 45; then every score relative to
   interpolation next to SSMCT's ratios on LaFAN1 (Duan et al. 2021, Table 1:
   L2Q 0.14/0.22, 0.36/0.62, 0.61/0.98; L2P 0.22/0.37, 0.56/1.25, 1.10/2.32;
   NPSS 0.0016/0.0023, 0.0234/0.0391, 0.1222/0.2013; at 45 frames, which the
   paper does not report, its 30-frame ratios). The goal is met where the
   model's ratio is at most SSMCT's. Issue 14's goal beside it: the ratios of
   the best published model (Qin et al. 2022, two-stage transformer, on LaFAN1:
   L2Q 0.45 / 0.46 / 0.56, L2P 0.28 / 0.32 / 0.39, NPSS 0.48 / 0.48 / 0.56 at
   5 / 15 / 30 frames). Issue 46's *fair anchors* beside them: Qin et al.'s headline figures post-process
   with a frame after the target key (the target's velocity), which the one-target-frame protocol of Harvey,
   SSMCT, the Delta-Interpolator and keyfill does not give; the best ratios verified under that rule are the
   Delta-Interpolator's at 5 / 15 / 30 frames (Oreshkin et al., ``boreshkinai/delta-interpolator``: L2Q 0.517 /
   0.512 / 0.584, L2P 0.346 / 0.374 / 0.430, NPSS 0.609 / 0.555 / 0.605) and Qin's first stage alone at 45
   (L2Q 0.734, L2P 0.579). The goal: at or below them in at least 7 of the 9 cells at 5-30, and at 45 no worse
   than Qin's first stage. ``velocity`` (the pre-fill of keyfill's velocity-prefill models) is scored as a
   baseline.
2. The same model on other key layouts of the same windows: in-filling (a key
   every 5, 10 or 15 frames over 61 frames) and blending (10 given frames, a
   gap of 15 or 30, 10 given frames), against interpolation and cubic.

The corpus is read from ``data/bandai2/`` (unpacked from ``../shared`` when
absent; ``--data`` another folder, ``--test-pattern`` other held-out clips, e.g. dataset-1's ``sad`` and
``feminine``, the statistics then from that folder's other clips); without it the script says ``skipped`` and
exits 0. The run is recorded in
``benchmarks/results/transformer_quality-<model folder>[-<patterns>].json`` (``results.py``; not with
``--no-record``): ``model``, ``protocol``, ``inbetweening`` (``{method: {length: scores}}``),
``layouts`` (``{layout: {method: scores}}``), the papers' ratios ``ssmct``, ``qin`` and ``fair``
(``{metric: {length: ratio}}``), ``test_pattern`` and ``seconds``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import results

from keyfill import interpolate
from keyfill.errors import DataError
from keyfill.learn.corpus import locate
from keyfill.learn.protocols import lafan1 as B
from keyfill.learn.transformer.model import load

SSMCT = {  # Table 1 of the paper: (SSMCT, interpolation) at 5, 15, 30 frames
    "L2Q": {5: (0.14, 0.22), 15: (0.36, 0.62), 30: (0.61, 0.98)},
    "L2P": {5: (0.22, 0.37), 15: (0.56, 1.25), 30: (1.10, 2.32)},
    "NPSS": {5: (0.0016, 0.0023), 15: (0.0234, 0.0391), 30: (0.1222, 0.2013)},
}


#: Qin et al. 2022, ratios to interpolation on LaFAN1 at 5, 15, 30 frames (issue 14's goal)
QIN = {"L2Q": {5: 0.45, 15: 0.46, 30: 0.56}, "L2P": {5: 0.28, 15: 0.32, 30: 0.39},
       "NPSS": {5: 0.48, 15: 0.48, 30: 0.56}}


#: issue 46's fair anchors, ratios to interpolation under the one-target-frame rule: the Delta-Interpolator's at 5,
#: 15 and 30 frames (Oreshkin et al., boreshkinai/delta-interpolator), Qin et al. 2022's first stage alone at 45
FAIR = {"L2Q": {5: 0.517, 15: 0.512, 30: 0.584, 45: 0.734}, "L2P": {5: 0.346, 15: 0.374, 30: 0.430, 45: 0.579},
        "NPSS": {5: 0.609, 15: 0.555, 30: 0.605}}


def ssmct_ratio(metric: str, n: int) -> float:
    ours, interp = SSMCT[metric][n if n in SSMCT[metric] else 30]
    return ours / interp


def _cells(met: dict) -> str:
    """``N of M cells`` and the cells missed, from ``{metric: {length: met}}``."""
    missed = [f"{m} at {n}" for m, by_n in met.items() for n, ok in by_n.items() if not ok]
    total = sum(len(by_n) for by_n in met.values())
    return f"{total - len(missed)} of {total} cells" + (f"; missed: {', '.join(missed)}" if missed else "")


def goals(goal: dict, qin: dict, fair: dict, held: str) -> list[dict]:
    """Issue 6's goal (SSMCT's ratios, 12 cells), issue 14's (Qin et al.'s, 9 cells) and issue 46's (the fair
    anchors: 7 of the 9 cells at 5-30 frames, and both at 45) on the held-out clips ``held``."""
    short = {m: {n: ok for n, ok in by_n.items() if n != 45} for m, by_n in fair.items()}
    long = {m: {45: by_n[45]} for m, by_n in fair.items() if 45 in by_n}
    met = sum(ok for by_n in short.values() for ok in by_n.values())
    fair_goals = [results.goal(46, f"transformer on `{held}`: at or below the fair anchors (the Delta-Interpolator's "
                                   "ratios) in at least 7 of the 9 cells at 5, 15 and 30 frames", _cells(short),
                               met >= 7),
                  results.goal(46, f"transformer on `{held}`: at 45 frames no worse than Qin et al.'s first stage "
                                   "(L2Q 0.734, L2P 0.579)", _cells(long), all(ok for by_n in long.values()
                                                                                for ok in by_n.values()))]
    if held != "*_normal_*":  # issues 6 and 14 were set on `normal`
        return fair_goals
    return fair_goals + [results.goal(6, "transformer ratios to interpolation at most SSMCT's, every metric and length (12 cells)",
                         _cells(goal), all(ok for by_n in goal.values() for ok in by_n.values())),
            results.goal(14, "transformer ratios to interpolation at most Qin et al.'s at 5, 15 and 30 frames (9 "
                             "cells)", _cells(qin), all(ok for by_n in qin.values() for ok in by_n.values()))]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("model", help="a model folder trained with the normal style held out")
    ap.add_argument("--json", action="store_true", help="print the record as JSON")
    ap.add_argument("--data", default=None, help="BVH folder (default: Bandai-Namco dataset-2)")
    ap.add_argument("--test-pattern", default="*_normal_*",
                    help="held-out clips, file-name patterns separated by commas (default: *_normal_*)")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    try:
        folder = args.data or locate("bandai2")
    except DataError as e:
        print(f"skipped: {e}")
        return 0
    t0 = time.perf_counter()
    model = load(args.model)
    patterns = [p.strip() for p in args.test_pattern.split(",") if p.strip()]
    proto = B.lafan1([folder], patterns, fold=True, facing_axis="+Y")
    methods = {"zero-velocity": interpolate.hold_windows, "interpolation": interpolate.linear_windows, "cubic": interpolate.cubic_windows,
               "velocity": interpolate.velocity_windows, "transformer": model.benchmark_method()}
    inbetween = B.evaluate(methods, proto.test, proto.stats, B.LENGTHS)
    layouts = {
        "in-filling, key every 5": np.arange(0, 61, 5),
        "in-filling, key every 10": np.arange(0, 61, 10),
        "in-filling, key every 15": np.arange(0, 61, 15),
        "blending, 10 + gap 15 + 10": np.r_[0:10, 25:35],
        "blending, 10 + gap 30 + 10": np.r_[0:10, 40:50],
    }
    others = {name: B.score_keys({k: methods[k] for k in ("interpolation", "cubic", "velocity", "transformer")},
                                 proto.test, proto.stats, keys) for name, keys in layouts.items()}
    ratio = {m: {n: inbetween["transformer"][n][m] / inbetween["interpolation"][n][m] for n in B.LENGTHS}
             for m in ("L2Q", "L2P", "NPSS")}
    goal = {m: {n: ratio[m][n] <= ssmct_ratio(m, n) for n in B.LENGTHS} for m in ratio}
    qin = {m: {n: ratio[m][n] <= QIN[m][n] for n in QIN[m]} for m in ratio}
    fair = {m: {n: ratio[m][n] <= FAIR[m][n] for n in FAIR[m]} for m in ratio}
    report = {"protocol": proto.info, "model": args.model, "inbetweening": inbetween, "layouts": others,
              "ssmct": {m: {n: ssmct_ratio(m, n) for n in B.LENGTHS} for m in SSMCT}, "qin": QIN, "fair": FAIR,
              "test_pattern": args.test_pattern, "seconds": time.perf_counter() - t0}
    name = f"transformer_quality-{Path(args.model).name}"
    if args.test_pattern != "*_normal_*":
        name += "-" + "-".join(p.strip("*_") for p in patterns)
    record = bench.record(name, report, goals(goal, qin, fair, args.test_pattern), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0
    print(f"LaFAN1 protocol on {folder}: {proto.info['test_windows']} test windows ({proto.info['test_clips']} "
          f"held-out clips {args.test_pattern}), statistics from {proto.info['train_windows']} windows")
    print(B.format_table(inbetween))
    print("\ntransformer / interpolation vs SSMCT / interpolation on LaFAN1 (goal: at most SSMCT's)")
    for m in ("L2Q", "L2P", "NPSS"):
        print(f"  {m:<5}" + "   ".join(f"{n:>2}: {ratio[m][n]:.3f} vs {ssmct_ratio(m, n):.3f} "
                                     f"{'met' if goal[m][n] else 'NOT met'}" for n in B.LENGTHS))
    print("\ntransformer / interpolation vs Qin et al. 2022 on LaFAN1 (issue 14's goal: at most Qin's)")
    for m in ("L2Q", "L2P", "NPSS"):
        print(f"  {m:<5}" + "   ".join(f"{n:>2}: {ratio[m][n]:.3f} vs {QIN[m][n]:.2f} {'met' if qin[m][n] else 'NOT met'}"
                                     for n in QIN[m]))
    print("\ntransformer / interpolation vs the fair anchors (issue 46: 7 of 9 at 5-30, both at 45)")
    for m in ("L2Q", "L2P", "NPSS"):
        print(f"  {m:<5}" + "   ".join(f"{n:>2}: {ratio[m][n]:.3f} vs {FAIR[m][n]:.3f} "
                                     f"{'met' if fair[m][n] else 'NOT met'}" for n in FAIR[m]))
    print("\nother key layouts (every frame between the first and last key that is not a key is scored)")
    width = max(map(len, layouts))
    print(f"{'':{width}}  {'method':<13} {'L2Q':>7} {'L2P':>7} {'NPSS':>8}   L2Q, L2P, NPSS / interpolation")
    for name, res in others.items():
        for meth, v in res.items():
            rel = " ".join(f"{v[m] / res['interpolation'][m]:.3f}" for m in ("L2Q", "L2P", "NPSS"))
            print(f"{name:{width}}  {meth:<13} {v['L2Q']:7.4f} {v['L2P']:7.4f} {v['NPSS']:8.5f}   {rel}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
