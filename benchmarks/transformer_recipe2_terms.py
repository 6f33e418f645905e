"""The loss magnitudes of the transformer's realism terms (foot_weight, smooth_weight) on issue 30's data.

They set the terms' trial weights (0.3 and 0.00025); a validation A/B then turned both off in
benchmarks/transformer_recipe2.json (docs/transformer.md, "Retraining for unseen styles").

Not a training and not a record of docs/benchmarks.md: on the first batches of the retraining's data
(Bandai-Namco dataset-2 and dataset-1 without the held-out styles, as ``make transformer-model-2``), with
one torch thread, it prints as JSON the mean of every loss term (the realism terms at weight 1) over
``--batches`` batches for three outputs: the shipped model's network (``pred``), the pre-fill the network
corrects (``prefill``) and the truth (``truth``: the floor of each term), once with the shipped weights and
once with a fresh network. About a minute once the corpus is cached.

    .venv/bin/python benchmarks/transformer_recipe2_terms.py [--batches 8]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

from keyfill.learn.corpus import locate

EXCLUDE = ("*_normal_*", "*_elderly_*", "dataset-1_*_old_*", "dataset-1_*_sad_*", "dataset-1_*_feminine_*")
SHIPPED = "models/bandai/keyfill_models_bandai/bandai2-transformer"
RECIPE = "benchmarks/transformer_recipe2.json"


def main(argv=None) -> int:
    import torch

    from keyfill.learn.corpus import load_corpus
    from keyfill.learn.transformer.task import TransformerTask, read_config

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batches", type=int, default=8)
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    corpus = load_corpus([locate("bandai2"), locate("bandai1")]).select((), EXCLUDE)
    model_cfg, train_cfg = read_config(RECIPE)
    model_cfg = dataclasses.replace(model_cfg, foot_weight=1.0, smooth_weight=1.0)  # the terms as they are
    out = {"recipe": RECIPE, "exclude": list(EXCLUDE), "batches": args.batches}
    for name, init in (("shipped", SHIPPED), ("fresh", None)):
        t0 = time.perf_counter()
        task = TransformerTask(corpus, model_cfg, train_cfg, seed=0, init=init)
        torch.manual_seed(0)
        task.build(None)
        task.model.network.eval()
        rows: dict[str, list] = {"pred": [], "prefill": [], "truth": []}
        for _, batch in zip(range(args.batches), task.batches(0)):
            x, kinds = batch[0], batch[4]
            with torch.no_grad():
                for kind, output in (("pred", task.model.network(x, kinds)), ("prefill", x), ("truth", batch[1])):
                    rows[kind].append({k: float(v) for k, v in task.losses(output, batch).items() if k != "total"})
        out[name] = {kind: {k: float(np.mean([r[k] for r in v])) for k in v[0]} for kind, v in rows.items()}
        out[name]["seconds"] = round(time.perf_counter() - t0, 1)
        out["data"] = {k: task.info[k] for k in ("train_clips", "train_windows", "validation_clips",
                                                  "contact_columns", "mirrored")}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
