"""Table 3 of Ciccone et al. 2019, rebuilt: milliseconds per tangent-space edit.

For each constraint configuration, interpolation length (2, 7, 20 frames
between keys) and number of optimised degrees of freedom (24, 72, 120, 168 =
4 per control: the (X, Y) of two tangents), it times at least ``--edits``
independent move edits and prints the median beside the paper's figure
(Mosek on an i7-4930K, Jacobians included). Each edit drags the left hand's
tip by up to 1 % of the character's size at a random frame between two keys
(an interactive increment, as in the paper), from the same curves every
time, to a place the configuration can reach (where an untimed first drag
in a random direction got to).
Timed: everything :func:`keyfill.edit.solve.edit_tangents` does for the edit
(reduction, sampling, targets, Jacobians, QPs, iterations), not the dense
checks after it; each edit is then checked: target reached, keys unchanged,
pins and contacts within epsilon at every frame, the optimised DOF as asked.

Characters:

* Bandai: ``dataset-1_walk_normal_002.bvh`` from ../shared/data (CC BY-NC,
  read in place), fitted with every channel as a control (22 joints x 6
  channels, like a rig with many controls); its arms swing as captured while
  the rest of the body holds frame 0, so feet and head are true contacts.
  The DOF of a cell is set by locking all but the chosen controls, taken in
  turn from the groups that the configuration's chains do and do not share.
* Lamp: the hopping lamp of keyfill.characters.lamp (6 controls = 24 DOF).

Configurations (the six tables of the paper, in its reading order; the
paper's text does not label them, so the goal is checked against the same
table and, for the constrained ones, also against the smallest figure of
the five constrained tables):

    alone             the hand only
    pin low           + pin on the right hand's tip (another branch)
    pin high          + pin on the head's tip (high in the hierarchy)
    contact low       + the right toes in contact over the edited segment
    contact high      + the head's tip in contact over the edited segment
    pin + contact     + pin on the right hand and contact of the right toes

Tangents: by default each edit changes only its segment (``break_tangents``:
the paper's reduction to ``theta_k+, theta_k+1-``); ``--unified`` keeps
unified keys unified, which also changes (and samples) the neighbouring
segments.

The run is recorded in ``benchmarks/results/tangent_qp.json`` (``tangent_qp-unified.json`` with
``--unified``; ``results.py``; not with ``--no-record``): ``edits``, ``unified``, ``seed``, ``solver``
and the cells, ``bandai[configuration][frames][dof]`` and ``lamp[frames]``, each with the medians
(``median_ms``, ``median_cpu_ms``, ``p90_ms``), ``failed``, ``dof``, ``median_iterations``,
``median_move``, the paper's figure (``paper_ms``), a tenth of the figure the goal uses
(``goal_ms``) and ``met``; the edit-by-edit outcomes stay in ``--json``.

Run (about 3 minutes on 2 cores; it sets one BLAS thread before numpy loads)::

    .venv/bin/python benchmarks/bench_tangent_qp.py --edits 100 --json out/bench_tangent_qp.json \
        --markdown out/bench_tangent_qp.md
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # small dense problems: BLAS threads only contend

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
import results as bench_results

from keyfill import io
from keyfill.edit import solve
from keyfill.edit.edits import Contact, EditFile, Manipulation
from keyfill.edit.fit import fit
from keyfill.edit.rig import Point, Rig
from keyfill.edit.session import WorkingCurves
from keyfill.motion import Keys

DOFS = (24, 72, 120, 168)
LENGTHS = (2, 7, 20)
CONFIGS = ("alone", "pin low", "pin high", "contact low", "contact high", "pin + contact")
#: Table 3 of the paper, in reading order: [length 2, 7, 20] x [24, 72, 120, 168 DOF], ms
PAPER = {
    "alone": [[10, 12, 16, 21], [10, 13, 16, 21], [10, 12, 16, 20]],
    "pin low": [[52, 54, 57, 63], [59, 68, 81, 101], [63, 103, 144, 200]],
    "pin high": [[52, 57, 69, 86], [58, 80, 94, 130], [67, 106, 158, 227]],
    "contact low": [[55, 57, 59, 64], [60, 67, 77, 92], [60, 99, 137, 167]],
    "contact high": [[53, 59, 63, 68], [63, 80, 91, 113], [65, 103, 144, 187]],
    "pin + contact": [[56, 59, 61, 66], [61, 76, 89, 99], [63, 101, 162, 191]],
}
PAPER_CONSTRAINED_MIN = np.min([PAPER[c] for c in CONFIGS[1:]], axis=0)
GOAL_FRACTION = 0.1
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "bvh_fixtures"
WALK = SHARED / "dataset-1_walk_normal_002.bvh"
MOVING = ("Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L", "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R")


def bandai_motion():
    """The walk's arm swing over a body that holds frame 0 (so feet and head stand still)."""
    m = io.load(WALK)
    sk = m.skeleton
    rot, pos = m.rotations.copy(), m.positions.copy()
    still = [j for j in range(sk.num_joints) if sk.names[j] not in MOVING]
    rot[:, still] = rot[:1, still]
    pos[:, still] = pos[:1, still]
    return m.replace(rotations=rot, positions=pos, keys=None)


