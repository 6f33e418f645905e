"""Build the matched-start training set of issue 46 (:mod:`keyfill.learn.transformer.starts`).

Bandai-Namco dataset-2 without its held-out ``normal`` style (the shipped transformer's corpus), in two folds
by style: the active, elderly and exhausted clips are matched against a library of the feminine and masculine
clips, and those against a library of the first three, so that no window is matched from its own clip.
``--dataset-1`` adds dataset-1 without its held-out ``normal``, ``sad`` and ``feminine`` styles, six styles to
each fold. Windows of 65 frames at most, every ``--offset`` frames, keyed every 20, 30, 40 and 60 frames. The
two folds run in parallel (``--workers``, one per fold).

    .venv/bin/python benchmarks/transformer_starts.py -o data/starts/bandai2.npz
    .venv/bin/python benchmarks/transformer_starts.py --dataset-1 -o data/starts/bandai12.npz
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

#: each fold's file patterns: the styles of dataset-2 and (with --dataset-1) of dataset-1
FOLDS = ([f"dataset-2_*_{s}_*" for s in ("active", "elderly", "exhausted")],
         [f"dataset-2_*_{s}_*" for s in ("feminine", "masculine")])
FOLDS_1 = ([f"dataset-1_*_{s}_*" for s in ("active", "angry", "childish", "chimpira", "giant", "happy")],
           [f"dataset-1_*_{s}_*" for s in ("masculinity", "musical", "not-confident", "old", "proud", "tired")])
WINDOW = 65


def one_fold(folders: list[str], patterns: list[str], library: str, offset: int) -> dict:
    from keyfill.learn.completion import CompleteOptions
    from keyfill.learn.library.matcher import Matcher
    from keyfill.learn.library.store import clip_files
    from keyfill.learn.library.store import load as load_library
    from keyfill.learn.transformer import model as T
    from keyfill.learn.transformer import starts

    model = T.load(T.model_path(CompleteOptions()))
    return starts.match_windows(Matcher(load_library(library)), clip_files(folders, include=patterns),
                                model.skeleton, model.folded, WINDOW, offset)


def fold_libraries(folders: list[str], folds, stem: Path, workers: int) -> list[str]:
    """Library ``n`` of each fold's clips (``STEM-library-N``, half precision), which matches the *other* fold."""
    from keyfill.learn.library.store import build

    out = []
    for n, patterns in enumerate(folds):
        lib = stem.parent / f"{stem.name}-library-{n}"
        build(folders, lib, include=patterns, precision="half", workers=workers)
        out.append(str(lib))
    return out


def main(argv=None) -> int:
    import numpy as np

    from keyfill.learn.corpus import locate
    from keyfill.learn.transformer import starts

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", required=True, help="the .npz start set to write")
    ap.add_argument("--offset", type=int, default=30, help="frames between window starts (default 30)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--dataset-1", action="store_true", help="add dataset-1's styles to the folds")
    args = ap.parse_args(argv)
    folders = [str(locate("bandai2"))] + ([str(locate("bandai1"))] if args.dataset_1 else [])
    folds = [a + b for a, b in zip(FOLDS, FOLDS_1)] if args.dataset_1 else list(FOLDS)
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    libraries = fold_libraries(folders, folds, out.parent / out.stem, args.workers)
    print(f"libraries built in {time.perf_counter() - t0:.0f} s", flush=True)
    with ProcessPoolExecutor(args.workers) as pool:
        jobs = [pool.submit(one_fold, folders, folds[n], libraries[1 - n], args.offset) for n in range(len(folds))]
        parts = [j.result() for j in jobs]
    arrays = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    starts.save(arrays, out)
    counts = {s: len(arrays[f"truth_q_{s}"]) for s in starts.SPACINGS}
    print(f"wrote {out}: windows per key spacing {counts} in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
