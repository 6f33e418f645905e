"""Batch completion against single calls, and the ONNX runtime against torch.

Batch (issue 16's goal: at least 20x per file): ``--files`` lamp key files (copies
of ``examples/lamp/keys.usda`` under many names) are completed with the
built-in ARNN by *one* command::

    keyfill complete IN/ -o OUT/ --method arnn --workers W

and, in the same run, a sample of ``--singles`` of them by one command each::

    keyfill complete IN/hop_NNNN.usda -o OUT1/hop_NNNN.usda --method arnn

(1,000 single calls take tens of CPU-minutes on a loaded machine; the sample's
median stands for them, and its size is printed). Per-file times and their
ratio are reported.

ONNX (goals: start-up at most half of torch's; 1 x 30 latency no worse):

* start-up: ``keyfill complete keys.usda --method arnn`` with torch, and with
  the exported graph (``--model lamp-arnn.onnx``), medians of ``--repeat``
  alternating subprocess runs; the same for a transformer model folder of the
  default architecture (8 layers, d_model 256; random weights: no transformer
  ships) with and without its ``model.onnx``;
* latency of one 30-frame window: the transformer network alone (torch vs
  onnxruntime, one thread each) and a 30-frame lamp completion of the network
  (``predict``), in process.

The run is recorded in ``benchmarks/results/batch.json`` (``results.py``; not with
``--no-record``): ``batch`` (left out with ``--skip-batch``), ``startup``, ``latency`` (parity
included) and ``seconds``.

    .venv/bin/python benchmarks/bench_batch.py                 # --files 1000 --singles 20 --repeat 7
    .venv/bin/python benchmarks/bench_batch.py --json
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import results
from bench_complete import keyfill_command, timed_run
from timing import timed_ms

ROOT = Path(__file__).resolve().parents[1]
LAMP_KEYS = ROOT / "examples" / "lamp" / "keys.usda"
BATCH_GOAL, STARTUP_GOAL, PARITY_GOAL = 20.0, 0.5, 1e-4


def batch_vs_single(work: Path, files: int, singles: int, workers: int | None) -> dict:
    src = work / "in"
    src.mkdir()
    for i in range(files):
        shutil.copy(LAMP_KEYS, src / f"hop_{i:04d}.usda")
    kf = keyfill_command()
    one = work / "one"
    one.mkdir()
    picks = np.linspace(0, files - 1, singles).astype(int)
    single = []
    for i in picks:
        name = f"hop_{i:04d}.usda"
        single.append(timed_run([*kf, "complete", str(src / name), "-o", str(one / name), "--method", "arnn"])[0])
    cmd = [*kf, "-q", "complete", str(src), "-o", str(work / "out") + "/", "--method", "arnn", "--json"]
    if workers:
        cmd += ["--workers", str(workers)]
    wall, cpu = timed_run(cmd)
    outputs = sorted((work / "out").glob("*.usda"))
    assert len(outputs) == files, f"{len(outputs)} outputs of {files}"
    per_single = statistics.median(single)
    shown = {str(src): "IN/", str(work / "out") + "/": "OUT/"}
    per_batch = wall / files
    return {"files": files, "single_sample": int(singles), "single_median_s": per_single,
            "single_best_s": min(single), "batch_wall_s": wall, "batch_cpu_s": cpu, "batch_per_file_s": per_batch,
            "ratio": per_single / per_batch, "workers": workers or "default (one per core)",
            "batch_command": " ".join(["keyfill", *(shown.get(a, a) for a in cmd[len(kf):])])}


def startup(work: Path, repeat: int) -> dict:
    """Subprocess wall times of a single ``complete``: torch vs the exported graph (ARNN, transformer)."""
    import torch

    from keyfill.learn.transformer import config as TC
    from keyfill.learn.transformer import model as T
    from keyfill.motion import Keys

    sys.path.insert(0, str(ROOT / "tests"))
    from synthetic_corpus import walker_motion, walker_skeleton

    from keyfill import io

    kf = keyfill_command()
    graph = work / "lamp-arnn.onnx"
    subprocess_ok = timed_run([*kf, "export", "arnn", "-o", str(graph)])
    skeleton = walker_skeleton(static_root=False)
    motion = walker_motion(skeleton, 40, np.random.default_rng(0))
    with torch.random.fork_rng():
        torch.manual_seed(0)
        model = T.new_model(skeleton, TC.ModelConfig(dropout=0.0), np.zeros(21), np.full(21, 30.0), folded=False)
        with torch.no_grad():  # every layer random, the zero-initialised output too (else it returns its input)
            for p in model.network.parameters():
                p.add_(0.02 * torch.randn(p.shape))
    torch_folder, onnx_folder = work / "tf-torch", work / "tf-onnx"
    model.save(torch_folder)
    model.save(onnx_folder)
    timed_run([*kf, "export", str(onnx_folder)])
    io.save(motion.replace(keys=Keys([0, 10, 29])), work / "walk.bvh")
    cases = {
        "arnn_torch": [*kf, "complete", str(LAMP_KEYS), "-o", str(work / "a.usda"), "--method", "arnn"],
        "arnn_onnx": [*kf, "complete", str(LAMP_KEYS), "-o", str(work / "b.usda"), "--method", "arnn",
                      "--model", str(graph)],
        "transformer_torch": [*kf, "complete", str(work / "walk.bvh"), "-o", str(work / "c.bvh"), "--method",
                              "transformer", "--model", str(torch_folder), "--keys", "0,10,29"],
        "transformer_onnx": [*kf, "complete", str(work / "walk.bvh"), "-o", str(work / "d.bvh"), "--method",
                             "transformer", "--model", str(onnx_folder), "--keys", "0,10,29"],
    }
    for cmd in cases.values():  # warm the file cache
        timed_run(cmd)
    times = {k: [] for k in cases}
    for _ in range(repeat):
        for k, cmd in cases.items():
            times[k].append(timed_run(cmd)[0])
    out = {k: {"median_s": statistics.median(v), "best_s": min(v)} for k, v in times.items()}
    for m in ("arnn", "transformer"):
        out[f"{m}_onnx_over_torch"] = out[f"{m}_onnx"]["median_s"] / out[f"{m}_torch"]["median_s"]
    del subprocess_ok
    return out, model, graph


def latency(model, graph: Path, work: Path, repeat: int) -> dict:
    """In-process latency of one 30-frame window, torch vs onnxruntime (one thread each)."""
    import torch

    from keyfill import io
    from keyfill.characters.lamp import to_variables
    from keyfill.learn import onnx as kx
    from keyfill.learn.arnn import model as arnn
    from keyfill.learn.arnn.onnx import OnnxLampModel
    from keyfill.learn.lamp_data import LampSequence

    torch.set_num_threads(1)
    tf_graph = kx.Graph(work / "tf-onnx" / kx.GRAPH)
    net = model.network.eval()
    x = np.random.default_rng(0).normal(size=(1, 30, model.features.size)).astype(np.float32)
    kinds = np.ones((1, 30), dtype=np.int64)
    kinds[:, [0, 29]] = 0
    xt, kt = torch.from_numpy(x), torch.from_numpy(kinds)

    def torch_tf():
        with torch.inference_mode():
            net(xt, kt)

    out = {"transformer_1x30_torch_ms": timed_ms(torch_tf, repeat),
           "transformer_1x30_onnx_ms": timed_ms(lambda: tf_graph.run({"features": x, "kinds": kinds}), repeat)}
    motion = io.load(LAMP_KEYS)
    k = motion.keys.frames[motion.keys.frames <= 29]
    k = np.append(k, 29) if k[-1] != 29 else k
    values = np.zeros((30, 6))
    values[k] = to_variables(motion.frames(k))
    seq = [LampSequence(values, k)]
    torch_lamp, onnx_lamp = arnn.load(arnn.DEFAULT_MODEL), OnnxLampModel(kx.Graph(graph))
    out["arnn_1x30_torch_ms"] = timed_ms(lambda: torch_lamp.predict(seq), repeat)
    out["arnn_1x30_onnx_ms"] = timed_ms(lambda: onnx_lamp.predict(seq), repeat)
    # parity: the largest difference relative to the data's scale
    rng = np.random.default_rng(1)
    worst = 0.0
    for B, T in ((1, 30), (4, 17), (2, 65)):
        xr = rng.normal(size=(B, T, model.features.size)).astype(np.float32)
        kr = rng.integers(0, 3, size=(B, T))
        with torch.inference_mode():
            ref = net(torch.from_numpy(xr), torch.from_numpy(kr)).numpy()
        got = tf_graph.run({"features": xr, "kinds": kr})[0]
        worst = max(worst, float(np.abs(got - ref).max() / np.abs(ref).max()))
    out["transformer_parity_relative"] = worst
    full = [LampSequence(np.where(np.isin(np.arange(87), motion.keys.frames)[:, None],
                                  to_variables(motion), 0.0), motion.keys.frames)]
    full += [LampSequence(rng.normal(scale=0.5, size=(n, 6)), [0, n // 3, n - 1]) for n in (10, 30, 140)]
    scale = torch_lamp.normalizer.std
    out["arnn_parity_relative_to_std"] = max(float((np.abs(a - b) / scale).max())
                                             for a, b in zip(onnx_lamp.predict(full), torch_lamp.predict(full)))
    return out


def goals(result: dict) -> list[dict]:
    """Issue 16's goals: batch per file, ONNX start-up, 1 x 30 latency, parity."""
    out = []
    if "batch" in result:
        b = result["batch"]
        out.append(results.goal(16, f"{b['files']:,} lamp files in one batch command at least {BATCH_GOAL:g}x faster "
                                    "per file than single calls", f"{1e3 * b['batch_per_file_s']:.0f} ms against "
                                    f"{b['single_median_s']:.2f} s per file: {b['ratio']:.0f}x", b["ratio"] >= BATCH_GOAL))
    s, lat = result["startup"], result["latency"]
    ratios = {m: s[f"{m}_onnx_over_torch"] for m in ("arnn", "transformer")}
    out.append(results.goal(16, "start-up of one `complete` with the ONNX runtime at most half of torch's",
                            f"ARNN {ratios['arnn']:.2f}x, transformer {ratios['transformer']:.2f}x",
                            all(r <= STARTUP_GOAL for r in ratios.values())))
    ms = {m: (lat[f"{m}_1x30_onnx_ms"]["median"], lat[f"{m}_1x30_torch_ms"]["median"]) for m in ("transformer", "arnn")}
    out.append(results.goal(16, "1 x 30 frames with onnxruntime no slower than torch",
                            f"transformer {ms['transformer'][0]:.1f} against {ms['transformer'][1]:.1f} ms, ARNN "
                            f"{ms['arnn'][0]:.1f} against {ms['arnn'][1]:.1f} ms", all(o <= t for o, t in ms.values())))
    parity = (lat["transformer_parity_relative"], lat["arnn_parity_relative_to_std"])
    out.append(results.goal(16, "onnxruntime equals torch to 1e-4 of the data's scale",
                            f"transformer {parity[0]:.1e}, ARNN {parity[1]:.1e}", max(parity) <= PARITY_GOAL))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--files", type=int, default=1000, help="lamp files of the batch")
    ap.add_argument("--singles", type=int, default=20, help="single calls timed beside it (a sample)")
    ap.add_argument("--workers", type=int, help="--workers of the batch command (default: keyfill's)")
    ap.add_argument("--repeat", type=int, default=7, help="runs per start-up case")
    ap.add_argument("--skip-batch", action="store_true")
    ap.add_argument("--json", action="store_true", help="print the record as JSON")
    results.add_option(ap)
    args = ap.parse_args(argv)
    bench = results.Run()
    result = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        t = time.perf_counter()
        if not args.skip_batch:
            (work / "batch").mkdir()
            result["batch"] = batch_vs_single(work / "batch", args.files, args.singles, args.workers)
            result["batch"]["load_after"] = list(os.getloadavg())
        result["startup"], model, graph = startup(work, args.repeat)
        result["latency"] = latency(model, graph, work, 50)
        result["seconds"] = time.perf_counter() - t
    record = bench.record("batch", result, goals(result), write=not args.no_record)
    if args.json:
        print(results.dumps(record), end="")
        return 0
    print(results.summary(record))
    if "batch" in result:
        b = result["batch"]
        print(f"batch: {b['files']} lamp files by one command: {b['batch_wall_s']:.1f} s wall "
              f"({1e3 * b['batch_per_file_s']:.1f} ms per file; {b['batch_command']})")
        print(f"single calls (a sample of {b['single_sample']}): median {b['single_median_s']:.2f} s per file, "
              f"best {b['single_best_s']:.2f} s")
        print(f"ratio single / batch per file: {b['ratio']:.0f}x (goal >= 20x)")
    s = result["startup"]
    for m in ("arnn", "transformer"):
        print(f"start-up, complete --method {m}: torch {s[m + '_torch']['median_s']:.2f} s, onnx "
              f"{s[m + '_onnx']['median_s']:.2f} s (onnx/torch {s[m + '_onnx_over_torch']:.2f}; goal <= 0.5)")
    lat = result["latency"]
    for m in ("transformer", "arnn"):
        print(f"1 x 30 frames, {m} network: torch {lat[m + '_1x30_torch_ms']['median']:.2f} ms, onnx "
              f"{lat[m + '_1x30_onnx_ms']['median']:.2f} ms (medians)")
    print(f"parity: transformer {lat['transformer_parity_relative']:.1e} of the output scale, ARNN "
          f"{lat['arnn_parity_relative_to_std']:.1e} of the variables' std (goal 1e-4)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
