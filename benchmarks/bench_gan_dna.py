"""Motion DNA and partial-key figures of a trained gan model on held-out Bandai-Namco dataset-2 clips.

The table of docs/benchmarks.md (gan: Motion DNA and partial keys), from a model
trained with ``--dna --partial-keys`` and the ``normal`` style held out::

    make -j2 gan-models            # data/models/bandai2-gan-partial among them (see the Makefile)
    .venv/bin/python benchmarks/bench_gan_dna.py data/models/bandai2-gan-partial --sequences 50

On the ``normal`` clips (:func:`keyfill.learn.gan.quality.quality_report`):
the DNA errors of Eqs. 11-12 in cm (the paper: 8.4 and 6.5 cm), keyframe
errors for whole, root-only, half-body, 2-D and sketched 2-D keys, and the variety (mean
pairwise joint distance of the in-betweens) for 4 DNAs through the same keys
against 4 noise seeds. Without the corpus the script says ``skipped`` and exits 0.
The run is recorded in ``benchmarks/results/gan_dna-<model folder>.json`` (``results.py``; not
with ``--no-record``): the quality report (``sequences``, ``frames``, ``clips``, ``key_errors``,
``variety_cm``, ``dna_pull_cm``, ``dna_error_1_cm``, ``dna_error_2_cm``), ``model`` and ``paper``.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import results

from keyfill.errors import DataError
from keyfill.learn.corpus import load_corpus, locate
from keyfill.learn.gan.model import load_model
from keyfill.learn.gan.quality import quality_report

PAPER = {"dna_error_1_cm": 8.4, "dna_error_2_cm": 6.5}  # Zhou et al. 2020, Eqs. 11-12


def goals(report: dict) -> list[dict]:
    """Issue 13's goal: the DNA errors of Eqs. 11-12 at most the paper's (only for a model with Motion DNA)."""
    if "dna_error_1_cm" not in report:
        return []
    e1, e2 = report["dna_error_1_cm"], report["dna_error_2_cm"]
    p1, p2 = PAPER["dna_error_1_cm"], PAPER["dna_error_2_cm"]
    return [results.goal(13, f"Motion DNA errors at most the paper's (Eqs. 11-12: {p1} and {p2} cm)",
                         f"{e1:.2f} and {e2:.2f} cm ({e1 / p1:.2f}x, {e2 / p2:.2f}x)", e1 <= p1 and e2 <= p2)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="a full gan model folder (trained with --dna --partial-keys for every figure)")
    ap.add_argument("--data", default=None, help="BVH folder (default: Bandai-Namco dataset-2)")
    ap.add_argument("--test-pattern", default="*_normal_*", help="held-out clips (file-name pattern)")
    ap.add_argument("--sequences", type=int, default=50, help="key layouts scored")
    ap.add_argument("--frames", type=int, default=None, help="frames per sequence (default: the model's)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true", help="print the record as JSON")
    results.add_option(ap)
    args = ap.parse_args(argv)
    try:
        data = args.data or str(locate("bandai2"))
    except DataError as e:
        print(f"skipped: {e}")
        return 0
    print(f"load average before: {os.getloadavg()[0]:.2f}", file=sys.stderr)
    bench = results.Run()
    model = load_model(args.model)
    corpus = load_corpus([data], fold=model.folded).select(include=(args.test_pattern,))
    report = quality_report(model, corpus, range(len(corpus)), args.sequences, args.frames, args.seed)
    print(f"load average after: {os.getloadavg()[0]:.2f}", file=sys.stderr)
    figures = {**report, "model": args.model, "paper": PAPER}
    record = bench.record(f"gan_dna-{Path(args.model).name}", figures, goals(report), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0

    def cm(v):
        return "-" if v is None else f"{v:.1f}"

    print(f"{report['sequences']} sequences of {report['frames']} frames over {report['clips']} held-out clips")
    if "dna_error_1_cm" in report:
        print(f"DNA errors (cm): Eq. 11 {cm(report['dna_error_1_cm'])} (paper 8.4), "
              f"Eq. 12 {cm(report['dna_error_2_cm'])} (paper 6.5)")
    print("key errors (cm)   joints   root")
    for kind, e in report["key_errors"].items():
        print(f"  {kind:<15} {cm(e['joints_cm']):>6} {cm(e['root_cm']):>6}")
    v = report["variety_cm"]
    print(f"variety (cm): 4 DNAs {cm(v.get('dnas'))}, 4 noise seeds {cm(v['seeds'])}")
    if "dna_pull_cm" in report:
        pull = report["dna_pull_cm"]
        print(f"DNA pull (cm): Eq. 11 error to the DNA given {cm(pull['own'])}, to another {cm(pull['other'])}")
    results.print_goals(record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
