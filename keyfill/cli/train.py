"""``keyfill train METHOD``: one subcommand per trainable method of the registry, built from its TrainingSpec.

The options every method shares (DATA, -o, --seed, --epochs, --resume,
checkpoint and log paths, --threads, --device, --json) are defined here once;
a method adds its own through :class:`keyfill.learn.training.Option` values, so
a new learned method needs no CLI code. The method's training module (and
torch) is imported only when its subcommand runs or shows its help.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from keyfill.cli.common import emit_json, progress, say, verbosity
from keyfill.cli.main import SuggestingGroup
from keyfill.learn import registry
from keyfill.limits import MAX_WORKERS, check_count

_TYPES = {"file": click.Path(exists=True, dir_okay=False)}


def _click_option(opt) -> click.Option:
    """A click option for a :class:`~keyfill.learn.training.Option`."""
    flag = "--" + opt.name.replace("_", "-")
    if opt.flag:
        return click.Option([f"{flag}/--no-{flag[2:]}", opt.name], default=opt.default,
                            show_default=opt.default is not None, help=opt.help)
    kind = click.Choice(opt.choices) if opt.choices else _TYPES.get(opt.type, opt.type)
    return click.Option([flag, opt.name], type=kind, default=opt.default, multiple=opt.multiple,
                        metavar=opt.metavar, show_default=opt.default not in (None, ()), help=opt.help)


def _common_params(name: str, threads: int | None) -> list[click.Parameter]:
    return [
        click.Argument(["data"], nargs=-1, required=True, type=click.Path(exists=True)),
        click.Option(["-o", "--output"], required=True, type=click.Path(file_okay=False),
                     help="Model folder to write (config.json + weights.safetensors); replaced if it is a model."),
        click.Option(["--epochs"], type=int, help=f"Passes over the training data [default: the {name} default]."),
        click.Option(["--seed"], type=int, default=0, show_default=True,
                     help="Seed of every random choice (same data, options and seed: same model bytes)."),
        click.Option(["--resume"], is_flag=True, help="Continue from the checkpoint (same data, options and seed)."),
        click.Option(["--checkpoint"], type=click.Path(dir_okay=False),
                     help="Checkpoint file [default: OUTPUT.checkpoint.pt]."),
        click.Option(["--checkpoint-every"], type=int, metavar="N", help="Write the checkpoint every N epochs."),
        click.Option(["--log"], type=click.Path(dir_okay=False),
                     help="Loss log, one JSON line per epoch [default: OUTPUT.log.jsonl]."),
        click.Option(["--threads"], type=int, default=threads, show_default=threads is not None,
                     help="Torch CPU threads (results are reproducible for a given thread count)."),
        click.Option(["--device"], default="cpu", show_default=True, help="Torch device: cpu, cuda, cuda:1, ..."),
        click.Option(["--json", "as_json"], is_flag=True, help="Print a summary as JSON on stdout."),
    ]


def _command(method: registry.Method) -> click.Command:
    spec = method.training_spec()

    def run(data, output, epochs, seed, resume, checkpoint, checkpoint_every, log, threads, device, as_json,
            **options):
        import torch

        from keyfill.learn.modelfile import torch_device
        from keyfill.learn.training import Common, check_outputs, read_checkpoint, side_files, train

        torch_device(device)  # meta, xla or a missing GPU: a usage error before the corpus is read
        if threads is not None:
            check_count("threads", threads, MAX_WORKERS)
            torch.set_num_threads(threads)
        output = output.rstrip("/") or output
        default_checkpoint, default_log = side_files(output)
        checkpoint, log = checkpoint or str(default_checkpoint), log or str(default_log)
        check_outputs(output, checkpoint, log)
        if resume and Path(checkpoint).is_file():
            read_checkpoint(checkpoint, method.name)  # a checkpoint of another kind is refused before any work
        common = Common(tuple(data), output, seed=seed, epochs=epochs, checkpoint_every=checkpoint_every,
                        device=device)
        task = spec.make_task(common, options, progress)
        if not as_json:
            say(spec.started(task))
        line = spec.epoch_line if spec.epoch_line is not None and not as_json else None
        outcome = train(task, output, seed=seed, checkpoint=checkpoint, log=log, resume=resume, device=device,
                        progress=progress, on_epoch=(lambda row: say(line(row))) if line else None,
                        progress_lines=None if sys.stderr.isatty() or verbosity() < 0 else say)  # no bar: lines
        if outcome.model is None:  # a process other than rank 0 of a torchrun job: rank 0 reports
            return
        summary, text = spec.finished(task, outcome)
        if as_json:  # docs/json.md: the model an id (the folder's name) and its path
            folder = Path(summary.get("output") or output)
            emit_json({**summary, "input": list(data), "output": str(folder), "model": folder.name,
                       "model_path": str(folder.resolve())})
        else:
            say(text)

    params = _common_params(method.name, spec.threads) + [_click_option(o) for o in spec.options]
    return click.Command(method.name, callback=run, params=params, help=spec.help, short_help=method.summary)


class TrainGroup(SuggestingGroup):
    """The trainable methods of the registry as subcommands, each built on first use."""

    def list_commands(self, ctx):
        return [m.name for m in registry.trainable()]

    def get_command(self, ctx, name):
        if name not in self.list_commands(ctx):
            return None
        return _command(registry.get(name))

    def format_commands(self, ctx, formatter):
        """List the methods from the registry's summaries, without importing their training modules."""
        rows = [(m.name, m.summary) for m in registry.trainable()]
        with formatter.section("Methods"):
            formatter.write_dl(rows)


@click.group(cls=TrainGroup)
def train():
    """Train an in-betweening model on a corpus of motion files.

    Every method trains through one loop: checkpoints (--resume), a JSONL
    loss log and, under torchrun, data-parallel training on N processes
    (rank 0 alone writes files):

    \b
      torchrun --standalone --nproc-per-node 2 -m keyfill train transformer clips/ -o models/m

    \b
    Examples:
      keyfill train transformer bandai2/data --exclude '*_normal_*' -o models/bandai2-transformer
      keyfill train transformer clips/ -o models/small --config small.json --epochs 5
      keyfill train arnn data/hops -o models/lamp-arnn
    """
