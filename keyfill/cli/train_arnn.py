"""``keyfill train arnn``: train a keyframe-conditioned network on a simulated lamp dataset."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, progress, say


@click.command()
@click.argument("data", type=click.Path(file_okay=False))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=True, file_okay=False),
              help="Model folder to write (config.json + weights.safetensors); replaced if it is a model.")
@click.option("--arch", type=click.Choice(["arnn", "no-memory", "segregated"]), default="arnn", show_default=True,
              help="Network: the ARNN, or section 9's no-memory or segregated comparison networks.")
@click.option("--epochs", type=int, default=400, show_default=True, help="Passes over the training sequences.")
@click.option("--batch-size", type=int, default=16, show_default=True, help="Sequences per gradient step.")
@click.option("--lr", type=float, default=1e-3, show_default=True, help="Adam learning rate.")
@click.option("--curriculum/--no-curriculum", default=True, show_default=True,
              help="Scheduled sampling then a rising key weight (section 7.2); without: free-running, weight 1.")
@click.option("--max-deleted", type=int, default=2, show_default=True,
              help="Delete 0 to this many interior keys of a sequence each time it is used.")
@click.option("--key-loss", type=click.Choice(["mean", "sum"]), default="mean", show_default=True,
              help="Key term of the loss: mean squared key error, or the paper's literal sum over keys.")
@click.option("--clip", type=float, default=1.0, show_default=True,
              help="Clip the gradient norm to this (0: no clipping).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of all training randomness.")
@click.option("--threads", type=int, default=1, show_default=True,
              help="Torch CPU threads (results are reproducible for a given thread count).")
@click.option("--checkpoint", "checkpoint", type=click.Path(dir_okay=False),
              help="Checkpoint file [default: OUTPUT.checkpoint.pt].")
@click.option("--checkpoint-every", type=int, default=50, show_default=True, metavar="N",
              help="Write the checkpoint every N epochs.")
@click.option("--resume", is_flag=True, help="Continue from the checkpoint (same data and options).")
@click.option("--log", "log", type=click.Path(dir_okay=False),
              help="Loss log, one JSON line per epoch [default: OUTPUT.log.jsonl].")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def arnn(data, output, arch, epochs, batch_size, lr, curriculum, max_deleted, key_loss, clip, seed, threads,
         checkpoint, checkpoint_every, resume, log, as_json):
    """Train a lamp in-betweening network on the dataset folder DATA.

    DATA is a folder made by 'keyfill simulate'. Its sequences are split by
    position: the last 20 % are the test split (for 'keyfill evaluate'), the
    10 % before them are held out and scored every epoch in the log, the rest
    is trained on. Training follows Zhang & van de Panne 2018: the loss
    100 w (key error) + frame MSE, scheduled sampling and a sigmoid key
    weight w (--no-curriculum: none), 0-2 keys deleted at random each time a
    sequence is used, Adam. The same data, options, --seed and --threads give
    the same model bytes, also across --resume.

    \b
    Examples:
      keyfill train arnn data/hops -o models/lamp-arnn
      keyfill train arnn data/hops -o models/nomem --arch no-memory --epochs 300
      keyfill train arnn data/hops -o models/lamp-arnn --resume
    """
    import torch

    from keyfill.learn.lamp_features import read_sequences
    from keyfill.learn.train_arnn import Settings, split, train

    torch.set_num_threads(threads)
    settings = Settings(arch=arch, epochs=epochs, batch_size=batch_size, lr=lr, curriculum=curriculum,
                        max_deleted=max_deleted, key_loss=key_loss, clip=clip, seed=seed,
                        checkpoint_every=checkpoint_every).check()
    parts = split(read_sequences(data))
    output = output.rstrip("/")
    checkpoint = checkpoint or output + ".checkpoint.pt"
    log = log or output + ".log.jsonl"
    say(f"training {arch} on {len(parts['train'])} sequences of {data} ({len(parts['val'])} held out, "
        f"{len(parts['test'])} left for testing), {epochs} epochs")
    with progress(total=epochs, unit="epoch") as bar:
        def on_epoch(row):
            if bar.n == 0 and row["epoch"] > 1:
                bar.update(row["epoch"] - 1)
            bar.set_postfix(key=f"{row['train_key']:.4f}", frame=f"{row['train_frame']:.4f}",
                            val=f"{row['val_total']:.4f}", refresh=False)
            bar.update(1)

        result = train(parts["train"], parts["val"], settings, output, checkpoint=checkpoint, log=log,
                       resume=resume, on_epoch=on_epoch, source=str(data))
    summary = {
        "model": str(result.path),
        "arch": arch,
        "epochs": result.epochs,
        "seconds": round(result.seconds, 1),
        "cpu_seconds": round(result.cpu_seconds, 1),
        "weights": result.weights,
        "held_out": result.val,
        "log": str(result.log),
        "checkpoint": checkpoint,
    }
    if as_json:
        emit_json(summary)
    else:
        v = result.val
        say(f"wrote {result.path}: {arch}, {result.weights} weights, {result.epochs} epochs in "
            f"{result.seconds / 60:.1f} min ({result.cpu_seconds / 60:.1f} min of CPU); held-out total loss {v['total']:.5f} (all keys), "
            f"{v['deleted_total']:.5f} (1-2 keys deleted); log {result.log}")
