"""Each step of the gan's second recipe, taken out one at a time (issue 31: docs/gan.md, The second recipe).

Short runs of the Motion DNA generator, all from the same seed, data and frozen path predictor, each
``--epochs`` epochs of 200 steps with the cosine schedule over that length: the full recipe
(``benchmarks/gan_recipe2.json``) and the recipe with one setting put back to the first recipe's.
Figures are the training log's held-out validation after the last epoch, on the validation clips of the
*training* styles (settings are chosen there, never on the held-out styles):

* ``window_error`` (cm): in-clip windows (keys every 15-90 frames, LaFAN1 layouts, short clips), the mean
  world joint position error on the frames between keys, the path moved onto the key roots;
* ``window_foot_speed`` (cm/s): the horizontal speed of the feet where the real clip has them in contact;
* ``key_joint_error`` / ``key_root_error`` (cm): at the keys of the paper's long sequences (Appendix C);
* the share of the generator's pre-``tanh`` joint values beyond 2 on those windows (saturation).

::

    .venv/bin/python benchmarks/bench_gan_ablation.py data/models/bandai2-gan-path --epochs 5 --jobs 2

Runs already finished in ``--work`` (default ``data/ablation``) are reused. Without the corpora the script
says ``skipped`` and exits 0. The record is ``benchmarks/results/gan_ablation.json``: ``epochs``, ``runs``
(``{name: {"changes", figures...}}``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import results

from keyfill.errors import DataError
from keyfill.learn.corpus import locate

RECIPE = Path(__file__).resolve().parent / "gan_recipe2.json"
#: each run: the settings that differ from the second recipe (the first recipe's values)
RUNS = {
    "second recipe": {},
    "without in-clip windows": {"in_clip_fraction": 0.0},
    "printed Eq. 6, default output init": {"residual_form": "printed", "output_init": "default"},
    "transposed up-sampling": {"upsampling": "transposed"},
    "centred root input": {"root_input": "centred"},
    "without reconstruction term": {"recon_weight": 0.0},
    "without foot-sliding term": {"foot_weight": 0.0},
    "RMSprop at a constant rate, no moving average": {"optimizer": "rmsprop", "lr_schedule": "constant",
                                                       "lr_generator": 1e-4, "lr_discriminator": 1e-4,
                                                       "ema_decay": 0.0},
    "spline base (third recipe)": {"base": "spline", "output_init": "zero"},
    "linear base": {"base": "linear", "output_init": "zero"},
    "spline base with adversarial weight 0.1": {"base": "spline", "output_init": "zero", "adv_weight": 0.1},
}
EXCLUDE = ("*_normal_*", "dataset-1_*_sad_*", "dataset-1_*_feminine_*")


def slug(name: str) -> str:
    return "".join(c if c.isalnum() else "-" for c in name).strip("-")


def train(name: str, changes: dict, path_model: str, epochs: int, work: Path, data: list[str]) -> dict:
    """Train (or reuse) one run; its last log row."""
    folder = work / slug(name)
    log = Path(f"{folder}.log.jsonl")
    if not (folder / "weights.safetensors").is_file():
        config = work / f"{slug(name)}.json"
        config.write_text(json.dumps({**json.loads(RECIPE.read_text()), **changes}))
        cmd = [str(Path(sys.executable).with_name("keyfill")), "train", "gan", *data, *[a for p in EXCLUDE for a in ("--exclude", p)],
               "--config", str(config), "--seed", "0", "-o", str(folder), "--stage", "generator", "--dna",
               "--threads", "1", "--epochs", str(epochs), "-q"]
        if changes.get("base", "none") == "none":  # a base gives the root path: no predictor
            cmd += ["--path-model", path_model]
        if Path(f"{folder}.checkpoint.pt").is_file():
            cmd.append("--resume")
        subprocess.run(cmd, check=True)
    rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    return rows[-1]


def saturation(folder: Path, corpus) -> float:
    """The share of pre-tanh joint values beyond 2 over 16 held-out in-clip windows of the run's model
    (``corpus``: the training corpus, whose seeded split gives the validation clips)."""
    import numpy as np
    import torch

    from keyfill.learn.gan.model import load_model
    from keyfill.learn.gan.task import GanTask

    model = load_model(folder)
    spline = model.config.base != "none"  # its windows need the base: the generator stage's pools
    task = GanTask(corpus, model.config, stage="generator" if spline else "path")  # the same validation split
    arrays = task.windows(np.random.default_rng([0, 97]), task.val_pool, 16)
    with torch.no_grad():
        dna = torch.as_tensor(arrays["dna"]) if "dna" in arrays else None
        valid = torch.as_tensor(arrays["dna_valid"]) if "dna_valid" in arrays else None
        noise = torch.zeros(16, model.config.noise_dim, arrays["dense"].shape[-1] // 64)
        base = torch.as_tensor(arrays["base"]) if spline else None
        v = model.generator(torch.as_tensor(arrays["dense"]), noise if model.config.noise_dim else None,
                            dna=dna, dna_valid=valid, base=base)
    return float((v[:, 6:].abs() > 2).float().mean())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("path_model", help="the frozen path predictor (a gan model folder)")
    ap.add_argument("--epochs", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=2, help="runs side by side (one thread each)")
    ap.add_argument("--work", default="data/ablation", help="where the runs' model folders go")
    ap.add_argument("--only", default=None, help="comma-separated run names (default: all)")
    results.add_option(ap)
    args = ap.parse_args(argv)
    try:
        data = [str(locate("bandai2")), str(locate("bandai1"))]
    except DataError as e:
        print(f"skipped: {e}")
        return 0
    bench = results.Run()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    runs = {k: v for k, v in RUNS.items() if args.only is None or k in args.only.split(",")}
    with ThreadPoolExecutor(args.jobs) as pool:
        rows = dict(zip(runs, pool.map(lambda kv: train(kv[0], kv[1], args.path_model, args.epochs, work, data),
                                       runs.items())))
    from keyfill.learn.corpus import load_corpus

    corpus = load_corpus(data).select((), EXCLUDE)  # read once: every run trained on it
    out = {}
    for name, row in rows.items():
        mpu = 0.01  # the Bandai-Namco files are in centimetres: the log's file units
        out[name] = {"changes": runs[name], "window_error_cm": row.get("window_error", float("nan")) * mpu * 100,
                     "window_foot_speed_cm_s": row.get("window_foot_speed", float("nan")) * mpu * 100,
                     "key_joint_error_cm": row["key_joint_error"] * mpu * 100,
                     "key_root_error_cm": row["key_root_error"] * mpu * 100,
                     "saturated_pct": 100 * saturation(work / slug(name), corpus), "seconds": row.get("seconds")}
        r = out[name]
        print(f"{name:<48} window {r['window_error_cm']:6.2f} cm  feet {r['window_foot_speed_cm_s']:6.2f} cm/s  "
              f"keys {r['key_joint_error_cm']:5.2f} / {r['key_root_error_cm']:6.2f} cm  saturated "
              f"{r['saturated_pct']:5.2f} %", flush=True)
    bench.record("gan_ablation", {"epochs": args.epochs, "runs": out}, [], write=not args.no_record)
    print(f"load average: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
