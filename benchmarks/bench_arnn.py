"""ARNN on the hopping lamp: inference speed, and the quality rows of Zhang & van de Panne 2018, Tables 1-2.

Inference (``--inference``), each the median of ``--repeat`` calls in one
process on a 3-hop sequence (87 frames, 9 keys), with the model loaded once:

* ``network``: :meth:`LampModel.predict`, encoding, the 86 autoregressive
  steps in ``inference_mode`` and decoding;
* ``complete``: ``keyfill.learn.registry.complete(..., "arnn")``, the whole
  method of ``keyfill complete``: reading the keys' variables, the network,
  the exact-keys correction, the output Motion;
* ``cubic``: the same call with the cubic spline, as a peer in the same run;
* ``cli``: ``keyfill complete KEYS -o OUT --method arnn`` as a new process
  (Python start, imports, model file, USD read and write), median of 5.

The goal is under 20 ms for ``complete``.

Quality (``--tables DATA``): every ``--model LABEL=PATH`` and the spline
baselines scored by :func:`keyfill.learn.protocols.keys.evaluate` on the test
split of the dataset (the last 20 % of its sequences) with all keys and with
1-2 keys deleted; a markdown table with key, frame and total loss, the frame
loss relative to cubic, and each model's training time from its config.

Each part is recorded (``results.py``; not with ``--no-record``): ``benchmarks/results/arnn-inference.json``
(``frames``, ``keys``, ``model``, ``threads``, ``repeat`` and the timings above, each ``median`` and
``best`` in ms) and ``arnn-tables.json`` (``data``, ``test_sequences``, ``seed`` and ``rows``: per model
``label``, ``path``, ``arch``, ``curriculum``, ``epochs``, training minutes, and the scores
``all_keys`` / ``deleted_keys``; then each model with exact keys, cubic and linear). The first model
with the ARNN architecture and the curriculum is the one the goals judge.

    .venv/bin/python benchmarks/bench_arnn.py --inference
    .venv/bin/python benchmarks/bench_arnn.py --tables data/hops \\
        --model "ARNN, curriculum=data/models/arnn" --model "ARNN, no curriculum=data/models/arnn-nocurr"
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import results
import torch
from timing import timed_ms

ROOT = Path(__file__).resolve().parents[1]
GOAL_MS = 20.0


def inference(keys_file: Path, model: str | None, repeat: int) -> dict:
    from keyfill import io
    from keyfill.characters.lamp import to_variables
    from keyfill.learn.arnn import model as arnn
    from keyfill.learn.completion import CompleteOptions
    from keyfill.learn.lamp_data import LampSequence
    from keyfill.learn.registry import complete

    motion = io.load(keys_file)
    keys = motion.keys
    path = model or str(arnn.DEFAULT_MODEL)
    loaded = arnn.load(path)
    values = np.zeros((motion.num_frames, 6))
    values[keys.frames] = to_variables(motion.frames(keys.frames))
    seq = LampSequence(values, keys.frames)
    options = CompleteOptions(model=path)
    out = {
        "frames": motion.num_frames,
        "keys": len(keys),
        "load_ms": timed_ms(lambda: arnn.load(path), max(5, repeat // 10)),
        "network_ms": timed_ms(lambda: loaded.predict([seq]), repeat),
        "complete_ms": timed_ms(lambda: complete(motion, keys, "arnn", options), repeat),
        "cubic_ms": timed_ms(lambda: complete(motion, keys, "cubic"), repeat),
    }
    exe = shutil.which("keyfill", path=str(Path(sys.executable).parent)) or "keyfill"
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [exe, "complete", str(keys_file), "-o", str(Path(tmp) / "out.usda"), "--method", "arnn"]
        if model:
            cmd += ["--model", model]
        out["cli_ms"] = timed_ms(lambda: subprocess.run(cmd, check=True, capture_output=True), 5, warmup=1)
    return out


def tables(data: str, models: list[tuple[str, str]], seed: int) -> dict:
    from keyfill.learn.arnn import model as arnn
    from keyfill.learn.lamp_data import read_sequences, split
    from keyfill.learn.protocols.keys import evaluate

    test = split(read_sequences(data))["test"]
    rows = []
    for label, path in models:
        model = arnn.load(path)
        rep = evaluate(label, test, model, seed=seed)
        training = model.config.get("training", {})
        rows.append({"label": label, "path": path, "arch": model.arch,
                     "curriculum": training.get("settings", {}).get("curriculum"),
                     "epochs": training.get("epochs"), "train_minutes": round(training.get("seconds", 0) / 60, 1),
                     "train_cpu_minutes": round(training["cpu_seconds"] / 60, 1) if "cpu_seconds" in training else None,
                     **{c: s.as_dict() for c, s in rep.scores.items()}})
        rep = evaluate(label + " + exact keys", test, model, exact_keys=True, seed=seed)
        rows.append({"label": rep.method, "path": path, **{c: s.as_dict() for c, s in rep.scores.items()}})
    for name in ("cubic", "linear"):
        rep = evaluate(name, test, seed=seed)
        rows.append({"label": name, **{c: s.as_dict() for c, s in rep.scores.items()}})
    return {"data": data, "test_sequences": len(test), "seed": seed, "rows": rows}


def inference_goals(figures: dict) -> list[dict]:
    """Issue 4's goal: a 3-hop completion under 20 ms (the median of ``complete``)."""
    ms = figures["complete_ms"]["median"]
    return [results.goal(4, f"3-hop lamp completion under {GOAL_MS:g} ms", f"{ms:.1f} ms (median of "
                                                                            f"{figures['repeat']})", ms < GOAL_MS)]