def lamp_motion():
    from keyfill.characters.lamp import from_variables

    t = np.arange(31) / 30.0
    v = np.stack(
        [
            0.4 * t,
            0.08 * np.sin(np.pi * t) ** 2,
            0.15 * np.sin(2 * np.pi * t),
            0.6 + 0.3 * np.sin(3 * t),
            -1.1 + 0.25 * np.cos(4 * t),
            0.5 * np.sin(2 * t),
        ],
        -1,
    )
    return from_variables(v, 30.0)


def key_frames(num_frames: int, length: int) -> Keys:
    return Keys.every(length, num_frames)


def segments_to_edit(curves, length: int) -> list[int]:
    """Segments of the full interpolation length (the last may be shorter)."""
    return [s for s in range(curves.num_keys - 1) if curves.times[s + 1] - curves.times[s] == length]


class Scene:
    """Curves of one character and key spacing, with the points of the configurations."""

    def __init__(self, motion, length: int, hand: Point, pins: dict, all_channels: bool):
        self.curves = fit(motion, key_frames(motion.num_frames, length), all_channels=all_channels)
        self.rig = Rig(self.curves.skeleton, self.curves.controls)
        self.length = length
        self.hand = hand
        self.points = pins
        self.size = solve.character_size(self.curves.skeleton)
        self.eps = 1e-4 * self.size

    def rig_state(self, curves, frame: float) -> np.ndarray:
        """World position ``(3,)`` of the moved point at ``frame``."""
        return WorkingCurves(curves).states([self.hand], [frame])[0][0][0]

    def unlocked(self, groups: list[list[list[int]]], k: int) -> list[int]:
        """``k`` controls taken in turn from ``groups`` (lists of joints' controls): a whole joint at
        a time when there is room for one from every group, else one control at a time."""
        groups = [list(g) for g in groups if g]
        size = 3 if k >= 3 * len(groups) else 1
        out: list[int] = []
        while len(out) < k and any(groups):
            for g in groups:
                if g and len(out) < k:
                    unit = g[0][:size]
                    g[0] = g[0][size:]
                    if not g[0]:
                        g.pop(0)
                    out += unit[: k - len(out)]
        return out

    def units(self, controls, shallow: bool = False) -> list[list[int]]:
        """``controls`` grouped by joint, rotations (per joint) before translations (per joint);
        joints deepest first (nearest the moved point), or shallowest first."""
        ctl = self.curves.controls
        joints = sorted({ctl[c].joint for c in controls}, reverse=not shallow)
        out = []
        for rot in (True, False):
            for j in joints:
                unit = sorted(c for c in controls if ctl[c].joint == j and ctl[c].is_rotation == rot)
                if unit:
                    out.append(unit)
        return out


def configuration(scene: Scene, name: str, dof: int, segment: int):
    """``(pins, contacts, locked)`` for a configuration with ``dof`` optimised DOF on ``segment``."""
    rig, k = scene.rig, dof // 4
    Cs = rig.controls_of(scene.hand)
    a, b = scene.curves.times[segment], scene.curves.times[segment + 1]
    pins, contacts = [], []
    if name in ("pin low", "pin + contact"):
        pins.append(scene.points["hand_r"])
    if name == "pin high":
        pins.append(scene.points["head"])
    if name in ("contact low", "pin + contact"):
        contacts.append(Contact(scene.points["toes_r"], a, b))
    if name == "contact high":
        contacts.append(Contact(scene.points["head"], a, b))
    chains = [rig.controls_of(p) for p in pins + [c.point for c in contacts]]
    others = [ch - Cs for ch in chains]
    shared = set().union(*chains) & Cs if chains else set()
    # in turn: controls shared with the constrained points (those shared with the most of them
    # first), the constrained points' own (shallow joints first: they can make up for the
    # shared ones), then the hand's own
    by_joint = scene.units(shared)
    by_joint.sort(key=lambda unit: -sum(unit[0] in ch for ch in chains))
    groups = [by_joint] + [scene.units(o, shallow=True) for o in others] + [scene.units(Cs - shared)]
    if not others:
        groups = [scene.units(Cs)]
    keep = scene.unlocked(groups, k)
    locked = frozenset(range(scene.curves.num_controls)) - set(keep)
    return tuple(pins), tuple(contacts), locked


