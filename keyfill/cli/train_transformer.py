"""``keyfill train transformer``: train the motion-completion transformer (Duan et al. 2021)."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, progress, say


@click.command()
@click.argument("data", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("-o", "--output", required=True, type=click.Path(file_okay=False),
              help="Model folder to write (config.json + weights.safetensors; replaced if it is a model). "
                   "The checkpoint OUTPUT.checkpoint.pt and the log OUTPUT.log.jsonl go beside it.")
@click.option("--config", "config_file", type=click.Path(exists=True, dir_okay=False),
              help='JSON file {"model": {...}, "training": {...}} overriding the defaults (see docs/transformer.md).')
@click.option("--epochs", type=int, help="Number of epochs (overrides the config).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of every random choice (same seed, same model).")
@click.option("--resume", is_flag=True, help="Continue from OUTPUT.checkpoint.pt (same data, settings and seed).")
@click.option("--device", default="cpu", show_default=True, help="Torch device: cpu, cuda, cuda:1, ...")
@click.option("--threads", type=int, help="CPU threads for torch (1 is fastest on a busy machine).")
@click.option("--include", multiple=True, metavar="GLOB", help="Train only on files matching one of these patterns.")
@click.option("--exclude", multiple=True, metavar="GLOB", help="Leave out files matching these patterns (e.g. a test style).")
@click.option("--fold-root/--no-fold-root", default=None,
              help="Fold a static top joint (like Bandai's joint_Root) into the hips. Default: when it is static.")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def transformer(data, output, config_file, epochs, seed, resume, device, threads, include, exclude, fold_root, as_json):
    """Train a motion-completion transformer on the BVH clips in DATA.

    One model learns in-betweening (10 context frames and a target key),
    in-filling (a key every k frames) and blending (a given head and tail).
    After every epoch it is scored on held-out clips with the LaFAN1 protocol
    and a checkpoint is written; --resume continues an interrupted run.

    \b
    Examples:
      keyfill train transformer bandai2/data --exclude '*_normal_*' -o models/bandai2-transformer
      keyfill train transformer clips/ -o models/small --config small.json --epochs 3 --seed 1
      keyfill train transformer clips/ -o models/small --config small.json --epochs 3 --seed 1 --resume
    """
    import dataclasses

    import torch

    from keyfill.learn.corpus import load_corpus
    from keyfill.learn.train_transformer import read_config, select_clips, side_files, train

    if threads is not None:
        torch.set_num_threads(threads)
    model_cfg, train_cfg = read_config(config_file)
    if epochs is not None:
        train_cfg = dataclasses.replace(train_cfg, epochs=epochs)
    corpus = select_clips(load_corpus(data, fold=fold_root, progress=lambda f: progress(f, desc="reading clips", unit="file")),
                          include, exclude)

    def report(r):
        vals = " ".join(f"L2P@{n} {r[f'val_L2P_{n}_vs_interp']:.3f}" for n in train_cfg.val_lengths if f"val_L2P_{n}_vs_interp" in r)
        say(f"epoch {r['epoch']}: loss {r['loss_total']:.4f}" + (f", vs interpolation {vals}" if vals else ""))

    def started(info):
        say(f"training on {info['train_windows']} windows of {info['train_clips']} clips "
            f"({info['clips_too_short']} clips shorter than a window skipped), "
            f"validating on {info['validation_clips']} clips; mirroring {'on' if info['mirrored'] else 'off'}")

    output = output.rstrip("/") or output
    model = train(corpus, output, model_cfg, train_cfg, seed=seed, device=device, resume=resume,
                  progress=lambda **kw: progress(**kw), report=None if as_json else report,
                  started=None if as_json else started)
    checkpoint, log = side_files(output)
    if as_json:
        emit_json({"output": output, "checkpoint": str(checkpoint), "log": str(log), **model.info})
    else:
        say(f"wrote {output} (checkpoint {checkpoint}, log {log})")
