"""Build the matched set a gan on a matched base trains on (issue 45, :mod:`keyfill.learn.gan.matched_base`).

The gan's corpus (Bandai-Namco dataset-2 and dataset-1 without the held-out ``normal``, ``sad`` and
``feminine`` styles) in the two folds by style of ``transformer_starts.py --dataset-1``: each fold's clips are
matched against a library of the other fold's (the same libraries, ``data/starts/bandai12-library-N``, built
when missing), so that no window is matched from its own clip. ``--per-clip`` windows per clip, laid out as the
gan's in-clip windows are (``GanConfig`` of ``--config``: whole short clips keyed every 30-60 frames, crops of
longer ones keyed every ``min_key_every``-``max_key_every``, the LaFAN1 layout a quarter of the time), matched
with seed 0, feet free. The two folds run in parallel (``--workers``).

    .venv/bin/python benchmarks/gan_matched_set.py --config benchmarks/gan_recipe6_match_seen.json -o data/starts/gan12.npz
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from transformer_starts import FOLDS, FOLDS_1, fold_libraries


def one_fold(folders: list[str], patterns: list[str], library: str, settings: dict, per_clip: int) -> dict:
    from keyfill.learn.gan import model as G
    from keyfill.learn.gan.config import GanConfig
    from keyfill.learn.gan.matched_set import match_rows
    from keyfill.learn.library.matcher import Matcher
    from keyfill.learn.library.store import clip_files
    from keyfill.learn.library.store import load as load_library

    gan = G.load_model(G.DEFAULT_MODEL)  # the skeleton and hierarchy of the corpus the gan trains on
    cfg = GanConfig.from_json(settings)
    return match_rows(Matcher(load_library(library)), clip_files(folders, include=patterns), gan.skeleton,
                      gan.folded, cfg, per_clip)


def main(argv=None) -> int:
    import numpy as np

    from keyfill.learn.corpus import locate
    from keyfill.learn.gan.matched_set import save

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", required=True, help="the .npz matched set to write")
    ap.add_argument("--config", required=True, help="the recipe (GAN settings JSON) whose windows are matched")
    ap.add_argument("--per-clip", type=int, default=6, help="windows per clip (default 6)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    settings = json.loads(Path(args.config).read_text())
    folders = [str(locate("bandai2")), str(locate("bandai1"))]
    folds = [a + b for a, b in zip(FOLDS, FOLDS_1)]
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    libraries = fold_libraries(folders, folds, out.parent / "bandai12", args.workers)
    print(f"libraries ready in {time.perf_counter() - t0:.0f} s", flush=True)
    with ProcessPoolExecutor(args.workers) as pool:
        jobs = [pool.submit(one_fold, folders, folds[n], libraries[1 - n], settings, args.per_clip)
                for n in range(len(folds))]
        parts = [j.result() for j in jobs]
    offset = len(parts[0]["clips"])
    K = max(p["row_keys"].shape[1] for p in parts)
    arrays = {
        "clips": np.concatenate([p["clips"] for p in parts]),
        "row_clip": np.concatenate([parts[0]["row_clip"], parts[1]["row_clip"] + offset]),
        "row_keys": np.concatenate([np.pad(p["row_keys"], ((0, 0), (0, K - p["row_keys"].shape[1])),
                                           constant_values=-1) for p in parts]),
        **{k: np.concatenate([p[k] for p in parts]) for k in ("row_start", "row_length", "quats", "root")},
    }
    save(arrays, out)
    print(f"wrote {out}: {len(arrays['row_clip'])} windows of {len(arrays['clips'])} clips, "
          f"{len(arrays['quats'])} frames, in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