def probe(scene: Scene, frame: float, rng, pins, contacts, locked, unified) -> np.ndarray:
    """A move of the hand that the configuration can make (untimed): ``(3,)``, at most 1 % of the size.

    A random direction may be out of reach (the lamp is planar; 6 controls
    may not move the tip along every axis; pins take directions away), so a
    first best-effort drag of 1 % of the character's size in a random
    direction shows where the hand can go; the timed edit moves it there.
    """
    before = scene.rig_state(scene.curves, frame)
    for _ in range(10):
        direction = rng.normal(size=3)
        move = direction / np.linalg.norm(direction) * 0.01 * scene.size
        edit = Manipulation(1, 0, scene.hand, frame, None, move, None, (), (), (), break_tangents=not unified)
        ef = EditFile(path="probe", edits=(edit,), pins=pins, contacts=contacts, locked=locked)
        out, _ = solve.edit_tangents(scene.curves, ef, best_effort=True)
        reached = scene.rig_state(out, frame) - before
        if np.linalg.norm(reached) > 1e-3 * scene.size:
            return reached
    raise RuntimeError(f"the hand cannot move at frame {frame:g} under this configuration")


def run_cell(scene: Scene, name: str, dof: int, edits: int, rng, unified: bool) -> dict:
    times, cpu, failures, dofs, iters, moves, per_edit = [], [], [], set(), [], [], []
    segs = segments_to_edit(scene.curves, scene.length)
    for _ in range(edits):
        s = int(rng.choice(segs))
        a, b = scene.curves.times[s], scene.curves.times[s + 1]
        frame = float(rng.integers(int(a) + 1, int(b))) if b - a > 1 else 0.5 * (a + b)
        pins, contacts, locked = configuration(scene, name, dof, s)
        move = probe(scene, frame, rng, pins, contacts, locked, unified)
        moves.append(np.linalg.norm(move) / scene.size)
        edit = Manipulation(1, 0, scene.hand, frame, None, move, None, (), (), (), break_tangents=not unified)
        ef = EditFile(path="bench", edits=(edit,), pins=pins, contacts=contacts, locked=locked)
        out, (report,) = solve.edit_tangents(scene.curves, ef, best_effort=True)
        times.append(report.solve_ms)
        cpu.append(report.solve_cpu_ms)
        iters.append(report.iterations)
        per_edit.append(
            {"frame": frame, "reached": report.reached, "iterations": report.iterations, "distance": report.distance}
        )
        dofs.add(2 * report.optimised_tangents)
        why = []
        if not report.reached:
            why.append(f"stopped {report.distance:.3g} from the target")
        if not np.array_equal(out.values, scene.curves.values):
            why.append("key values changed")
        for what in ("pin", "contact"):
            v = getattr(report, f"worst_{what}_violation") or 0.0
            if v > scene.eps:
                why.append(f"{what} off by {v:.3g}")
        if why:
            failures.append(f"frame {frame:g}: " + ", ".join(why))
    return {
        "median_ms": float(np.median(times)),
        "median_cpu_ms": float(np.median(cpu)),
        "p90_ms": float(np.percentile(times, 90)),
        "edits": len(times),
        "failed": len(failures),
        "failures": failures,
        "dof": sorted(dofs),
        "median_iterations": float(np.median(iters)),
        "median_move": float(np.median(moves)),  # fraction of the character's size
        "per_edit": per_edit,  # the solver's outcome of each edit, to compare runs edit by edit
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--edits", type=int, default=100, help="edits per cell (the paper: over a hundred)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the edit sampler")
    parser.add_argument(
        "--unified", action="store_true", help="keep unified keys unified (neighbour segments change too)"
    )
    parser.add_argument("--configs", default=",".join(CONFIGS), help="comma-separated subset of: " + ", ".join(CONFIGS))
    parser.add_argument("--json", type=Path, help="also write the results (with every edit's outcome) here")
    parser.add_argument("--markdown", type=Path, help="also write the tables (wall and CPU medians) as Markdown")
    bench_results.add_option(parser)
    args = parser.parse_args(argv)
    if not WALK.exists():
        print(f"needs {WALK} (the shared Bandai fixtures beside the checkout)", file=sys.stderr)
        return 2
    bench = bench_results.Run()
    rng = np.random.default_rng(args.seed)
    load = os.getloadavg()[0]
    print(
        f"# {platform.machine()} {os.cpu_count()} cores, load {load:.2f}; {args.edits} edits per cell; "
        f"{'unified' if args.unified else 'segment-only (paper)'} tangents; solver daqp"
    )
    if load > 0.5 * (os.cpu_count() or 1):
        print("# WARNING: the machine is busy; timings are inflated")
    walk = bandai_motion()
    sk = walk.skeleton
    tip = dict(sk.end_sites)
    hand = Point(sk.index("Hand_L"), tip[sk.index("Hand_L")])
    points = {
        "hand_r": Point(sk.index("Hand_R"), tip[sk.index("Hand_R")]),
        "head": Point(sk.index("Head"), tip[sk.index("Head")]),
        "toes_r": Point(sk.index("Toes_R"), tip[sk.index("Toes_R")]),
    }
    results = {
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "load": load,
        "edits": args.edits,
        "seed": args.seed,
        "unified": args.unified,
        "bandai": {},
        "lamp": {},
    }
    configs = [c.strip() for c in args.configs.split(",")]
    t0 = time.perf_counter()
    for length in LENGTHS:
        scene = Scene(walk, length, hand, points, all_channels=True)
        for name in configs:
            for dof in DOFS:
                cell = run_cell(scene, name, dof, args.edits, rng, args.unified)
                results["bandai"].setdefault(name, {}).setdefault(str(length), {})[str(dof)] = cell
    lamp = lamp_motion()
    lsk = lamp.skeleton
    lamp_tip = Point(lsk.index("head"), dict(lsk.end_sites)[lsk.index("head")])
    for length in LENGTHS:
        scene = Scene(lamp, length, lamp_tip, {}, all_channels=False)
        results["lamp"][str(length)] = run_cell(scene, "alone", 24, args.edits, rng, args.unified)
    results["wall_s"] = time.perf_counter() - t0
    results["load_after"] = os.getloadavg()[0]
    print(report(results))
    print(report(results, "median_cpu_ms"))
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(markdown(results))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=1, sort_keys=True))
    for g in record(results, bench, write=not args.no_record)["goals"]:
        print(f"goal: {g['goal']}: {g['measured']} {'met' if g['met'] else 'MISSED'}")
    return 0


