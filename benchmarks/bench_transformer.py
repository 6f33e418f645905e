"""Inference speed of the motion-completion transformer on this CPU.

The paper (Duan et al. 2021, Table 2) completes 1 sequence of 30 frames in
25 ms and a batch of 10 in 83 ms on an i7-8700K. keyfill's goal on the 2-core
development VM: 1 x 30 in at most 10 ms, 10 x 30 in at most 25 ms.

Measured here, each the median of ``--repeat`` calls in one process, for the
LaFAN1 in-betweening layout with a 30-frame transition (10 context frames, 30
unknown frames, 1 target key: 41 frames in, 30 of them generated):

* ``network``: the torch forward pass alone (Conv1d, mixture embedding, 8-layer
  encoder, Conv1d) in ``inference_mode``;
* ``complete``: :meth:`CompletionModel.complete_windows`, everything from
  numpy windows in to numpy windows out (canonical frame, LERP/SLERP
  pre-fill, global features by forward kinematics, network, IK back to local
  rotations, frame restored).

The model is the paper's size (8 layers, d_model 256, FFN 512, 8 heads) with
random weights unless ``--model`` names a trained model folder: the time does
not depend on the weights, only on the model's size. Threads: torch's default
(one per core) and 1. ``--onnx GRAPH`` (a graph written by ``keyfill export``
from the ``--model`` folder) adds ``complete`` through onnxruntime, as
``keyfill complete --model GRAPH`` runs it (one thread). The report also gives
this CPU's one-thread float32 matrix-product rate (``timing.matmul_gflops``):
the network's time follows it, and it varies between days on one VM kind.

The run is recorded in ``benchmarks/results/transformer-<model folder>.json`` (``transformer.json``
for the random paper-size model; ``results.py``; not with ``--no-record``): ``model``, ``frames``,
``repeat``, ``matmul_gflops_1_thread`` and ``results``, one row per thread count and batch with
``network_ms``, ``complete_ms``, ``onnx_complete_ms`` (with ``--onnx``), ``goal_ms``, ``paper_ms`` and
``complete_vs_paper``. The goals are judged with torch's default threads.

    .venv/bin/python benchmarks/bench_transformer.py
    .venv/bin/python benchmarks/bench_transformer.py --model data/models/bandai2-transformer --repeat 200 --json
    .venv/bin/keyfill export transformer -o /tmp/transformer.onnx
    .venv/bin/python benchmarks/bench_transformer.py --model models/bandai/keyfill_models_bandai/bandai2-transformer \
        --onnx /tmp/transformer.onnx --repeat 200
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import results
import torch
from timing import matmul_gflops, timed_ms

from keyfill import rotations as R
from keyfill.learn.transformer import config as TC
from keyfill.learn.transformer import features as TF
from keyfill.learn.transformer import model as T
from keyfill.motion import Skeleton

PAPER_MS = {1: 25.0, 10: 83.0}
GOAL_MS = {1: 10.0, 10: 25.0}


def bandai_like_skeleton() -> Skeleton:
    """A 22-joint chain-tree skeleton (Bandai-Namco's topology) for a model with random weights."""
    parents = [-1, 0, 1, 2, 3, 4, 3, 6, 7, 8, 3, 10, 11, 12, 1, 14, 15, 16, 1, 18, 19, 20]
    rng = np.random.default_rng(0)
    offsets = rng.normal(size=(22, 3)) * 10
    offsets[0] = 0
    return Skeleton([f"j{i}" for i in range(22)], parents, offsets, [()] * 22)


def goals(rows: list[dict], threads: int) -> list[dict]:
    """Issues 6 and 14: 1 x 30 and 10 x 30 frames within their budgets, with ``threads`` torch threads."""
    ms = {r["batch"]: r["complete_ms"] for r in rows if r["threads"] == threads}
    return [results.goal("6, 14", f"transformer inference at most {GOAL_MS[1]:g} ms for 1 x 30 frames and "
                                  f"{GOAL_MS[10]:g} ms for 10 x 30 (torch's default threads)",
                         f"{ms[1]:.1f} ms and {ms[10]:.1f} ms ({threads} thread{'s' * (threads > 1)})",
                         all(ms[b] <= GOAL_MS[b] for b in GOAL_MS))]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", help="a trained model folder (default: paper-size model with random weights)")
    ap.add_argument("--repeat", type=int, default=100, help="timed calls per figure (default 100)")
    ap.add_argument("--onnx", help="also time complete through this exported graph of --model (onnxruntime)")
    ap.add_argument("--json", action="store_true", help="print the record as JSON")
    results.add_option(ap)
    args = ap.parse_args(argv)
    if args.onnx and not args.model:
        ap.error("--onnx needs the --model folder the graph was exported from")

    bench = results.Run()
    if args.model:
        model = T.load(args.model)
    else:
        torch.manual_seed(0)
        skel = bandai_like_skeleton()
        model = T.new_model(skel, TC.ModelConfig(), np.zeros(66), np.full(66, 20.0), folded=False)
        model.network.eval()
    if args.onnx:
        from keyfill.learn.onnx import open_graph
        from keyfill.learn.transformer.onnx import model_from_graph

        graph_model = model_from_graph(open_graph(args.onnx))
    J = model.skeleton.num_joints
    rng = np.random.default_rng(1)
    frames = 10 + 30 + 1
    keys = np.append(np.arange(10), 40)
    timings = {}
    default_threads = torch.get_num_threads()
    for threads in sorted({default_threads, 1}, reverse=True):
        torch.set_num_threads(threads)
        for batch in (1, 10):
            q = R.quat_normalize(rng.normal(size=(batch, frames, J, 4)))
            r = rng.normal(size=(batch, frames, 3)) * 50
            x = torch.randn(batch, frames, model.features.size)
            kinds = torch.as_tensor(TF.frame_kinds(frames, keys)).expand(batch, frames)

            def network(x=x, kinds=kinds):
                with torch.inference_mode():
                    model.network(x, kinds)

            def complete(q=q, r=r):
                model.complete_windows(q, r, keys)

            timings[(threads, batch)] = {
                "network_ms": timed_ms(network, args.repeat)["median"],
                "complete_ms": timed_ms(complete, args.repeat)["median"],
            }
            if args.onnx and threads == 1:
                timings[(threads, batch)]["onnx_complete_ms"] = timed_ms(
                    lambda q=q, r=r: graph_model.complete_windows(q, r, keys), args.repeat)["median"]
    torch.set_num_threads(default_threads)
    report = {
        "matmul_gflops_1_thread": matmul_gflops(),
        "model": args.model or "paper size (8 x 256, FFN 512, 8 heads), random weights",
        "frames": frames,
        "repeat": args.repeat,
        "results": [{"threads": t, "batch": b, **v, "goal_ms": GOAL_MS[b], "paper_ms": PAPER_MS[b],
                     "complete_vs_paper": v["complete_ms"] / PAPER_MS[b]} for (t, b), v in timings.items()],
    }
    name = f"transformer-{Path(args.model).name}" if args.model else "transformer"
    record = bench.record(name, report, goals(report["results"], default_threads), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0
    print(results.summary(record))
    print(f"float32 matrix products on one thread: {report['matmul_gflops_1_thread']:.0f} GFLOP/s")
    print(f"model: {report['model']}; in-betweening of 30 frames ({frames} frames in), median of {args.repeat}")
    print(f"{'threads':>7} {'batch':>5} {'network ms':>11} {'complete ms':>12} {'goal ms':>8} {'paper ms':>9} {'vs paper':>9}")
    for row in report["results"]:
        print(f"{row['threads']:>7} {row['batch']:>5} {row['network_ms']:>11.2f} {row['complete_ms']:>12.2f} "
              f"{row['goal_ms']:>8.0f} {row['paper_ms']:>9.0f} {row['complete_vs_paper']:>9.2f}")
        if "onnx_complete_ms" in row:
            print(f"{'onnx':>7} {row['batch']:>5} {'':>11} {row['onnx_complete_ms']:>12.2f} {row['goal_ms']:>8.0f}")
    results.print_goals(record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
