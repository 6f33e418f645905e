"""Feet on the ground: foot skating, jitter and gap error of every method, raw and with its feet locked.

Held-out clips of styles no shipped model saw: ``normal`` of Bandai-Namco dataset-2 (held out of every
shipped human model) and, from dataset-1 (another capture of the same skeleton, none of it trained on),
``sad`` and ``feminine``; clips of at least 6 s, cut to 6 s. Keys every 30 and every 60 frames (30 fps); linear,
cubic, the shipped transformer (keys every 30 only: its window holds gaps up to 63 frames) and the shipped
gan, each raw (``feet="free"``) and locked (``feet="lock"``, :func:`keyfill.characters.feet.lock_feet`)::

    .venv/bin/python benchmarks/bench_feet.py                  # --clips 8 per style set
    .venv/bin/python benchmarks/bench_feet.py --clips 2 --no-record
    .venv/bin/python benchmarks/bench_feet.py --transformer data/models/bandai-transformer-3   # a candidate

Per style set, method, layout and raw/locked: foot skating (cm/s, :func:`keyfill.learn.protocols.metrics.foot_skating`:
foot and toe joints within 2.5 cm of the ground truth's floor), jitter (m/s^3, the third difference of world
positions) and gap error (cm, the mean world position error over non-key frames), against the real clips'
skating and jitter; whether the keys are bit-identical and the bone lengths exact; the share of between-key
joint rotations outside the gan's ranges (raw and locked: locking must add none); and the time of
``lock_feet`` against a gan completion of 2,048 frames. Without the corpora the script says ``skipped`` and
exits 0. The run is recorded in ``benchmarks/results/feet.json`` (``results.py``; not with ``--no-record``).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import results

from keyfill import io
from keyfill.characters.feet import lock_feet
from keyfill.characters.retarget import make_rig
from keyfill.errors import DataError
from keyfill.kinematics import fk
from keyfill.learn import registry
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.corpus import fold_root, locate
from keyfill.learn.gan.model import DEFAULT_MODEL, load
from keyfill.learn.gan.ranges import inside
from keyfill.learn.modelfile import load_cached
from keyfill.learn.protocols.metrics import foot_joints, foot_skating, jitter
from keyfill.motion import Keys, Motion

SECONDS = 6
METHODS = ("linear", "cubic", "transformer", "gan")
GAPS = (30, 60)
RANGE_TOLERANCE = 1.1e-4  # radians: as bench_gan_quality.py, the float noise of zero-width ranges


def style_sets(count: int) -> dict[str, list[Motion]]:
    """Held-out clips by style set: ``count`` each, at least ``SECONDS`` long, cut to it."""
    def pick(folder, patterns):
        files = sorted(f for p in patterns for f in Path(folder).rglob(p))
        out = []
        for f in files:
            m = io.load(f)
            if m.num_frames >= SECONDS * m.fps:
                out.append(m.frames(slice(0, int(SECONDS * m.fps))).replace(keys=None))
        if not out:
            raise DataError(f"no clip of {', '.join(patterns)} under {folder} lasts {SECONDS} s")
        return [out[i] for i in np.unique(np.linspace(0, len(out) - 1, count).round().astype(int))]

    return {"normal (dataset-2)": pick(locate("bandai2"), ["*_normal_*.bvh"]),
            "sad, feminine (dataset-1)": pick(locate("bandai1"), ["*_sad_*.bvh", "*_feminine_*.bvh"])}


def world(m: Motion) -> np.ndarray:
    return fk(m.rotations, m.positions, m.skeleton.parents)[1]


def bone_error(out: Motion, truth: Motion) -> float:
    """Largest difference of a bone's length (a joint's distance to its parent) between ``out`` and ``truth``,
    in units, over the bones whose length the skeleton fixes (not the hips' translation from its parent)."""
    p, q = world(out), world(truth)
    par = out.skeleton.parents
    moving = np.ptp(truth.positions, axis=0).max(axis=-1) > 1e-9  # joints translated by the motion
    kids = np.flatnonzero((par >= 0) & ~moving)
    a = np.linalg.norm(p[:, kids] - p[:, par[kids]], axis=-1)
    b = np.linalg.norm(q[:, kids] - q[:, par[kids]], axis=-1)
    return float(np.abs(a - b).max())


def scores(sets: dict[str, list[Motion]], transformer: str | None = None) -> dict:
    """``{set: {gap: {method: {raw|locked: {...}}, "real": {...}}}}`` (see the module docstring); ``transformer``:
    a model folder to score instead of the shipped transformer."""
    gan = load_cached(load, DEFAULT_MODEL, "cpu")
    out = {}
    for name, clips in sets.items():
        sk = clips[0].skeleton
        feet, fps, mpu = foot_joints(sk), clips[0].fps, sk.meters_per_unit
        for gap in GAPS:
            real = [world(m) for m in clips]
            row = {"real": {"foot_skating_cm_s": float(np.nanmean([foot_skating(w[None], feet, sk.up_axis, fps, mpu)
                                                                   for w in real])),
                            "jitter_m_s3": float(np.mean([jitter(w[None], fps, mpu) for w in real]))}}
            for method in METHODS:
                if method == "transformer" and gap > 63:
                    continue
                for variant in ("free", "lock"):
                    skate, jit, err, exact, bones, outside = [], [], [], True, 0.0, []
                    for m, w in zip(clips, real):
                        keys = Keys(np.unique(np.r_[np.arange(0, m.num_frames, gap), m.num_frames - 1]))
                        options = CompleteOptions(feet=variant, model=transformer if method == "transformer" else None)
                        filled = registry.complete(m, keys, method, options).motion
                        p = world(filled)
                        skate.append(foot_skating(p[None], feet, sk.up_axis, fps, mpu, reference=w[None]))
                        jit.append(jitter(p[None], fps, mpu))
                        between = np.setdiff1d(np.arange(m.num_frames), keys.frames)
                        err.append(float(np.linalg.norm(p[between] - w[between], axis=-1).mean() * mpu * 100))
                        k = keys.frames
                        exact &= bool(np.array_equal(filled.rotations[k], m.rotations[k])
                                      and np.array_equal(filled.positions[k], m.positions[k]))
                        bones = max(bones, bone_error(filled, m))
                        rot, _ = fold_root(filled.rotations[between], filled.positions[between], sk.parents)
                        outside.append((~inside(gan.ranges, rot, RANGE_TOLERANCE)).mean())
                    row.setdefault(method, {})["raw" if variant == "free" else "locked"] = {
                        "foot_skating_cm_s": float(np.nanmean(skate)), "jitter_m_s3": float(np.mean(jit)),
                        "gap_error_cm": float(np.mean(err)), "keys_exact": exact, "bone_error": bones,
                        "range_violations_pct": float(100 * np.mean(outside))}
            out.setdefault(name, {})[str(gap)] = row
            print(f"{name}, keys every {gap}: " + "; ".join(
                f"{m} " + " / ".join(f"{v}: skate {r['foot_skating_cm_s']:.1f} jitter {r['jitter_m_s3']:.0f} "
                                     f"gap {r['gap_error_cm']:.2f}" for v, r in row[m].items())
                for m in row if m != "real") + f"; real skate {row['real']['foot_skating_cm_s']:.1f} "
                f"jitter {row['real']['jitter_m_s3']:.0f}", flush=True)
    return out


def speed(clip: Motion, repeat: int = 5) -> dict:
    """``lock_feet`` against the gan completion it cleans: 2,048 frames (the clip tiled), keys every 60."""
    reps = -(-2048 // clip.num_frames)
    rot = np.concatenate([clip.rotations] * reps)[:2048]
    pos = np.concatenate([clip.positions] * reps)[:2048]
    m = Motion(clip.skeleton, clip.fps, rot, pos)
    keys = Keys(np.unique(np.r_[np.arange(0, 2048, 60), 2047]))
    rig = make_rig(m.skeleton)
    raw = registry.complete(m, keys, "gan", CompleteOptions(feet="free")).motion  # loads the model
    complete_s, lock_s = [], []
    for _ in range(repeat):
        t = time.perf_counter()
        raw = registry.complete(m, keys, "gan", CompleteOptions(feet="free")).motion
        complete_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        lock_feet(raw, rig, keys)
        lock_s.append(time.perf_counter() - t)
    c, lk = statistics.median(complete_s), statistics.median(lock_s)
    return {"frames": 2048, "joints": m.num_joints, "complete_s": c, "lock_s": lk, "share": lk / c}


def goals(f: dict) -> list[dict]:
    """Issue 33's goals, each over both style sets and both layouts (the worst case is the figure)."""
    rows = [g for s in f["scores"].values() for g in s.values()]

    def worst(method, value, variants=("locked",)):
        return max(g[method][v][value] / g["real"][value] for g in rows if method in g for v in variants)

    skate = {m: worst(m, "foot_skating_cm_s") for m in ("transformer", "gan", "cubic")}
    jit = {m: worst(m, "jitter_m_s3", ("raw", "locked")) for m in ("transformer", "gan")}
    gap = max(g[m]["locked"]["gap_error_cm"] / g[m]["raw"]["gap_error_cm"] for g in rows for m in g if m != "real")
    exact = all(g[m][v]["keys_exact"] for g in rows for m in g if m != "real" for v in ("raw", "locked"))
    new = max(g[m]["locked"]["range_violations_pct"] - g[m]["raw"]["range_violations_pct"]
              for g in rows for m in g if m != "real")
    bones = max(g[m]["locked"]["bone_error"] for g in rows for m in g if m != "real")
    share = f["speed"]["share"]
    return [
        results.goal(33, "locked feet: foot skating at most 1.5x the real clips' (transformer, gan, cubic)",
                     ", ".join(f"{m} {v:.2f}x" for m, v in skate.items()) + " (worst set and layout)",
                     max(skate.values()) <= 1.5),
        results.goal(33, "jitter at most 1.5x the real clips' (transformer, gan; raw and locked)",
                     ", ".join(f"{m} {v:.2f}x" for m, v in jit.items()) + " (worst)", max(jit.values()) <= 1.5),
        results.goal(33, "locking costs nothing else: gap error at most 1.02x the raw output's, keys and bone "
                         "lengths exact, no new joint-range violations (every method)",
                     f"gap error {gap:.3f}x (worst), keys {'bit-identical' if exact else 'NOT exact'}, bones within "
                     f"{bones:.1e} units, {new:+.3f} % of rotations newly outside the gan's ranges",
                     gap <= 1.02 and exact and bones < 1e-6 and new <= 0.0),
        results.goal(33, "locking takes at most 10 % of the completion it cleans (2,048 frames, 22 joints)",
                     f"{100 * share:.1f} %", share <= 0.10),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=8, help="clips per style set (default 8)")
    ap.add_argument("--transformer", metavar="MODEL", help="score this transformer model folder instead of the "
                    "shipped one (a candidate; not recorded: the records describe the shipped models)")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    try:
        sets = style_sets(args.clips)
    except DataError as e:
        print(f"skipped: {e}")
        return 0
    figures = {"clips": {k: len(v) for k, v in sets.items()}, "seconds": SECONDS, "scores": scores(sets, args.transformer),
               "speed": speed(next(iter(sets.values()))[0])}
    record = bench.record("feet", figures, goals(figures), write=not args.no_record and args.transformer is None)
    print(f"speed: {figures['speed']}")
    results.print_goals(record)
    print(results.summary(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