def _totals(rows: list[dict]) -> str:
    return " / ".join(f"{r['all_keys']['total']:.5f}" for r in rows)


def table_goals(rows: list[dict]) -> list[dict]:
    """The goals of issues 4 and 14 on Tables 1-2, judged for the first ARNN trained with the curriculum."""
    trained = [r for r in rows if "arch" in r]
    subject = next((r for r in trained if r["arch"] == "arnn" and r["curriculum"]), None)
    if subject is None:
        return []
    cubic = next(r for r in rows if r["label"] == "cubic")
    a, d = (subject[p]["frame"] / cubic[p]["frame"] for p in ("all_keys", "deleted_keys"))
    out = [results.goal(4, "ARNN frame error at most half of cubic's, with all keys and with 1-2 keys deleted",
                        f"{a:.2f}x (all keys), {d:.2f}x (deleted)", a <= 0.5 and d <= 0.5)]
    for goal_issue, text, others in (
            (4, "Table 1: the curriculum beats none", [r for r in trained if r["arch"] == "arnn" and not r["curriculum"]]),
            (14, "the ARNN has the lowest total of the three architectures in both tables",
             [r for r in trained if r["arch"] != "arnn" and r["curriculum"]])):
        if others:
            wins = all(subject[p]["total"] < r[p]["total"] for r in others for p in ("all_keys", "deleted_keys"))
            deleted = " / ".join(f"{r['deleted_keys']['total']:.5f}" for r in others)
            out.append(results.goal(goal_issue, text, f"total {subject['all_keys']['total']:.5f} against "
                                    f"{_totals(others)} (all keys), {subject['deleted_keys']['total']:.5f} against "
                                    f"{deleted} (deleted)", wins))
    out.append(results.goal(14, "ARNN frame error at most 0.8x cubic's (all keys) and 0.45x (1-2 keys deleted)",
                            f"{a:.2f}x and {d:.2f}x", a <= 0.8 and d <= 0.45))
    return out


def markdown(rows: list[dict], test_sequences: int) -> str:
    cubic = next(r for r in rows if r["label"] == "cubic")
    head = ("| method | key | frame | total | frame / cubic | key (1-2 deleted) | frame (1-2 deleted) | "
            "total (1-2 deleted) | frame / cubic (1-2 deleted) | training |\n|---|---|---|---|---|---|---|---|---|---|")
    lines = [head]
    for r in rows:
        a, d = r["all_keys"], r["deleted_keys"]
        train = ""
        if r.get("epochs"):
            cpu = f"{r['train_cpu_minutes']} CPU-min, " if r.get("train_cpu_minutes") is not None else ""
            train = f"{r['epochs']} epochs, {cpu}{r['train_minutes']} min wall"
        lines.append(
            f"| {r['label']} | {a['key']:.5f} | {a['frame']:.5f} | {a['total']:.5f} | "
            f"{a['frame'] / cubic['all_keys']['frame']:.2f} | {d['key']:.5f} | {d['frame']:.5f} | {d['total']:.5f} | "
            f"{d['frame'] / cubic['deleted_keys']['frame']:.2f} | {train} |"
        )
    return "\n".join(lines) + f"\n\n({test_sequences} test sequences; losses on standardised variables)"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--inference", action="store_true", help="time completions of one 3-hop sequence")
    ap.add_argument("--keys", type=Path, default=ROOT / "examples" / "lamp" / "keys.usda",
                    help="lamp key file for --inference")
    ap.add_argument("--tables", metavar="DATA", help="score models on the test split of this dataset folder")
    ap.add_argument("--model", action="append", default=[], metavar="LABEL=PATH",
                    help="a model for --tables (repeatable); for --inference, the model to time")
    ap.add_argument("--repeat", type=int, default=100)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0, help="seed of the key deletions")
    ap.add_argument("--json", action="store_true", help="print the records as JSON")
    results.add_option(ap)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    report = {}
    if args.inference:
        bench = results.Run()
        model = args.model[0].split("=", 1)[-1] if args.model else None
        figures = {**inference(args.keys, model, args.repeat), "model": model, "threads": args.threads,
                   "repeat": args.repeat}
        report["inference"] = bench.record("arnn-inference", figures, inference_goals(figures),
                                           write=not args.no_record)
    if args.tables:
        bench = results.Run()
        figures = tables(args.tables, [tuple(m.split("=", 1)) for m in args.model], args.seed)
        report["tables"] = bench.record("arnn-tables", figures, table_goals(figures["rows"]), write=not args.no_record)
    if args.json:
        print(results.dumps(report), end="")
        return
    for record in report.values():
        print(results.summary(record))
        results.print_goals(record)
    if "inference" in report:
        r = report["inference"]["figures"]
        print(f"3-hop sequence, {r['frames']} frames, {r['keys']} keys:          median      best")
        rows = [("network", "network_ms", ""), ("complete", "complete_ms", f"goal {GOAL_MS:.0f} ms"),
                ("cubic", "cubic_ms", "peer, same run"), ("load", "load_ms", "model folder, once per process"),
                ("cli", "cli_ms", "keyfill complete as a new process")]
        for name, key, note in rows:
            print(f"  {name:<9} {r[key]['median']:24.2f} ms {r[key]['best']:8.2f} ms   {note}")
        print(f"  complete / goal: {r['complete_ms']['median'] / GOAL_MS:.2f} (median), "
              f"{r['complete_ms']['best'] / GOAL_MS:.2f} (best)")
    if "tables" in report:
        f = report["tables"]["figures"]
        print(markdown(f["rows"], f["test_sequences"]))


if __name__ == "__main__":
    main()
