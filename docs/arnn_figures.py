"""Make the ARNN pictures of docs/arnn.md (like Zhang & van de Panne 2018, Figures 8-11) with keyfill's CLI.

From one sequence of the test split of a ``keyfill simulate`` dataset it
writes key files (sparse USD: samples at the keys only), completes them with
``keyfill complete`` (``--method arnn`` with the shipped model, and
``--method cubic``) and draws them with ``keyfill plot``:

* ``arnn_reconstruction.png`` (Figure 8): the sequence's own 9 keys;
* ``arnn_height_edit.png`` (Figure 9): the in-air key of the second hop
  raised or lowered to 0.7x, 1.5x and 1.8x its base height;
* ``arnn_timing_edit.png`` (Figure 10): every in-air key moved ``--shift``
  frames earlier or later (same poses, new times);
* ``arnn_sparse_keys.png`` (Figure 11): the in-air and landing keys of the
  second hop removed.

Completed files keep their keys, which ``keyfill plot`` draws as open circles.
With ``--log`` (a training log, ``MODEL.log.jsonl``) it also draws
``arnn_training.png`` (like Figure 7): the curriculum (teacher forcing, omega)
and the held-out key and frame losses per epoch.

    .venv/bin/python docs/arnn_figures.py --data data/hops --log data/models/lamp-arnn.log.jsonl
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from keyfill import io
from keyfill.characters.lamp import from_variables
from keyfill.io.hops import read_dataset
from keyfill.learn.lamp_data import read_sequences, split
from keyfill.motion import Keys

HERE = Path(__file__).parent
KEYFILL = str(Path(sys.executable).parent / "keyfill")


def keyfill(*args) -> None:
    subprocess.run([KEYFILL, "-q", *map(str, args)], check=True)


def write_keys(values: np.ndarray, keys: np.ndarray, fps: float, path: Path) -> Path:
    """A sparse USD key file: the lamp variables ``values`` at frames ``keys`` (other frames are not written)."""
    io.save(from_variables(values, fps, keys=Keys(keys)), path, sparse=True)
    return path


def complete(keys_file: Path, out: Path, method: str, model: str | None) -> Path:
    extra = ["--model", model] if model and method == "arnn" else []
    keyfill("complete", keys_file, "-o", out, "--method", method, *extra)
    return out


def training_figure(log: Path, out: Path) -> None:
    """The curriculum schedules and the held-out losses of a training log, one panel each."""
    import json

    from keyfill.viz.style import FILE_COLORS, new_figure, save_figure, style

    rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
    epoch = [r["epoch"] for r in rows]
    with style():
        fig = new_figure(7.5, 5.0)
        top, bottom = fig.subplots(2, 1, sharex=True)
        top.plot(epoch, [r["teacher_forcing"] for r in rows], color=FILE_COLORS[2], label="teacher forcing ratio")
        top.plot(epoch, [r["omega"] for r in rows], color=FILE_COLORS[0], label="key importance weight omega")
        top.plot(epoch, [r["lr"] / rows[0]["lr"] for r in rows], color=FILE_COLORS[7], ls="--",
                 label="learning rate / initial")
        top.set_title("curriculum")
        top.legend(loc="center right", frameon=False)
        for key, label, color in (("val_frame", "frame loss, all keys", FILE_COLORS[1]),
                                  ("val_deleted_frame", "frame loss, 1-2 keys deleted", FILE_COLORS[3]),
                                  ("val_key", "key loss, all keys", FILE_COLORS[4])):
            bottom.plot(epoch, [r[key] for r in rows], color=color, label=label)
        bottom.set_yscale("log")
        bottom.set_title("held-out losses (standardised variables)")
        bottom.set_xlabel("epoch")
        bottom.legend(loc="lower left", frameon=False)
        for ax in (top, bottom):
            ax.grid(True, color="#e5e5e5")
        fig.tight_layout()
        save_figure(fig, out, "png")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="data/hops", help="dataset folder made by keyfill simulate")
    ap.add_argument("--sequence", help="sequence id (default: the test sequence with the highest second hop "
                                       "among those whose in-air keys allow --shift)")
    ap.add_argument("--model", help="model folder (default: the shipped lamp model)")
    ap.add_argument("--shift", type=int, default=5, help="frames to move the in-air keys for the timing edit")
    ap.add_argument("--out", type=Path, default=HERE / "img")
    ap.add_argument("--log", type=Path, help="training log to draw as arnn_training.png")
    args = ap.parse_args()
    if args.log:
        args.out.mkdir(parents=True, exist_ok=True)
        training_figure(args.log, args.out / "arnn_training.png")

    test = split(read_sequences(args.data))["test"]
    hops = 3

    def shiftable(s) -> bool:
        k = s.keys.reshape(hops, 3)  # liftoff, in-air, landing per hop
        return bool(np.all(k[:, 1] - args.shift > k[:, 0]) and np.all(k[:, 1] + args.shift < k[:, 2]))

    if args.sequence:
        seq = next(s for s in test if s.name == args.sequence)
    else:  # the clearest second hop: the highest in-air key among those that allow the timing edit
        seq = max((s for s in test if len(s.keys) == 3 * hops and shiftable(s)), key=lambda s: s.values[s.keys[4], 1])
    fps = next(s.motion.fps for s in read_dataset(args.data) if s.id == seq.name)
    values, keys = seq.values, seq.keys
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        truth = tmp / "truth.usda"
        io.save(from_variables(values, fps, keys=Keys(keys)), truth)

        # Figure 8: reconstruction from the sequence's own keys
        k = write_keys(values, keys, fps, tmp / "keys.usda")
        arnn, cubic = complete(k, tmp / "arnn.usda", "arnn", args.model), complete(k, tmp / "cubic.usda", "cubic", None)
        keyfill("plot", truth, cubic, arnn, "--labels", "truth,cubic,arnn",
                "-o", args.out / "arnn_reconstruction.png")

        # Figure 9: height edits of the second hop's in-air key
        air = keys[4]
        files, labels = [truth], ["truth"]
        for scale in (0.7, 1.5, 1.8):
            edited = values.copy()
            edited[air, 1] *= scale
            k = write_keys(edited, keys, fps, tmp / f"height_{scale}.usda")
            files.append(complete(k, tmp / f"height_{scale}_arnn.usda", "arnn", args.model))
            labels.append(f"arnn x{scale}")
        keyfill("plot", *files, "--labels", ",".join(labels), "-o", args.out / "arnn_height_edit.png")

        # Figure 10: timing edits, every in-air key earlier or later with the same pose
        files, labels = [truth], ["truth"]
        for shift in (-args.shift, 0, args.shift):
            new = keys.copy()
            new[1::3] += shift
            moved = np.zeros_like(values)
            moved[new] = values[keys]
            k = write_keys(moved, new, fps, tmp / f"timing_{shift}.usda")
            files.append(complete(k, tmp / f"timing_{shift}_arnn.usda", "arnn", args.model))
            labels.append(f"arnn {shift:+d} frames")
        keyfill("plot", *files, "--labels", ",".join(labels), "-o", args.out / "arnn_timing_edit.png")

        # Figure 11: sparse keys, the second hop's in-air and landing keys removed
        sparse = np.delete(keys, [4, 5])
        k = write_keys(values, sparse, fps, tmp / "sparse.usda")
        arnn, cubic = (complete(k, tmp / "sparse_arnn.usda", "arnn", args.model),
                       complete(k, tmp / "sparse_cubic.usda", "cubic", None))
        keyfill("plot", truth, cubic, arnn, "--labels", "truth (all keys),cubic,arnn",
                "-o", args.out / "arnn_sparse_keys.png")
    # the variables at the keys, to check the edits by eye
    print(f"{seq.name}: keys {keys.tolist()}, in-air key of hop 2 at frame {air}, base_y {values[air, 1]:.3f} m")
    print(f"wrote {', '.join(str(args.out / n) for n in ('arnn_reconstruction.png', 'arnn_height_edit.png', 'arnn_timing_edit.png', 'arnn_sparse_keys.png'))}")


if __name__ == "__main__":
    main()