def goal_figure(name: str, li: int, di: int) -> float:
    """The paper's figure a cell is judged against: its own table's for manipulation alone, for a
    constrained configuration the smaller of its own and the smallest of the five constrained tables."""
    paper = PAPER[name][li][di]
    return paper if name == CONFIGS[0] else min(paper, float(PAPER_CONSTRAINED_MIN[li][di]))


def judged_cells(results: dict) -> dict:
    """The cells of ``results`` without the edit-by-edit outcomes, with the paper's figure and the goal."""
    def judged(cell, paper, figure):
        slim = {k: v for k, v in cell.items() if k not in ("per_edit", "failures")}
        limit = GOAL_FRACTION * figure
        return {**slim, "paper_ms": paper, "goal_ms": limit, "met": cell["median_ms"] <= limit}

    bandai = {name: {length: {dof: judged(cell, PAPER[name][LENGTHS.index(int(length))][DOFS.index(int(dof))],
                                          goal_figure(name, LENGTHS.index(int(length)), DOFS.index(int(dof))))
                              for dof, cell in cells.items()}
                     for length, cells in by_length.items()}
              for name, by_length in results["bandai"].items()}
    lamp = {length: judged(cell, PAPER["alone"][LENGTHS.index(int(length))][0],
                           PAPER["alone"][LENGTHS.index(int(length))][0])
            for length, cell in results["lamp"].items()}
    return {"bandai": bandai, "lamp": lamp}


def goals(cells: dict) -> list[dict]:
    """Issue 5's goal: every cell at most a tenth of the paper's time."""
    flat = [c for by_length in cells["bandai"].values() for by_dof in by_length.values() for c in by_dof.values()]
    flat += list(cells["lamp"].values())
    ratios = [GOAL_FRACTION * c["median_ms"] / c["goal_ms"] for c in flat]
    met = sum(c["met"] for c in flat)
    return [bench_results.goal(5, "Table 3: every cell at most 1/10 of the paper's time",
                               f"{met} of {len(flat)} cells; median ratio {np.median(ratios):.3f}, worst "
                               f"{max(ratios):.3f}", met == len(flat))]


