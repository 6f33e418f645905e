"""The gan on a matched base (issue 45) as a generator: realism per seed, variety, best-of-5, Motion DNA's pull,
speed; against cubic, match alone, the shipped gan (on the spline) and the shipped transformer.

Held-out clips as ``bench_match.py`` (6 s clips of dataset-2 ``normal`` and of dataset-1 ``sad`` / ``feminine``,
styles no gan corpus holds), keys every 60 and every 120 frames, feet free and the guard off for every method
so that each is scored as it fills
(``--feet lock``: the gan on a matched base and match with their feet locked, the default of both, the record
``gan_match-<model>-lock``). Per method: foot skating (cm/s, against the true clip's floor), jitter
(m/s^3), gap error (cm) and whether the keys are exact; for the gan on a matched base (``MODEL``), each of the
seeds 0-4, the mean pairwise distance of their in-betweens (cm, variety) and the best of the five gap errors
per clip, averaged. Motion DNA (keys every 60): each clip completed with the DNA of a run and of a wave
(``--dna``, held-out ``normal`` clips of dataset-2): the Eq. 11 error of each in-between to the DNA it was given
and to the other (mean over the DNA's poses of the nearest in-between frame's mean joint distance, cm), and how
far changing the DNA moves the in-between against how far changing the seed (0 to 1) does, and the gap error
with a DNA. Speed: 2,048 frames
keyed every 120 on one CPU thread, library search included (median of 5, warm). The shipped transformer
fills gaps of at most 63 frames: it is scored at keys every 60 only.

    .venv/bin/python benchmarks/bench_gan_match.py data/models/bandai2-gan-match          # --clips 24 per set
    .venv/bin/python benchmarks/bench_gan_match.py data/models/bandai2-gan-match --clips 4 --no-record

Without the corpora it says ``skipped`` and exits 0. The run is recorded in
``benchmarks/results/gan_match-<model folder>.json``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import results
from bench_match import figures_of, keys_every, quality, run_method, seed_figures, style_sets, world

from keyfill import io
from keyfill.errors import DataError
from keyfill.learn import registry, rig_bridge
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.corpus import locate, model_hierarchy
from keyfill.learn.gan.dna import dna_poses
from keyfill.learn.gan.model import load_model
from keyfill.learn.representative import root_free_poses
from keyfill.motion import Motion

SETS = ("normal (dataset-2)", "sad, feminine (dataset-1)")
GAPS = (60, 120)
BASELINES = ("cubic", "match raw", "gan", "transformer")


def match_name(feet: str) -> str:
    """The baseline the gan on a matched base is held to: match raw, or match locked with ``--feet lock``."""
    return "match raw" if feet == "free" else "match"
DNAS = {"run": "dataset-2_run_normal_001.bvh", "wave": "dataset-2_wave-both-hands_normal_001.bvh"}


def gan_match(model: str, m: Motion, keys, seed: int = 0, dna: str | None = None, feet: str = "free") -> Motion:
    return registry.complete(m, keys, "gan", CompleteOptions(model=model, seed=seed, feet=feet, guard="off",
                                                             dna=dna)).motion


def baseline(method: str, m: Motion, keys) -> Motion:
    if method in ("gan", "transformer"):
        return registry.complete(m, keys, method, CompleteOptions(feet="free", guard="off")).motion
    return run_method(method, m, keys).motion


def generator_figures(model: str, sets: dict[str, list[Motion]], feet: str) -> dict:
    """Per set: the real clips' figures, and per key spacing the baselines' summaries (:func:`bench_match.quality`)
    with each seed's (``seeds``), ``pairwise_cm`` and ``best_of_5_cm`` (:func:`bench_match.seed_figures`)."""
    out = {}
    for gap in GAPS:
        methods = [match_name(feet) if b == "match raw" else b for b in BASELINES
                   if b != "transformer" or gap <= 60]  # the transformer's gaps: at most 63 frames
        base = quality(sets, methods, baseline, gaps=(gap,))
        for name in SETS:
            row = base[name][str(gap)]
            v = seed_figures(sets[name], gap, lambda m, keys, s: gan_match(model, m, keys, s, feet=feet))
            row.update(seeds=v["seeds"], pairwise_cm=v["pairwise_cm"], best_of_5_cm=v["best_of_5_gap_error_cm"])
            out.setdefault(name, {"real": base[name]["real"]})[str(gap)] = row
            print(f"{name}, keys every {gap}: " + "; ".join(
                f"seed {s} {r['foot_skating_cm_s']:.1f}/{r['jitter_m_s3']:.0f}/{r['gap_error_cm']:.2f}"
                for s, r in row["seeds"].items()) + f"; pairwise {row['pairwise_cm']:.1f} cm, best of 5 "
                f"{row['best_of_5_cm']:.2f} cm", flush=True)
    return out


