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

from keyfill.sim.controller import REFERENCE
from keyfill.sim.hops import analyse, satisfactory
from keyfill.sim.physics import LampWorld
from keyfill.sim.search import anneal
from keyfill.sim.settings import DEFAULT_SETTINGS

S = DEFAULT_SETTINGS


def load() -> str:
    return "load average %.2f %.2f %.2f" % os.getloadavg()


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def bench_control(repeats: int) -> None:
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


def bench_resets(repeats: int) -> None:
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


def controllers(n: int) -> list:
    rng = np.random.default_rng(1)
    out = []
    for i in range(n):
        c = REFERENCE.perturbed(rng, S)
        for _ in range(i % 3):
            c = c.neighbour(rng, S)
        out.append(c)
    return out


def bench_time_step(n: int) -> None:
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
    for hz in (240, 480, 960):
        for it in (5, 10, 50):
            out, t = evaluate(dataclasses.replace(S, time_step=1 / hz, solver_iterations=it))
            both = (ref[:, 3] == 0) & (out[:, 3] == 0)
            d_err = np.median(np.abs(out[both, 0] - ref[both, 0]))
            h_err = np.median(np.abs(out[both, 1] - ref[both, 1]))
            same = np.mean(out[:, 2] == ref[:, 2])
            mark = " (shipped)" if (1 / hz, it) == (S.time_step, S.solver_iterations) else ""
            print(f"| 1/{hz} s{mark} | {it} | {t * 1e3:.1f} | {d_err * 100:.1f} cm | {h_err * 1000:.1f} mm | {same:.0%} |")


def bench_early_stop(n: int) -> None:
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


def bench_annealing(runs: int, iterations: int) -> None:
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


def bench_dataset(count: int, workers: int, iterations: int, out: Path) -> None:
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
    args = ap.parse_args()
    from keyfill.cli.simulate import DEFAULT_ITERATIONS

    iterations = args.iterations or DEFAULT_ITERATIONS
    print(f"# keyfill simulate benchmark ({os.cpu_count()} CPUs; {load()})")
    if not args.only_dataset:
        bench_control(args.repeats)
        bench_resets(args.repeats)
        bench_time_step(args.controllers)
        bench_early_stop(args.controllers)
        bench_annealing(args.runs, iterations)
    if args.dataset:
        bench_dataset(args.dataset, args.workers, iterations, args.out)
    print(f"\n({load()} at the end)")


if __name__ == "__main__":
    main()