def record(results: dict, bench, write: bool) -> dict:
    """The run's record (see the module docstring)."""
    figures = {"edits": results["edits"], "unified": results["unified"], "seed": results["seed"], "solver": "daqp",
               **judged_cells(results)}
    name = "tangent_qp-unified" if results["unified"] else "tangent_qp"
    return bench.record(name, figures, goals(figures), write=write)


def report(results: dict, key: str = "median_ms") -> str:
    """Markdown tables: our median (``key``: wall or CPU ms), the paper's figure, the ratio (goal <= 0.1).

    For the constrained configurations the ratio is against the smaller of the
    same table's figure and the smallest figure of the five constrained tables.
    """
    lines = []
    worst = 0.0
    for name in [c for c in CONFIGS if c in results["bandai"]]:
        by_length = results["bandai"][name]
        ti = CONFIGS.index(name)
        lines.append(f"\n**{name}** (Bandai; paper: table {ti + 1} of Table 3 in reading order)\n")
        lines.append("| frames | " + " | ".join(f"{d} DOF" for d in DOFS) + " |")
        lines.append("|---|" + "---|" * len(DOFS))
        for li, length in enumerate(LENGTHS):
            cells = []
            for di, dof in enumerate(DOFS):
                cell = by_length[str(length)][str(dof)]
                ratio = cell[key] / goal_figure(name, li, di)
                worst = max(worst, ratio)
                bad = f", {cell['failed']} failed" if cell["failed"] else ""
                dof_note = "" if cell["dof"] == [dof] else f", DOF {cell['dof']}"
                cells.append(f"{cell[key]:.2f} ({PAPER[name][li][di]}) {ratio:.3f}{bad}{dof_note}")
            lines.append(f"| {length} | " + " | ".join(cells) + " |")
    lines.append("\n**lamp, alone** (24 DOF)\n")
    lines.append("| frames | 24 DOF |")
    lines.append("|---|---|")
    for li, length in enumerate(LENGTHS):
        cell = results["lamp"][str(length)]
        ratio = cell[key] / PAPER["alone"][li][0]
        worst = max(worst, ratio)
        bad = f", {cell['failed']} failed" if cell["failed"] else ""
        lines.append(f"| {length} | {cell[key]:.2f} ({PAPER['alone'][li][0]}) {ratio:.3f}{bad} |")
    what = "wall-clock" if key == "median_ms" else "CPU (this thread)"
    lines.append(
        f"\ncells: our median {what} ms per edit (paper ms) ratio; worst ratio {worst:.3f} (goal <= 0.1); "
        f"wall {results['wall_s']:.0f} s, load {results['load']:.2f}"
    )
    return "\n".join(lines)


def markdown(results: dict) -> str:
    """The tables for docs: per cell ``wall / CPU ms (paper)``, bold where wall > 1/10 of the paper."""
    lines = []
    for name in [c for c in CONFIGS if c in results["bandai"]]:
        by_length = results["bandai"][name]
        lines += [f"**{name}**", "", "| frames | " + " | ".join(f"{d} DOF" for d in DOFS) + " |"]
        lines.append("|---|" + "---|" * len(DOFS))
        for li, length in enumerate(LENGTHS):
            cells = []
            for di, dof in enumerate(DOFS):
                cell = by_length[str(length)][str(dof)]
                paper = PAPER[name][li][di]
                text = f"{cell['median_ms']:.1f} / {cell['median_cpu_ms']:.1f} ({paper})"
                if cell["median_ms"] > GOAL_FRACTION * goal_figure(name, li, di):
                    text = f"**{text}**"
                if cell["failed"]:
                    text += f" {cell['failed']} unreached"
                cells.append(text)
            lines.append(f"| {length} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["**lamp, alone** (24 DOF)", "", "| frames | 24 DOF |", "|---|---|"]
    for li, length in enumerate(LENGTHS):
        cell = results["lamp"][str(length)]
        text = f"{cell['median_ms']:.1f} / {cell['median_cpu_ms']:.1f} ({PAPER['alone'][li][0]})"
        if cell["median_ms"] > 0.1 * PAPER["alone"][li][0]:
            text = f"**{text}**"
        lines.append(f"| {length} | {text} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