def dna_figures(model_path: str, sets: dict[str, list[Motion]], feet: str) -> dict:
    """Per set, keys every 60: the Eq. 11 errors to the DNA given and to the other, and the DNA's and the
    seed's effect on the in-between (mean joint distance, cm)."""
    model = load_model(model_path)
    served = rig_bridge.Served(model.skeleton, model.fps, model.folded)
    folder = locate("bandai2")
    files = {k: next(folder.rglob(v)) for k, v in DNAS.items()}
    sources = {k: rig_bridge.on_model_skeleton(io.load(f), served, what="the DNA motion") for k, f in files.items()}
    m_per_unit = model.skeleton.meters_per_unit
    offsets = model.skeleton.offsets * m_per_unit

    def poses(motion: Motion, frames) -> np.ndarray:
        q, _ = model_hierarchy(model.skeleton, model.folded, motion.skeleton, motion.rotations[frames],
                               motion.positions[frames])
        return root_free_poses(q, offsets, model.skeleton.parents)

    def eq11(p: np.ndarray, dna: np.ndarray) -> float:  # cm
        d = np.linalg.norm(p[:, None] - dna[None], axis=-1).mean(-1)  # (T, P)
        return float(d.min(0).mean() * 100)

    out = {}
    for name in SETS:
        own, other, by_dna, by_seed, errors = [], [], [], [], []
        for m in sets[name]:
            keys = keys_every(m, 60)
            between = np.setdiff1d(np.arange(m.num_frames), keys.frames)
            done = {k: gan_match(model_path, m, keys, 0, str(f), feet) for k, f in files.items()}
            for k, filled in done.items():
                errors.append(figures_of(m, keys, filled)["error"])
                dna = dna_poses(model, sources[k], key_frames=keys.frames)
                o = "wave" if k == "run" else "run"
                p = poses(filled, between)
                own.append(eq11(p, dna))
                other.append(eq11(p, dna_poses(model, sources[o], key_frames=keys.frames)))
            w = {k: world(v)[between] for k, v in done.items()}
            by_dna.append(np.linalg.norm(w["run"] - w["wave"], axis=-1).mean() * m_per_unit * 100)
            s0, s1 = (world(gan_match(model_path, m, keys, s, feet=feet))[between] for s in (0, 1))
            by_seed.append(np.linalg.norm(s0 - s1, axis=-1).mean() * m_per_unit * 100)
        out[name] = {"eq11_own_cm": float(np.mean(own)), "eq11_other_cm": float(np.mean(other)),
                     "dna_change_cm": float(np.mean(by_dna)), "seed_change_cm": float(np.mean(by_seed)),
                     "gap_error_cm": float(np.mean(errors))}
        f = out[name]
        print(f"DNA {name}: Eq. 11 own {f['eq11_own_cm']:.2f} cm, other {f['eq11_other_cm']:.2f} cm; "
              f"DNA change {f['dna_change_cm']:.2f} cm, seed change {f['seed_change_cm']:.2f} cm; gap error "
              f"{f['gap_error_cm']:.2f} cm", flush=True)
    return out


def speed(model: str, clip: Motion, feet: str, repeat: int = 5) -> dict:
    import torch

    torch.set_num_threads(1)
    long = Motion(clip.skeleton, clip.fps, np.concatenate([clip.rotations] * 12)[:2048],
                  np.concatenate([clip.positions] * 12)[:2048])
    keys = keys_every(long, 120)
    gan_match(model, long, keys, feet=feet)  # warm: the model and the library loaded once
    runs = []
    for _ in range(repeat):
        t = time.perf_counter()
        gan_match(model, long, keys, feet=feet)
        runs.append(time.perf_counter() - t)
    return {"frames": 2048, "key_every": 120, "threads": 1, "median_s": statistics.median(runs), "runs": runs}


