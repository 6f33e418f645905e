"""In-betweens matched from real motion (``--method match``) against the spline and the shipped models, the
guard, and the speed of the library.

Held-out clips (docs/match.md), none of them in the shipped library or any shipped model's corpus:

* ``normal (dataset-2)``: clips of the ``normal`` style of Bandai-Namco dataset-2 (every action: walks, runs,
  turns, waves, hand raises), at least 6 s, cut to 6 s;
* ``sad, feminine (dataset-1)``: dataset-1's ``sad`` and ``feminine`` styles (another capture, more actions);
* ``gestures (dataset-2)``: the ``normal`` wave and hand-raise clips (standing gestures);
* ``unknown actions (dataset-1)``: dataset-1's call, dance, kick, punch, respond and slash clips (style
  ``normal``): actions no shipped corpus or library holds, whole, for the guard.

Keys every 30 and every 60 frames (30 fps). For each set and layout, per method (cubic, the shipped
transformer and gan, match raw and match with its default feet): foot skating (cm/s,
:func:`keyfill.learn.protocols.metrics.foot_skating` against the true clip's floor), jitter (m/s^3), gap error
(cm: mean world joint position error over non-key frames) and whether the keys are bit-identical. Variety:
match with seeds 0-4 at keys every 60, the mean pairwise distance between the seeds' in-betweens (cm) and each
seed's figures. Guard: on the unknown actions, each method's gap error with ``guard="off"`` and with the
default fallback against cubic's, and the share of gaps it flagged; on the known held-out clips, the share of
gaps the guard changed and the change of gap error. Speed: one gap's library search (median of the gaps of
the normal set), 2,048 frames with keys every 60 through ``registry.complete`` (warm; and cold, a fresh
``keyfill complete`` process), the loaded library's resident memory, and (``--build``) building the library
of all of dataset-2 with 2 workers.

    .venv/bin/python benchmarks/bench_match.py                  # --clips 24 per set
    .venv/bin/python benchmarks/bench_match.py --clips 4 --no-record
    .venv/bin/python benchmarks/bench_match.py --build          # also the build time of dataset-2

Without the corpora it says ``skipped`` and exits 0. The run is recorded in ``benchmarks/results/match.json``.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import results

from keyfill import interpolate, io
from keyfill.errors import DataError
from keyfill.kinematics import fk
from keyfill.learn import registry
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.corpus import locate
from keyfill.learn.protocols.metrics import foot_joints, foot_skating, jitter
from keyfill.motion import Keys, Motion

SECONDS = 6
GAPS = (30, 60)
METHODS = ("cubic", "transformer", "gan", "match raw", "match")
UNKNOWN = ("call", "dance-short", "kick", "punch", "respond", "slash")
SEEDS = 5


def _clips(folder: Path, patterns: list[str], count: int | None, seconds: float | None = SECONDS) -> list[Motion]:
    files = sorted({f for p in patterns for f in folder.rglob(p)})
    out = []
    for f in files:
        m = io.load(f).replace(keys=None)
        if seconds is None:
            out.append(m)
        elif m.num_frames >= seconds * m.fps:
            out.append(m.frames(slice(0, int(seconds * m.fps))))
    if not out:
        raise DataError(f"no clip of {', '.join(patterns)} under {folder}")
    if count is None:
        return out
    return [out[i] for i in np.unique(np.linspace(0, len(out) - 1, count).round().astype(int))]


def style_sets(count: int) -> dict[str, list[Motion]]:
    d2, d1 = locate("bandai2"), locate("bandai1")
    return {"normal (dataset-2)": _clips(d2, ["*_normal_*.bvh"], count),
            "sad, feminine (dataset-1)": _clips(d1, ["*_sad_*.bvh", "*_feminine_*.bvh"], count),
            "gestures (dataset-2)": _clips(d2, ["*_wave-*_normal_*.bvh", "*_raise-up-*_normal_*.bvh"], count)}


def unknown_actions() -> list[Motion]:
    return _clips(locate("bandai1"), [f"dataset-1_{a}_*.bvh" for a in UNKNOWN], None, None)


def keys_every(m: Motion, gap: int) -> Keys:
    return Keys(np.unique(np.r_[np.arange(0, m.num_frames, gap), m.num_frames - 1]))


def world(m: Motion) -> np.ndarray:
    return fk(m.rotations, m.positions, m.skeleton.parents)[1]


def run_method(method: str, m: Motion, keys: Keys, seed: int = 0, guard: str | None = "off",
               library: str | None = None):
    if method == "cubic":
        return registry.complete(m, keys, "cubic")
    name, feet = ("match", "free") if method == "match raw" else (method, None)
    options = CompleteOptions(seed=seed, feet=feet, guard=guard, library=library if name == "match" else None)
    return registry.complete(m, keys, name, options)


def figures_of(m: Motion, keys: Keys, out: Motion) -> dict:
    sk = m.skeleton
    truth, p = world(m), world(out)
    between = np.setdiff1d(np.arange(m.num_frames), keys.frames)
    k = keys.frames
    return {"skating": foot_skating(p[None], foot_joints(sk), sk.up_axis, m.fps, sk.meters_per_unit,
                                    reference=truth[None]),
            "jitter": jitter(p[None], m.fps, sk.meters_per_unit),
            "error": float(np.linalg.norm(p[between] - truth[between], axis=-1).mean() * sk.meters_per_unit * 100),
            "exact": bool(np.array_equal(out.rotations[k], m.rotations[k])
                          and np.array_equal(out.positions[k], m.positions[k]))}


def summary(rows: list[dict]) -> dict:
    return {"foot_skating_cm_s": float(np.nanmean([r["skating"] for r in rows])),
            "jitter_m_s3": float(np.mean([r["jitter"] for r in rows])),
            "gap_error_cm": float(np.mean([r["error"] for r in rows])),
            "keys_exact": all(r["exact"] for r in rows)}


def quality(sets: dict[str, list[Motion]], methods=METHODS, fill=None, gaps=GAPS) -> dict:
    """Per set: the real clips' skating and jitter, and per key spacing of ``gaps`` and method the summary of its
    fills; ``fill(method, motion, keys) -> Motion`` (default: :func:`run_method`'s motion)."""
    fill = fill or (lambda method, m, keys: run_method(method, m, keys).motion)
    out = {}
    for name, clips in sets.items():
        sk = clips[0].skeleton
        real = [world(m) for m in clips]
        out[name] = {"real": {
            "foot_skating_cm_s": float(np.nanmean([foot_skating(w[None], foot_joints(sk), sk.up_axis, m.fps,
                                                                sk.meters_per_unit) for w, m in zip(real, clips)])),
            "jitter_m_s3": float(np.mean([jitter(w[None], m.fps, sk.meters_per_unit) for w, m in zip(real, clips)]))}}
        for gap in gaps:
            row = {}
            for method in methods:
                row[method] = summary([figures_of(m, keys_every(m, gap), fill(method, m, keys_every(m, gap)))
                                       for m in clips])
            out[name][str(gap)] = row
            print(f"{name}, keys every {gap}: " + "; ".join(
                f"{k} {v['foot_skating_cm_s']:.1f}/{v['jitter_m_s3']:.0f}/{v['gap_error_cm']:.2f}"
                for k, v in row.items()) + f" (real {out[name]['real']['foot_skating_cm_s']:.1f}/"
                f"{out[name]['real']['jitter_m_s3']:.0f})", flush=True)
    return out


def seed_figures(clips: list[Motion], gap: int, fill) -> dict:
    """``fill(motion, keys, seed) -> Motion`` for seeds 0 to ``SEEDS - 1`` on ``clips`` keyed every ``gap``: each
    seed's summary (``seeds``), the mean pairwise distance of the seeds' in-betweens (``pairwise_cm``) and the mean
    over clips of the best seed's gap error (``best_of_5_gap_error_cm``)."""
    per_seed = {s: [] for s in range(SEEDS)}
    distances = []
    for m in clips:
        keys = keys_every(m, gap)
        between = np.setdiff1d(np.arange(m.num_frames), keys.frames)
        outs = []
        for s in range(SEEDS):
            filled = fill(m, keys, s)
            per_seed[s].append(figures_of(m, keys, filled))
            outs.append(world(filled)[between])
        mpu = m.skeleton.meters_per_unit
        distances.append(np.mean([np.linalg.norm(outs[a] - outs[b], axis=-1).mean() * mpu * 100
                                  for a in range(SEEDS) for b in range(a + 1, SEEDS)]))
    best = float(np.mean([min(per_seed[s][i]["error"] for s in range(SEEDS)) for i in range(len(clips))]))
    return {"pairwise_cm": float(np.mean(distances)), "seeds": {str(s): summary(r) for s, r in per_seed.items()},
            "best_of_5_gap_error_cm": best}


def variety(sets: dict[str, list[Motion]], gap: int = 60) -> dict:
    out = {}
    for name in ("normal (dataset-2)", "sad, feminine (dataset-1)"):
        out[name] = v = seed_figures(sets[name], gap, lambda m, keys, s: run_method("match", m, keys, seed=s).motion)
        print(f"variety {name}: pairwise {v['pairwise_cm']:.1f} cm, best-of-5 {v['best_of_5_gap_error_cm']:.2f} cm; "
              + "; ".join(f"seed {s} {r['foot_skating_cm_s']:.1f}/{r['jitter_m_s3']:.0f}/{r['gap_error_cm']:.2f}"
                          for s, r in v["seeds"].items()), flush=True)
    return out


def guard_figures(known: list[Motion], unknown: list[Motion]) -> dict:
    out = {"unknown": {}, "known": {}}
    for gap in GAPS:
        for method in ("transformer", "gan", "match"):
            rows_off, rows_on, flagged, total = [], [], 0, 0
            for m in unknown:
                keys = keys_every(m, gap)
                rows_off.append(figures_of(m, keys, run_method(method, m, keys, guard="off").motion))
                guarded = run_method(method, m, keys, guard=None)
                rows_on.append(figures_of(m, keys, guarded.motion))
                block = guarded.info.get("guard") or {}
                flagged += block.get("unfamiliar", 0)
                total += block.get("gaps_scored", len(keys) - 1)
            cubic = [figures_of(m, keys_every(m, gap), interpolate.cubic(m, keys_every(m, gap))) for m in unknown]
            c = summary(cubic)["gap_error_cm"]
            out["unknown"].setdefault(str(gap), {})[method] = {
                "cubic_gap_error_cm": c, "off_gap_error_cm": summary(rows_off)["gap_error_cm"],
                "guard_gap_error_cm": summary(rows_on)["gap_error_cm"], "flagged_pct": 100.0 * flagged / total}
            changed, total, off_err, on_err = 0, 0, [], []
            for m in known:
                keys = keys_every(m, gap)
                guarded = run_method(method, m, keys, guard=None)
                block = guarded.info.get("guard") or {}
                changed += block.get("unfamiliar", 0)
                total += block.get("gaps_scored", len(keys) - 1)
                on_err.append(figures_of(m, keys, guarded.motion)["error"])
                off_err.append(figures_of(m, keys, run_method(method, m, keys, guard="off").motion)["error"])
            out["known"].setdefault(str(gap), {})[method] = {
                "changed_pct": 100.0 * changed / total,
                "gap_error_change_pct": 100.0 * (np.mean(on_err) / np.mean(off_err) - 1)}
            u, k = out["unknown"][str(gap)][method], out["known"][str(gap)][method]
            print(f"guard, keys every {gap}, {method}: unknown actions {u['off_gap_error_cm']:.2f} -> "
                  f"{u['guard_gap_error_cm']:.2f} cm (cubic {c:.2f}, {u['flagged_pct']:.0f} % of gaps); known: "
                  f"{k['changed_pct']:.1f} % of gaps changed, error {k['gap_error_change_pct']:+.1f} %", flush=True)
    return out


def speed(clip: Motion, repeat: int = 5) -> dict:
    from keyfill.learn.library.search import candidates
    from keyfill.learn.match.model import DEFAULT_MODEL, load

    matcher = load(DEFAULT_MODEL).matcher
    long = Motion(clip.skeleton, clip.fps, np.concatenate([clip.rotations] * 12)[:2048],
                  np.concatenate([clip.positions] * 12)[:2048])
    keys = keys_every(long, 60)
    gaps = matcher.gaps(long, keys)
    per_gap = []
    for g in gaps:
        t = time.perf_counter()
        candidates(matcher.library, matcher.tree, [g])
        per_gap.append(time.perf_counter() - t)
    warm = []
    for _ in range(repeat):
        t = time.perf_counter()
        registry.complete(long, keys, "match")
        warm.append(time.perf_counter() - t)
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "long.bvh", Path(tmp) / "out.bvh"
        io.save(long, src)
        keyfill = Path(sys.executable).with_name("keyfill")
        cold = []
        for _ in range(3):
            t = time.perf_counter()
            subprocess.run([str(keyfill), "complete", str(src), "--key-every", "60", "--method", "match", "-o",
                            str(dst)], check=True, capture_output=True)
            cold.append(time.perf_counter() - t)
    return {"gap_search_ms": {"median": 1e3 * statistics.median(per_gap), "max": 1e3 * max(per_gap),
                              "gaps": len(per_gap)},
            "frames": 2048, "complete_warm_s": {"median": statistics.median(warm), "runs": warm},
            "complete_cold_s": {"median": statistics.median(cold), "runs": cold},
            "library_resident_mib": _resident_mib(), "library_frames": matcher.library.num_frames}


#: run in a fresh process: resident memory before and after loading the shipped library, its tree and its
#: pose index, with every array touched (a memory map counts once read)
_RESIDENT = """
import psutil, numpy as np
from keyfill.learn.library.index import library_index
from keyfill.learn.match.model import DEFAULT_MODEL, load
p = psutil.Process()
before = p.memory_info().rss
m = load(DEFAULT_MODEL)
lib = m.library
_ = m.matcher.tree, library_index(lib)._tree()
touched = sum(float(np.asarray(getattr(lib, k)).sum()) for k in ("rotations", "hips", "features", "ground"))
print((p.memory_info().rss - before) / 2**20)
"""


def _resident_mib() -> float:
    out = subprocess.run([sys.executable, "-c", _RESIDENT], check=True, capture_output=True, text=True)
    return float(out.stdout.strip().splitlines()[-1])


def build_time() -> dict:
    from keyfill.learn.library.store import build

    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        report = build([locate("bandai2")], Path(tmp) / "lib", workers=2)
        return {"seconds": time.perf_counter() - t, "clips": report["clips"], "frames": report["frames"],
                "workers": 2}


def goals(f: dict) -> list[dict]:
    """Issue 42's goals, one line per goal and set (both key spacings in it)."""
    g = []
    q = f["quality"]
    for name in ("normal (dataset-2)", "sad, feminine (dataset-1)"):
        real, rows = q[name]["real"], [q[name][str(gap)] for gap in GAPS]
        sk = [r["match"]["foot_skating_cm_s"] / real["foot_skating_cm_s"] for r in rows]
        ji = [r["match"]["jitter_m_s3"] / real["jitter_m_s3"] for r in rows]
        er = [r["match"]["gap_error_cm"] / r["cubic"]["gap_error_cm"] for r in rows]
        below = [r["match"]["gap_error_cm"] < r["transformer"]["gap_error_cm"] for r in rows]
        g.append(results.goal(42, f"{name}, keys every 30 / 60: foot skating at most 1.5x real",
                              " / ".join(f"{x:.2f}x" for x in sk), max(sk) <= 1.5))
        g.append(results.goal(42, f"{name}, keys every 30 / 60: jitter 0.67x-1.5x real",
                              " / ".join(f"{x:.2f}x" for x in ji), min(ji) >= 0.67 and max(ji) <= 1.5))
        g.append(results.goal(42, f"{name}, keys every 30 / 60: gap error at most 0.6x cubic's and below the "
                              "transformer's", " / ".join(f"{x:.2f}x" for x in er) + ", below the transformer: "
                              + " / ".join(map(str, below)), max(er) <= 0.6 and all(below)))
        g.append(results.goal(42, f"{name}: keys exact", str(all(r["match"]["keys_exact"] for r in rows)),
                              all(r["match"]["keys_exact"] for r in rows)))
    ge = [q["gestures (dataset-2)"][str(gap)] for gap in GAPS]
    r = [row["match"]["gap_error_cm"] / row["cubic"]["gap_error_cm"] for row in ge]
    g.append(results.goal(42, "gestures, keys every 30 / 60: gap error at most 1.05x cubic's",
                          " / ".join(f"{x:.3f}x" for x in r), max(r) <= 1.05))
    v = {name: x["pairwise_cm"] for name, x in f["variety"].items()}
    g.append(results.goal(42, "keys every 60: 5 seeds at least 5 cm apart",
                          ", ".join(f"{k}: {x:.1f} cm" for k, x in v.items()), min(v.values()) >= 5))
    worst = max((u["guard_gap_error_cm"] / u["cubic_gap_error_cm"], f"{m} at {gap}")
                for gap, row in f["guard"]["unknown"].items() for m, u in row.items())
    g.append(results.goal(42, "unknown actions: every human method with the guard at most 1.1x cubic's gap error",
                          f"at most {worst[0]:.2f}x ({worst[1]})", worst[0] <= 1.1))
    known = [(k["changed_pct"], abs(k["gap_error_change_pct"])) for row in f["guard"]["known"].values()
             for k in row.values()]
    g.append(results.goal(42, "known actions (held out): the guard changes at most 2 % of gaps, 1 % of gap error",
                          f"at most {max(c for c, _ in known):.1f} % of gaps, {max(e for _, e in known):.1f} %",
                          all(c <= 2 and e <= 1 for c, e in known)))
    sp = f["speed"]
    g.append(results.goal(42, "a gap's search at most 10 ms (median)", f"{sp['gap_search_ms']['median']:.1f} ms",
                          sp["gap_search_ms"]["median"] <= 10))
    g.append(results.goal(42, "2,048 frames, keys every 60, at most 0.5 s end to end",
                          f"{sp['complete_warm_s']['median']:.2f} s in process, "
                          f"{sp['complete_cold_s']['median']:.2f} s a fresh command",
                          sp["complete_cold_s"]["median"] <= 0.5))
    g.append(results.goal(42, "the loaded library at most 300 MB resident", f"{sp['library_resident_mib']:.0f} MiB",
                          sp["library_resident_mib"] <= 300))
    if "build" in f:
        g.append(results.goal(42, "building the library of dataset-2 at most 60 s on two cores",
                              f"{f['build']['seconds']:.1f} s", f["build"]["seconds"] <= 60))
    return g


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clips", type=int, default=24, help="clips per style set (default 24)")
    ap.add_argument("--build", action="store_true", help="also time building the library of dataset-2")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    try:
        sets = style_sets(args.clips)
        unknown = unknown_actions()
    except DataError as e:
        print(f"skipped: {e}")
        return 0
    figures = {"clips": {k: len(v) for k, v in sets.items()} | {"unknown actions (dataset-1)": len(unknown)},
               "seconds": SECONDS, "quality": quality(sets), "variety": variety(sets),
               "guard": guard_figures(sets["normal (dataset-2)"], unknown),
               "speed": speed(sets["normal (dataset-2)"][0])}
    print(f"speed: {figures['speed']}", flush=True)
    if args.build:
        figures["build"] = build_time()
        print(f"build: {figures['build']}")
    record = bench.record("match", figures, goals(figures), write=not args.no_record)
    results.print_goals(record)
    print(results.summary(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
