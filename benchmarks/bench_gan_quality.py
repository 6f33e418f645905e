"""Quality of a trained gan model on held-out Bandai-Namco dataset-2 clips (issue 12: docs/benchmarks.md, docs/gan.md).

The model of the tables, with the ``normal`` style held out (both stages,
``make gan-model`` runs them)::

    .venv/bin/python benchmarks/bench_gan_quality.py data/models/bandai2-gan --json

Three parts, all on the ``normal`` clips the model never saw:

1. **Global path predictor** (Table 2): the mean 3-D error of the predicted
   root displacement over 1, 64 and 128 frames
   (:func:`keyfill.learn.gan.quality.path_errors`). The paper's figures are
   at 60 fps; 64 frames here last as long as its 128.
2. **Keyframe alignment before post-processing** (Table 4) on ``--sequences``
   key layouts of ``--frames`` frames sampled as in training (Appendix C: keys
   up to the model's ``max_gap`` apart, long gaps jump between clips): the mean
   joint and root error at the keys, in cm, of the networks' output
   (:func:`keyfill.learn.gan.quality.quality_report`, which also gives the
   Motion DNA errors and the variety).
   The same at keys every 30 frames on the held-out clips themselves
   (``key_errors_every``: the networks' output before the exact-key correction,
   the root after the least-squares move onto the key roots).
3. **Realism** of what ``keyfill complete`` writes, per method, on every held-out
   clip long enough for two gaps: keys every ``G`` frames (``--gaps``) and on
   the last frame, filled by linear, cubic, the gan (seed 0) and, with
   ``--transformer MODEL``, the transformer (gaps up to 63 frames), beside the
   real clip: foot skating (cm/s, :mod:`keyfill.learn.protocols.metrics`, the real
   clip's lowest foot heights as the floor), jitter (m/s^3), the share of driven
   joint rotations outside the model's RC-FK ranges by more than 0.01 degree on
   the frames between keys (%; keys are the input), the largest
   bone-length error (cm: every method writes rotations over constant offsets,
   so this checks that nothing else moved) and the gap error (cm: the mean world
   joint position error against the real clip over the frames between keys).

``--test-pattern`` takes several file-name patterns separated by commas (e.g. dataset-1's
held-out ``'*_sad_*,*_feminine_*'`` with ``--data`` its folder); a run on other patterns
than the default records under ``gan_quality-<model folder>-<patterns>``.

Without the corpus the script says ``skipped`` and exits 0. The run is recorded in
``benchmarks/results/gan_quality-<model folder>.json`` (``results.py``; not with ``--no-record``):
``model``, ``transformer``, ``paper`` (the paper's figures), ``path_cm`` (``{frames: cm}``; not for a model
with a base, which has no path predictor), ``sampled`` (the quality report of part 2), ``realism``
(``{gap: {method: figures}}``) and ``seconds``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np
import results

from keyfill import io
from keyfill.errors import DataError
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.corpus import bvh_files, load_corpus, locate
from keyfill.learn.gan.model import load_model
from keyfill.learn.gan.poses import clip_pool
from keyfill.learn.gan.quality import path_errors, quality_report
from keyfill.learn.gan.ranges import inside
from keyfill.learn.protocols.metrics import foot_joints, foot_skating, jitter
from keyfill.learn.registry import complete
from keyfill.motion import Keys

#: a rotation counts as outside its range beyond this (radians): the real clips' hinge joints leave their
#: zero-width ranges by up to 0.0064 degrees, the float noise of the BVH text
RANGE_TOLERANCE = np.radians(0.01)
#: Zhou et al. 2020: Table 2 (60 fps; 2.1 s is 128 of its frames), Table 4, Eqs. 11-12
PAPER = {"path_cm_per_frame": 0.7, "path_cm_2s": 5.5, "key_joints_cm": 3.5, "key_root_cm": 10.0,
         "dna_error_1_cm": 8.4, "dna_error_2_cm": 6.5}
#: "near the paper's" key errors, as a factor
NEAR = 2.0


def bone_error_cm(motion, reference) -> float:
    """Largest difference (cm), over frames, between ``motion``'s bone lengths and ``reference``'s at frame 0.

    Bones are the joints whose local translation is constant over ``reference`` (in Bandai-Namco's
    files every joint has position channels; the hips below the static ``joint_Root`` move, so that
    "bone" is the root's travel, not a bone).
    """
    par = motion.skeleton.parents
    moving = np.ptp(reference.positions, axis=0).max(axis=-1) > 1e-6 * np.abs(reference.positions).max()
    child = np.array([j for j in range(1, motion.num_joints) if not moving[j]])

    def lengths(world):
        return np.linalg.norm(world[:, child] - world[:, par[child]], axis=-1)

    ref = lengths(reference.world_positions()[:1])
    return float(np.abs(lengths(motion.world_positions()) - ref).max() * motion.skeleton.meters_per_unit * 100)


def realism_table(model, model_path: str, files: list[Path], gaps, transformer: str | None) -> dict:
    """``{gap: {method: {...}}}`` of part 3 (see the module docstring); ``model`` is loaded from ``model_path``."""
    methods = {"linear": CompleteOptions(), "cubic": CompleteOptions(),
               "gan": CompleteOptions(model=model_path, seed=0)}
    if transformer:
        methods["transformer"] = CompleteOptions(model=transformer)
    clips = [io.load(f) for f in files]
    out = {}
    for gap in gaps:
        rows: dict = {m: {"world": [], "rot": [], "bone": []} for m in ["real", *methods]}
        rows["real"]["between"] = []
        for motion in clips:
            T = motion.num_frames
            if T < 2 * gap + 1:
                continue
            frames = np.unique(np.r_[np.arange(0, T, gap), T - 1])
            keys = Keys(frames)
            between = np.setdiff1d(np.arange(T), frames)  # ranges are scored between keys: keys are the input
            rows["real"]["world"].append(motion.world_positions())
            rows["real"]["between"].append(between)
            rows["real"]["rot"].append(motion.rotations[between])
            rows["real"]["bone"].append(bone_error_cm(motion, motion))
            for name, options in methods.items():
                if name == "transformer" and gap > 63:
                    continue
                filled = complete(motion, keys, name, options).motion
                rows[name]["world"].append(filled.world_positions())
                rows[name]["rot"].append(filled.rotations[between])
                rows[name]["bone"].append(bone_error_cm(filled, motion))
        sk = clips[0].skeleton
        feet = foot_joints(sk)
        fps = clips[0].fps
        real = rows["real"]["world"]
        table = {}
        for name, r in rows.items():
            if not r["world"]:
                continue
            skating = [foot_skating(w[None], feet, sk.up_axis, fps, sk.meters_per_unit, reference=g[None])
                       for w, g in zip(r["world"], real)]
            rot = np.concatenate(r["rot"])
            if model.folded:  # the model's ranges are of the folded hierarchy: the hips carry joint 0's turn
                from keyfill.learn.corpus import fold_root

                rot, _ = fold_root(rot, np.zeros(rot.shape[:-1] + (3,)), sk.parents)
            gap_error = [np.linalg.norm(w[b] - g[b], axis=-1).mean() * sk.meters_per_unit * 100
                         for w, g, b in zip(r["world"], real, rows["real"]["between"])]
            table[name] = {
                "clips": len(r["world"]),
                "gap_error_cm": float(np.mean(gap_error)),
                "foot_skating_cm_s": float(np.nanmean(skating)),
                "jitter_m_s3": float(np.mean([jitter(w[None], fps, sk.meters_per_unit) for w in r["world"]])),
                "range_violations_pct": float(100.0 * (~inside(model.ranges, rot, RANGE_TOLERANCE)).mean()),
                "bone_error_cm": float(max(r["bone"])),
            }
        out[gap] = table
    return out


def key_errors_every(model, corpus, gap: int, seed: int = 0) -> dict:
    """``{"gap", "clips", "joints_cm", "root_cm"}``: the networks' key errors before the exact-key correction with
    keys every ``gap`` frames (and on the last frame) of each clip of ``corpus`` long enough for two gaps. A model
    on a matched base corrects the clip's match (the library its config names, seed ``seed``), as ``complete``
    does."""
    from keyfill.learn.gan.features import centre_keys
    from keyfill.learn.gan.model import dna_poses, generate
    from keyfill.learn.gan.poses import relative_positions

    sk = model.skeleton
    m = sk.meters_per_unit
    joints, roots = [], []
    for i in range(len(corpus)):
        q, root = corpus.clip(i)
        if len(q) < 2 * gap + 1:
            continue
        k = np.unique(np.r_[np.arange(0, len(q), gap), len(q) - 1])
        if model.config.base == "match":
            j, r = matched_key_errors(model, io.load(corpus.files[i]), Keys(k), seed)
            joints.append(j)
            roots.append(r)
            continue
        poses = relative_positions(q[k], sk.offsets * m, sk.parents)
        poses[:, 0] = root[k] * m
        poses, _ = centre_keys(poses, sk.up_axis)
        dna = dna_poses(model, key_frames=k, seed=seed) if model.config.dna else None  # as complete draws it
        gq, groot = generate(model, k - k[0], poses, seed, dna=dna, key_quats=q[k])
        rel = relative_positions(gq[k - k[0]], sk.offsets * m, sk.parents)
        joints.append(np.linalg.norm(rel[:, 1:] - poses[:, 1:], axis=-1).mean())
        roots.append(np.linalg.norm(groot[k - k[0]] - poses[:, 0], axis=-1).mean())
    return {"gap": gap, "clips": len(joints), "joints_cm": float(np.mean(joints) * 100),
            "root_cm": float(np.mean(roots) * 100)}


def matched_key_errors(model, motion, keys: Keys, seed: int) -> tuple[float, float]:
    """``(joints, root)`` m: a matched-base model's output at ``keys`` of ``motion`` before the exact-key correction
    (root-relative joints, and the root), against the keys."""
    from keyfill.learn.gan.matched_base import library_path, matched_start
    from keyfill.learn.gan.model import complete_motion

    start, _ = matched_start(model, motion, keys, seed, library_path(model, None))
    out, _ = complete_motion(model, motion, keys, seed, start=start)
    top = motion.skeleton.children(0)[0] if model.folded else 0  # the model's root: the hips under joint_Root
    k = keys.frames
    got, want = (x.world_positions()[k] * motion.skeleton.meters_per_unit for x in (out, motion))
    rel = np.delete(got - got[:, top : top + 1], [0, top], axis=1)
    true = np.delete(want - want[:, top : top + 1], [0, top], axis=1)
    return (float(np.linalg.norm(rel - true, axis=-1).mean()),
            float(np.linalg.norm(got[:, top] - want[:, top], axis=-1).mean()))


def goals(report: dict) -> list[dict]:
    """Issue 12's goals for the gan: no range violation or bone-length error, key errors near the paper's."""
    gan = {gap: table["gan"] for gap, table in report["realism"].items() if "gan" in table}
    out = []
    if gan:
        worst_range = max(r["range_violations_pct"] for r in gan.values())
        worst_bone = max(r["bone_error_cm"] for r in gan.values())
        out.append(results.goal(12, "gan: zero joint-range violations and bone-length error between keys",
                                f"{worst_range:.2f} % and {worst_bone:.1g} cm at keys every "
                                f"{' and '.join(str(g) for g in gan)} frames", worst_range == 0 and worst_bone < 1e-6))
    for gap, table in report["realism"].items():
        if "gan" not in table:
            continue
        g, c, real = table["gan"], table["cubic"], table["real"]
        out.append(results.goal(31, f"gan raw output, keys every {gap}: foot skating below cubic's, jitter at most "
                                    "1.5x the real clips', gap error at most cubic's",
                                f"skating {g['foot_skating_cm_s']:.1f} (cubic {c['foot_skating_cm_s']:.1f}) cm/s, "
                                f"jitter {g['jitter_m_s3']:.0f} (real {real['jitter_m_s3']:.0f}) m/s^3, gap error "
                                f"{g['gap_error_cm']:.2f} (cubic {c['gap_error_cm']:.2f}) cm",
                                g["foot_skating_cm_s"] < c["foot_skating_cm_s"]
                                and g["jitter_m_s3"] <= 1.5 * real["jitter_m_s3"]
                                and g["gap_error_cm"] <= c["gap_error_cm"]))
    e = report["key_errors_every"]
    out.append(results.goal(31, f"gan keys before correction, keys every {e['gap']}: at most 5 cm (joints), 30 cm "
                                "(root)", f"{e['joints_cm']:.1f} cm joints, {e['root_cm']:.1f} cm root",
                            e["joints_cm"] <= 5 and e["root_cm"] <= 30))
    if report["sampled"] is None:  # a matched base: no Table 4 layouts
        return out
    full = report["sampled"]["key_errors"]["full"]
    joints, root = full["joints_cm"], full["root_cm"]
    near = joints <= NEAR * PAPER["key_joints_cm"] and root <= NEAR * PAPER["key_root_cm"]
    return out + [results.goal(12, f"gan key errors before post-processing near the paper's (Table 4: "
                                   f"{PAPER['key_joints_cm']} cm joints, {PAPER['key_root_cm']} cm root; within "
                                   f"{NEAR:g}x)", f"{joints:.1f} cm joints, {root:.0f} cm root", near)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model", help="a full gan model folder")
    ap.add_argument("--data", default=None, help="BVH folder (default: Bandai-Namco dataset-2)")
    ap.add_argument("--test-pattern", default="*_normal_*", help="held-out clips (file-name pattern)")
    ap.add_argument("--sequences", type=int, default=50, help="key layouts of part 2")
    ap.add_argument("--frames", type=int, default=2048, help="frames per key layout of part 2")
    ap.add_argument("--gaps", default="30,60", help="key spacings of part 3, frames")
    ap.add_argument("--clips", type=int, default=None, help="score only the first N held-out clips in part 3")
    ap.add_argument("--transformer", default=None, help="a transformer model folder for part 3")
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
    started = time.perf_counter()
    model = load_model(args.model)
    patterns = tuple(p.strip() for p in args.test_pattern.split(",") if p.strip())
    corpus = load_corpus([data], fold=model.folded).select(include=patterns)
    # a model with a base has no path predictor: its root path is the base's interpolation of the key roots
    report = {"path_cm": path_errors(model, clip_pool(corpus))} if model.config.base == "none" else {}
    # Table 4's layouts jump between clips, which a library search does not follow: a matched base is scored
    # at keys every 30 of the held-out clips only (and by bench_gan_match.py as a generator)
    report["sampled"] = quality_report(model, corpus, range(len(corpus)), args.sequences, args.frames, args.seed) \
        if model.config.base != "match" else None
    report["key_errors_every"] = key_errors_every(model, corpus, 30, args.seed)
    files = sorted({f for p in patterns for f in bvh_files([data], p)})[: args.clips]
    report["realism"] = realism_table(model, args.model, files, [int(g) for g in args.gaps.split(",")], args.transformer)
    report["seconds"] = round(time.perf_counter() - started, 1)
    print(f"load average after: {os.getloadavg()[0]:.2f}", file=sys.stderr)
    figures = {"model": args.model, "transformer": args.transformer, "paper": PAPER, **report}
    name = f"gan_quality-{Path(args.model).name}"
    if args.test_pattern != "*_normal_*":
        name += "-" + "-".join(p.strip("*_") for p in patterns)
    figures["test_pattern"] = args.test_pattern
    record = bench.record(name, figures, goals(report), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0

    def cm(v):
        return "-" if v is None else f"{v:.2f}"

    if "path_cm" in report:
        p = report["path_cm"]
        print(f"path predictor error (cm): per frame {cm(p[1])} (paper 0.7 at 60 fps), after 64 frames {cm(p[64])}, "
              f"after 128 frames {cm(p[128])} (paper 5.5 at 60 fps)")
    s = report["sampled"]
    if s is not None:
        full = s["key_errors"]["full"]
        print(f"{s['sequences']} sequences of {s['frames']} frames: key errors before post-processing "
              f"joints {cm(full['joints_cm'])} cm (paper 3.5), root {cm(full['root_cm'])} cm (paper 10.0)")
    e = report["key_errors_every"]
    print(f"keys every {e['gap']} frames on {e['clips']} held-out clips: key errors before post-processing joints "
          f"{cm(e['joints_cm'])} cm, root {cm(e['root_cm'])} cm")
    for gap, table in report["realism"].items():
        print(f"keys every {gap} frames:  clips  skating cm/s  jitter m/s^3  gap error cm  out of range %  "
              "bone error cm")
        for label, r in table.items():
            print(f"  {label:<12} {r['clips']:>5} {r['foot_skating_cm_s']:>13.2f} {r['jitter_m_s3']:>13.2f} "
                  f"{r['gap_error_cm']:>13.2f} {r['range_violations_pct']:>15.3f} {r['bone_error_cm']:>14.2e}")
    results.print_goals(record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