def goals(f: dict) -> list[dict]:
    """Issue 45's goals on the figures, one line per goal with both held-out sets (``normal`` / ``sad, feminine``)."""
    per_set = {name: [(s, f["quality"][name][str(gap)]) for gap in GAPS for s in f["quality"][name][str(gap)]["seeds"].values()]
               for name in SETS}
    real = {name: f["quality"][name]["real"] for name in SETS}

    def each(fn):
        return [fn(name) for name in SETS]

    sk = each(lambda n: max(s["foot_skating_cm_s"] for s, _ in per_set[n]) / real[n]["foot_skating_cm_s"])
    ji = each(lambda n: [s["jitter_m_s3"] / real[n]["jitter_m_s3"] for s, _ in per_set[n]])
    vs_match = each(lambda n: max(s["gap_error_cm"] / r[f["match"]]["gap_error_cm"] for s, r in per_set[n]))
    vs_cubic = each(lambda n: max(s["gap_error_cm"] / r["cubic"]["gap_error_cm"] for s, r in per_set[n]))
    exact = all(s["keys_exact"] for n in SETS for s, _ in per_set[n])
    r60 = each(lambda n: f["quality"][n]["60"])
    d = each(lambda n: f["dna"][n])
    both = "normal / sad, feminine"
    sp = f["speed"]
    return [
        results.goal(45, "every seed, keys every 60 and 120: foot skating at most 1.5x the real clips'",
                     f"at most {' / '.join(f'{x:.2f}x' for x in sk)} ({both})", max(sk) <= 1.5),
        results.goal(45, "every seed: jitter 0.67x-1.5x the real clips'",
                     " / ".join(f"{min(x):.2f}x-{max(x):.2f}x" for x in ji) + f" ({both})",
                     min(min(x) for x in ji) >= 0.67 and max(max(x) for x in ji) <= 1.5),
        results.goal(45, "every seed: gap error at most match's (seed 0) and below cubic's",
                     " / ".join(f"{a:.2f}x match's, {b:.2f}x cubic's" for a, b in zip(vs_match, vs_cubic))
                     + f" (worst seed; {both})", max(vs_match) <= 1 and max(vs_cubic) < 1),
        results.goal(45, "keys exact, every seed and set", str(exact), exact),
        results.goal(45, "keys every 60: 5 seeds at least 5 cm apart (mean pairwise distance)",
                     " / ".join(f"{r['pairwise_cm']:.1f} cm" for r in r60) + f" ({both})",
                     min(r["pairwise_cm"] for r in r60) >= 5),
        results.goal(45, "keys every 60: best-of-5 gap error below the shipped transformer's",
                     " / ".join(f"{r['best_of_5_cm']:.2f} against {r['transformer']['gap_error_cm']:.2f} cm" for r in r60)
                     + f" ({both})", all(r["best_of_5_cm"] < r["transformer"]["gap_error_cm"] for r in r60)),
        results.goal(45, "Eq. 11 error to the DNA given at least 30 % below the other DNA's (a run, a wave)",
                     " / ".join(f"{1 - x['eq11_own_cm'] / x['eq11_other_cm']:.0%} lower" for x in d) + f" ({both})",
                     all(x["eq11_own_cm"] <= 0.7 * x["eq11_other_cm"] for x in d)),
        results.goal(45, "changing the DNA moves the in-between at least as far as changing the seed",
                     " / ".join(f"{x['dna_change_cm']:.2f} against {x['seed_change_cm']:.2f} cm" for x in d)
                     + f" ({both})", all(x["dna_change_cm"] >= x["seed_change_cm"] for x in d)),
        results.goal(45, "2,048 frames keyed every 120 in at most 0.3 s on one thread, library search included",
                     f"{sp['median_s']:.3f} s", sp["median_s"] <= 0.3),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("model", help="a gan model folder on a matched base")
    ap.add_argument("--clips", type=int, default=24, help="clips per style set (default 24)")
    ap.add_argument("--feet", choices=("free", "lock"), default="free",
                    help="the gan on a matched base and match raw (free, the default) or locked")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    try:
        sets = style_sets(args.clips)
    except DataError as e:
        print(f"skipped: {e}")
        return 0
    held_out = {k: sets[k] for k in SETS}
    figures = {"clips": {k: len(v) for k, v in held_out.items()}, "model": Path(args.model).name,
               "feet": args.feet, "match": match_name(args.feet),
               "quality": generator_figures(args.model, held_out, args.feet),
               "dna": dna_figures(args.model, held_out, args.feet), "speed": speed(args.model, held_out[SETS[0]][0], args.feet)}
    suffix = "" if args.feet == "free" else "-lock"
    record = bench.record(f"gan_match-{Path(args.model).name}{suffix}", figures, goals(figures), write=not args.no_record)
    results.print_goals(record)
    print(results.summary(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
