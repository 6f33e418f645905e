"""Speed (and the accuracy it costs) of ``keyfill simulate``.

Prints markdown tables with medians:

1. control: keyfill's PD torques (TORQUE_CONTROL, the shipped choice) against
   pybullet's POSITION_CONTROL motors, per physics step;
2. resets: ``restoreState`` against reconnecting and rebuilding the world;
3. time step and solver iterations: error of hop distance and height against
   a 1/1920 s, 100-iteration reference, and cost per episode;
4. early termination: steps a fallen episode takes with and without stopping;
5. annealing throughput in one process: episodes per second per core and
   seconds per run at ``--iterations``;
6. with ``--dataset N``: a full ``keyfill simulate`` build of N sequences with
   ``--workers`` processes: wall time, acceptance, episodes/s/core and
   accepted sequences per hour, against the paper's 10,000 runs x 1,000
   iterations for 300 sequences.

Sections 1-5 are recorded in ``benchmarks/results/simulate.json`` and the build in
``simulate-dataset.json`` (``results.py``; not with ``--no-record``): ``control``, ``resets``,
``time_step`` (``reference``, ``shipped_iterations``, ``rows``), ``early_stop`` and ``annealing``;
and the build's ``sequences``, ``runs``, ``acceptance_rate``, ``wall_s``, ``cpu_s``, ``episodes``,
``workers``, ``iterations`` and rates.

Usage::

    nice -n 5 .venv/bin/python benchmarks/bench_simulate.py                 # sections 1-5, about 3 min
    nice -n 5 .venv/bin/python benchmarks/bench_simulate.py --dataset 300 --workers 2 --out data/bench/hops
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import shutil
import statistics
import time
from pathlib import Path

import numpy as np
import results

from keyfill.sim.controller import REFERENCE
from keyfill.sim.hops import analyse, satisfactory
from keyfill.sim.physics import LampWorld
from keyfill.sim.search import anneal
from keyfill.sim.settings import DEFAULT_SETTINGS

S = DEFAULT_SETTINGS
GOAL_SEQUENCES, GOAL_MINUTES = 300, 30.0


def load() -> str:
    return "load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def bench_control(repeats: int) -> dict:
    print("\n## 1. Control: keyfill PD torques vs pybullet POSITION_CONTROL (reference controller, one episode)\n")
    with LampWorld(S) as w:
        ep = w.simulate(REFERENCE)
        steps = len(ep.times) - 1
        t_torque = median_time(lambda: w.simulate(REFERENCE), repeats)
        p, cid = w.p, w.client
        bounds = np.cumsum(np.tile(REFERENCE.durations, S.cycles))
        state = np.searchsorted(bounds, np.arange(steps) * S.time_step, side="right")
        poses = np.vstack([np.tile(REFERENCE.poses, (S.cycles, 1)), REFERENCE.poses[-1:]])

        def position_control():
            w.reset(REFERENCE.start_pose())
            last = -1
            for k in range(steps):
                if state[k] != last:
                    last = state[k]
                    p.setJointMotorControlArray(w.lamp, w.hinges, p.POSITION_CONTROL, targetPositions=poses[last].tolist(),
                                                forces=list(S.max_torque), physicsClientId=cid)
                p.stepSimulation(physicsClientId=cid)
                p.getJointStates(w.lamp, w.joints, physicsClientId=cid)
            # leave the motors as LampWorld expects them
            p.setJointMotorControlArray(w.lamp, w.hinges, p.VELOCITY_CONTROL, forces=[0.0] * 3, physicsClientId=cid)

        t_pos = median_time(position_control, repeats)
    print("| control | ms / episode | us / step | steps / s |")
    print("|---|---|---|---|")
    for name, t in (("keyfill PD, TORQUE_CONTROL (shipped)", t_torque), ("pybullet POSITION_CONTROL", t_pos)):
        print(f"| {name} | {t * 1e3:.1f} | {t / steps * 1e6:.1f} | {steps / t:,.0f} |")
    print(f"\n{steps} steps of {S.time_step * 1e3:.3f} ms; torque control costs {t_torque / t_pos:.2f}x position control.")
    return {"steps": steps, "torque_ms": t_torque * 1e3, "position_ms": t_pos * 1e3,
            "torque_us_per_step": t_torque / steps * 1e6, "position_us_per_step": t_pos / steps * 1e6}


def bench_resets(repeats: int) -> dict:
    print("\n## 2. Resets\n")
    with LampWorld(S) as w:
        t_restore = median_time(lambda: w.reset(REFERENCE.start_pose()), max(repeats * 20, 50))

    def rebuild():
        with LampWorld(S) as fresh:
            fresh.reset(REFERENCE.start_pose())

    t_rebuild = median_time(rebuild, repeats)
    print("| reset | median |")
    print("|---|---|")
    print(f"| restoreState + 6 x resetJointState (shipped, per episode) | {t_restore * 1e6:.0f} us |")
    print(f"| connect + build world (per run) | {t_rebuild * 1e3:.1f} ms |")
    return {"restore_us": t_restore * 1e6, "rebuild_ms": t_rebuild * 1e3}


def controllers(n: int) -> list:
    rng = np.random.default_rng(1)
    out = []
    for i in range(n):
        c = REFERENCE.perturbed(rng, S)
        for _ in range(i % 3):
            c = c.neighbour(rng, S)
        out.append(c)
    return out


def bench_time_step(n: int) -> dict:
    print(f"\n## 3. Time step and solver iterations ({n} controllers near the reference)\n")
    ctrls = controllers(n)

    def evaluate(settings):
        with LampWorld(settings) as w:
            t = time.perf_counter()
            res = [analyse(w.simulate(c), settings) for c in ctrls]
            el = time.perf_counter() - t
        arr = np.array([(h.distance, h.max_height, satisfactory(h, settings) is None, h.fell) for h in res], dtype=float)
        return arr, el / n

    ref, t_ref = evaluate(dataclasses.replace(S, time_step=1 / 1920, solver_iterations=100))
    print(f"reference: 1/1920 s, 100 iterations: {t_ref * 1e3:.0f} ms per episode\n")
    print("| time step | solver iterations | ms / episode | median abs. distance error | median abs. height error | same keep/reject as reference |")
    print("|---|---|---|---|---|---|")
    rows = []
    for hz in (240, 480, 960):
        for it in (5, 10, 50):
            out, t = evaluate(dataclasses.replace(S, time_step=1 / hz, solver_iterations=it))
            both = (ref[:, 3] == 0) & (out[:, 3] == 0)
            d_err = np.median(np.abs(out[both, 0] - ref[both, 0]))
            h_err = np.median(np.abs(out[both, 1] - ref[both, 1]))
            same = np.mean(out[:, 2] == ref[:, 2])
            mark = " (shipped)" if (1 / hz, it) == (S.time_step, S.solver_iterations) else ""
            print(f"| 1/{hz} s{mark} | {it} | {t * 1e3:.1f} | {d_err * 100:.1f} cm | {h_err * 1000:.1f} mm | {same:.0%} |")
            rows.append({"hz": hz, "iterations": it, "ms_per_episode": t * 1e3, "distance_error_cm": d_err * 100,
                         "height_error_mm": h_err * 1000, "same_decisions": same})
    return {"reference": {"hz": 1920, "iterations": 100, "ms_per_episode": t_ref * 1e3},
            "shipped_iterations": S.solver_iterations, "rows": rows}


def bench_early_stop(n: int) -> dict:
    print("\n## 4. Early termination of episodes that fell\n")
    rng = np.random.default_rng(2)
    fallen = []
    with LampWorld(S) as w:
        while len(fallen) < n:
            c = REFERENCE.neighbour(rng, S)
            if w.simulate(c).fell:
                fallen.append(c)
        t_stop = median_time(lambda: [w.simulate(c) for c in fallen], 3) / n
        t_full = median_time(lambda: [w.simulate(c, stop_on_fall=False) for c in fallen], 3) / n
        steps_stop = np.mean([len(w.simulate(c).times) for c in fallen])
        steps_full = np.mean([len(w.simulate(c, stop_on_fall=False).times) for c in fallen])
    print("| fallen episodes | steps | ms / episode |")
    print("|---|---|---|")
    print(f"| stopped at the fall (shipped) | {steps_stop:.0f} | {t_stop * 1e3:.1f} |")
    print(f"| run to the end | {steps_full:.0f} | {t_full * 1e3:.1f} |")
    return {"stopped": {"steps": steps_stop, "ms": t_stop * 1e3}, "full": {"steps": steps_full, "ms": t_full * 1e3}}


def bench_annealing(runs: int, iterations: int) -> dict:
    print(f"\n## 5. Annealing in one process ({runs} runs x {iterations} iterations, seed 0)\n")
    with LampWorld(S) as w:
        t = time.perf_counter()
        results = []
        per_run = []
        for r in range(runs):
            t0 = time.perf_counter()
            results.append(anneal(0, r, iterations, S, w))
            per_run.append(time.perf_counter() - t0)
        el = time.perf_counter() - t
    episodes = sum(r.episodes for r in results)
    acc = [r for r in results if r.accepted]
    print("| runs | accepted | median s / run | episodes / s / core | accepted / hour / core |")
    print("|---|---|---|---|---|")
    print(f"| {runs} | {len(acc)} ({len(acc) / runs:.0%}) | {statistics.median(per_run):.2f} | {episodes / el:.0f} | "
          f"{len(acc) / el * 3600:.0f} |")
    d = [r.hops.distance for r in acc]
    h = [r.hops.max_height for r in acc]
    print(f"\nAccepted hops: distance {min(d):.2f}-{max(d):.2f} m (median {statistics.median(d):.2f}), "
          f"base clearance {min(h) * 100:.1f}-{max(h) * 100:.1f} cm (median {statistics.median(h) * 100:.1f}).")
    return {"runs": runs, "iterations": iterations, "accepted": len(acc),
            "median_s_per_run": statistics.median(per_run), "episodes_per_s": episodes / el,
            "accepted_per_hour": len(acc) / el * 3600, "median_distance_m": statistics.median(d)}


def bench_dataset(count: int, workers: int, iterations: int, out: Path) -> dict:
    from keyfill.sim.runner import simulate

    print(f"\n## 6. Dataset build: {count} sequences, {workers} workers, {iterations} iterations\n")
    if out.exists():
        shutil.rmtree(out)

    def cpu() -> float:  # this process and its finished worker processes
        own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
        return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime

    t, c = time.perf_counter(), cpu()
    summary = simulate(out, count, seed=0, iterations=iterations, workers=workers).to_dict()
    wall, cpu_s = time.perf_counter() - t, cpu() - c
    eps_core = summary["new_episodes"] / wall / workers
    eps_cpu = summary["new_episodes"] / cpu_s
    paper_episodes = 10_000 * 1_001
    print("| sequences | runs | acceptance | wall time | CPU time | episodes | episodes / s / core (wall) | "
          "episodes / CPU-s | accepted / hour |")
    print("|---|---|---|---|---|---|---|---|---|")
    print(f"| {summary['sequences']} | {summary['runs']} | {summary['acceptance_rate']:.1%} | {wall / 60:.1f} min | "
          f"{cpu_s / 60:.1f} min | {summary['new_episodes']:,} | {eps_core:.0f} | {eps_cpu:.0f} | "
          f"{summary['sequences'] / wall * 3600:,.0f} |")
    print(f"\nThe paper: about 10,000 runs x 1,000 iterations ({paper_episodes:,} episodes) for 300 sequences, "
          f"{paper_episodes / 300:,.0f} episodes per sequence; here {summary['new_episodes'] / summary['sequences']:,.0f} "
          f"({paper_episodes / 300 / (summary['new_episodes'] / summary['sequences']):.0f}x fewer). "
          f"At this rate the paper's {paper_episodes:,} episodes would take "
          f"{paper_episodes / (eps_cpu * workers) / 3600:.0f} h on {workers} otherwise idle cores.")
    print(json.dumps({"wall_s": wall, **summary}))
    return {"sequences": summary["sequences"], "runs": summary["runs"], "acceptance_rate": summary["acceptance_rate"],
            "wall_s": wall, "cpu_s": cpu_s, "episodes": summary["new_episodes"], "workers": workers,
            "iterations": iterations, "episodes_per_s_per_core": eps_core, "episodes_per_cpu_s": eps_cpu,
            "sequences_per_hour": summary["sequences"] / wall * 3600}


def dataset_goals(figures: dict) -> list[dict]:
    """Issue 3's goal, for a build of at least 300 sequences: 300 in at most 30 minutes."""
    if figures["sequences"] < GOAL_SEQUENCES:
        return []
    minutes = figures["wall_s"] / 60 * GOAL_SEQUENCES / figures["sequences"]
    return [results.goal(3, f"{GOAL_SEQUENCES} accepted lamp sequences in at most {GOAL_MINUTES:g} min",
                         f"{minutes:.1f} min ({figures['sequences']} sequences, {figures['workers']} workers)",
                         minutes <= GOAL_MINUTES)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--controllers", type=int, default=24)
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--iterations", type=int, default=None, help="annealing iterations [default: the CLI's]")
    ap.add_argument("--dataset", type=int, default=0, help="also build a dataset of this many sequences")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("data/bench/hops"))
    ap.add_argument("--only-dataset", action="store_true", help="skip sections 1-5")
    results.add_option(ap)
    args = ap.parse_args()
    from keyfill.cli.simulate import DEFAULT_ITERATIONS

    iterations = args.iterations or DEFAULT_ITERATIONS
    print(f"# keyfill simulate benchmark ({os.cpu_count()} CPUs; {load()})")
    if not args.only_dataset:
        bench = results.Run()
        figures = {"control": bench_control(args.repeats), "resets": bench_resets(args.repeats),
                   "time_step": bench_time_step(args.controllers), "early_stop": bench_early_stop(args.controllers),
                   "annealing": bench_annealing(args.runs, iterations)}
        bench.record("simulate", figures, [], write=not args.no_record)
    if args.dataset:
        bench = results.Run()
        figures = bench_dataset(args.dataset, args.workers, iterations, args.out)
        bench.record("simulate-dataset", figures, dataset_goals(figures), write=not args.no_record)
    print(f"\n({load()} at the end)")


if __name__ == "__main__":
    main()
