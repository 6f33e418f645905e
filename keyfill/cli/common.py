"""Helpers shared by the subcommands: file arguments, keys, JSON, progress bars."""

from __future__ import annotations

import json
import re
import sys
import time
from pathlib import Path

import click

from keyfill import io
from keyfill.errors import UsageError
from keyfill.limits import CONNECT_SECONDS
from keyfill.motion import Keys, Motion


def did_you_mean(word: str, names) -> str:
    """The hint click adds to a mistyped option (its close matches by :mod:`difflib`, in its words), for a
    mistyped command or choice: ``" Did you mean 'complete'?"``, or ``""`` when no name is close."""
    from difflib import get_close_matches

    close = sorted(get_close_matches(word, list(names)))
    if len(close) > 1:
        return f" (Did you mean one of: {', '.join(map(repr, close))}?)"
    return f" Did you mean {close[0]!r}?" if close else ""


class Choice(click.Choice):
    """click's choice, whose refusal ends with the close choices, as a mistyped option's does."""

    def get_invalid_choice_message(self, value, ctx) -> str:
        return super().get_invalid_choice_message(value, ctx) + did_you_mean(str(value), map(str, self.choices))


#: ``--format`` / ``--in-format`` choices: the names of the one table of formats
FORMAT_CHOICE = Choice(list(io.FORMATS), case_sensitive=False)


#: library parameters whose flag is not ``--`` + the name with dashes
FLAG_OF = {"learning_rate": "--lr", "chunk": "--batch-size", "outdir": "-o", "output": "-o", "keys_text": "--keys",
           "in_format": "--in-format"}


def flag(param: str) -> str:
    """The command-line flag that gives the library parameter ``param`` (``key_every`` -> ``--key-every``)."""
    return FLAG_OF.get(param, "--" + param.replace("_", "-"))


def flag_words(message: str, params) -> str:
    """``message`` with each parameter of ``params`` written as its flag where the message first names it (as a
    whole word): later words that spell the same (``--fps: the frame rate 1e+308 fps``, ``--frames 30:40 selects
    no frame of walk (frames 0-23)``) are the message's own."""
    for param in params:
        # a whole word, not part of a name or path (``/data/format/x.bvh``, ``format.json``)
        message = re.sub(rf"(?<![\w\-/.]){re.escape(param)}(?![\w\-/.])", flag(param), message, count=1)
    return message


def verbosity(ctx: click.Context | None = None) -> int:
    ctx = ctx or click.get_current_context(silent=True)
    while ctx is not None:
        if ctx.obj and "verbosity" in ctx.obj:
            return ctx.obj["verbosity"]
        ctx = ctx.parent
    return 0


def _global_option(ctx, param, value):
    """``-q``, ``-v`` and ``--debug`` after the subcommand: they add to those given before it."""
    if value:
        ctx.ensure_object(dict)
        if param.name == "debug":
            ctx.obj["debug"] = True
        else:
            ctx.obj["verbosity"] = ctx.obj.get("verbosity", 0) + (value if param.name == "verbose" else -value)
    return value


def with_global_options(command: click.Command) -> click.Command:
    """``command`` (and, for a group, each subcommand it makes) accepting the group's ``-q``, ``-v`` and
    ``--debug`` after its name too (``keyfill info walk.bvh -q``); hidden from its ``--help``."""
    if getattr(command, "_global_options", False):
        return command
    taken = {o for p in command.params for o in getattr(p, "opts", ())}
    for opts, name, count in ((("-q", "--quiet"), "quiet", True), (("-v", "--verbose"), "verbose", True),
                              (("--debug",), "debug", False)):
        if not taken & set(opts):
            command.params.append(click.Option([*opts, name], count=count, is_flag=not count, hidden=True,
                                               expose_value=False, callback=_global_option))
    if isinstance(command, click.Group):
        get = command.get_command

        def get_command(ctx, name):
            sub = get(ctx, name)
            return None if sub is None else with_global_options(sub)

        command.get_command = get_command
    command._global_options = True
    return command


def progress_shown() -> bool:
    """Whether progress bars are drawn: stderr is a terminal and ``-q`` was not given."""
    return verbosity() >= 0 and sys.stderr.isatty()


def progress(iterable=None, **kwargs):
    """A tqdm progress bar on stderr, silent with ``-q`` or when stderr is not a terminal."""
    from tqdm import tqdm

    return tqdm(iterable, disable=not progress_shown(), file=sys.stderr, dynamic_ncols=True, **kwargs)


class DelayedBar:
    """The ``update(n)`` / ``close()`` of a progress bar that ``make(done)`` draws only once the task has run for
    ``delay`` seconds where bars are shown (:func:`progress_shown`). A short task, or any task whose stderr is
    not a terminal, makes no bar and imports no tqdm (about 40 ms of a command's start)."""

    def __init__(self, make, delay: float):
        self._make, self._shown, self._due = make, progress_shown(), time.monotonic() + delay
        self._done, self._bar = 0, None

    def update(self, n: int = 1) -> None:
        if self._bar is not None:
            self._bar.update(n)
            return
        self._done += n
        if self._shown and time.monotonic() >= self._due:
            self._bar = self._make(self._done)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def emit_json(data: dict) -> None:
    """Print a machine-readable summary on stdout."""
    click.echo(json.dumps(data, indent=2, sort_keys=True, default=_jsonable))


def _jsonable(x):
    import numpy as np

    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Path):
        return str(x)
    raise TypeError(f"cannot write {type(x).__name__} as JSON")


def say(message: str, min_verbosity: int = 0) -> None:
    """A human-readable line on stderr (so stdout stays clean for data and JSON)."""
    if verbosity() >= min_verbosity:
        click.echo(message, err=True)


def in_format_option(f):
    """``--in-format``: the input's format, the same in every command that reads motion files."""
    return click.option("--in-format", "in_fmt", type=FORMAT_CHOICE,
                        help="Input format [default: from the suffix; for '-', from the first bytes].")(f)


def meters_per_unit_option(f):
    """``--meters-per-unit``: the units of an input whose format records none (BVH)."""
    return click.option(
        "--meters-per-unit", type=float, metavar="M",
        help="The size of one unit of a BVH input in metres (BVH files do not say; without this keyfill assumes "
             "centimetres, 0.01). Files that record their units (USD, glTF) keep their own.")(f)


def up_axis_option(f):
    """``--up-axis``: the up axis of an input whose format records none (BVH)."""
    return click.option(
        "--up-axis", metavar="Y|Z",
        help="The up axis of a BVH input, Y or Z (BVH files do not say; without this keyfill assumes Y, BVH's "
             "custom; Blender exports Z-up BVH). The values stay as they are: the axis goes into the outputs' "
             "metadata (USD upAxis; glTF outputs are turned Y-up). Files that record their axis keep their own.")(f)


def bvh_layout_option(f):
    """``--bvh-layout``: the channel layout of BVH outputs (:data:`keyfill.io.bvh_channels.LAYOUTS`)."""
    return click.option(
        "--bvh-layout", type=click.Choice(["auto", "source", "full"]),
        help="Channel layout of BVH outputs: source keeps each joint's own channels (lossless from a BVH); full "
             "writes three rotation channels on every joint and Xposition Yposition Zposition on roots and "
             "translating joints, which every reader takes (Blender refuses joints with fewer than three "
             "rotation channels); auto (the default) keeps a BVH input's layout and writes the others full.")(f)


def usd_layer_option(f):
    """``--usd-layer``: what a USD output written from a USD input keeps of it (:mod:`keyfill.io.usd_stage`)."""
    return click.option(
        "--usd-layer", type=click.Choice(["stage", "over", "new"]),
        help="What a USD output of a USD input keeps of it. stage (the default): the input's whole stage (meshes, "
             "materials, skinning, prim names, metadata) with the new joint samples; over: a small layer that "
             "sublayers the input and holds only the new joint samples, to layer over the asset (e.g. "
             "--usd-layer over -o shot_anim.usda); new: a new file of the skeleton and animation alone.")(f)


def keys_options(f):
    """``--keys`` and ``--key-every`` options."""
    f = click.option(
        "--key-every",
        type=int,
        metavar="N",
        help="A key every N frames from frame 0, plus the last frame.",
    )(f)
    f = click.option("--keys", "keys_text", metavar="LIST", help="Key frame numbers, e.g. 0,12,30.")(f)
    return f


def resolve_keys(motion: Motion, keys_text: str | None, key_every: int | None, min_keys: int = 2) -> Keys:
    """The keys for ``motion``: from ``--keys``, ``--key-every``, or the file's own keys (:meth:`Keys.resolve`)."""
    return Keys.resolve(motion, keys_text, key_every, min_keys)


def partial_keys_options(f):
    """``--key-joints``, ``--key-positions`` and ``--key-plane``: keys that give only part of each pose."""
    f = click.option(
        "--key-plane", metavar="PLANE",
        help="2-D keys: the keyed joints give only their position in this view plane (XY, XZ or YZ of the "
             "file's world axes; e.g. XY is the front view of a Y-up, Z-forward file).",
    )(f)
    f = click.option(
        "--key-positions", is_flag=True,
        help="The keyed joints give only their 3-D positions, not rotations (with --key-joints ROOT: a path of "
             "spots on the ground).",
    )(f)
    f = click.option(
        "--key-joints", metavar="NAMES",
        help="Key only these joints (comma-separated names, e.g. Hips,LeftUpLeg,LeftLeg); the others are free.",
    )(f)
    return f


def apply_partial_keys(motion: Motion, keys: Keys, joints_text: str | None, positions: bool,
                       plane: str | None) -> Keys:
    """``keys`` restricted by ``--key-joints`` / ``--key-positions`` / ``--key-plane`` (unchanged without them)."""
    if positions and plane is not None:
        raise UsageError("give --key-positions (3-D) or --key-plane (2-D), not both")
    if joints_text is None and not positions and plane is None:
        return keys
    joints = None if joints_text is None else [t.strip() for t in joints_text.split(",") if t.strip()]
    given = plane if plane is not None else ("position" if positions else "pose")
    if joints is None and keys.mask is not None:
        return Keys(keys.frames, keys.mask, given)
    return keys.restrict(motion.skeleton, joints, given)


def output_format(path: str, fmt: str | None) -> str | None:
    """``--format`` is required for ``-`` (stdout); a file's suffix must name a format and agree with ``--format``
    (:func:`keyfill.io.format_of`). Called before any work, so a misnamed output costs nothing."""
    if not path:
        raise UsageError("the output path is empty: give a file name, or '-' and --format for standard output")
    if path == "-" and fmt is None:
        raise UsageError(f"writing to '-' needs --format ({io.listing(io.FORMATS)})")
    if path != "-":
        io.format_of(path, fmt)
    return fmt


def input_format(path: str, fmt: str | None) -> str | None:
    """``--in-format`` overrides the suffix; without it ``-`` (stdin) is recognised by its first bytes
    (:func:`keyfill.io.sniff`)."""
    return fmt


def load_labelled(files, labels: str | None, in_fmt: str | None, keys_text: str | None, key_every: int | None):
    """Read the FILES of a picture command: ``(motions, legend names)``.

    Names are the file stems or ``--labels`` (one per file). Keys given with
    ``--keys`` / ``--key-every`` replace each file's own keys. A file with no
    frames is a :class:`DataError`.
    """
    from keyfill.errors import DataError

    names = [Path(f).stem if f != "-" else "stdin" for f in files]
    if labels is not None:
        names = [t.strip() for t in labels.split(",")]
        if len(names) != len(files):
            raise UsageError(f"--labels gives {len(names)} names for {len(files)} files")
    motions = []
    for f in files:
        motion = io.load(f, input_format(f, in_fmt))
        if motion.num_frames == 0:
            raise DataError(f"{f}: the motion has no frames")
        if keys_text is not None or key_every is not None:
            motion = motion.replace(keys=resolve_keys(motion, keys_text, key_every, min_keys=1))
        motions.append(motion)
    return motions, names


def _executor_option(ctx, param, value):
    """``--workers`` and ``--connect-timeout`` checked as they are parsed: one file refuses what a batch does
    (the defaults need no check, and a command given neither imports no :mod:`keyfill.parallel`)."""
    if value is None or (param.name == "connect_timeout" and value == CONNECT_SECONDS):
        return value
    from keyfill.parallel import check_options

    if param.name == "workers":
        check_options(value)
    else:
        check_options(None, value)
    return value


def batch_options(f):
    """``--workers``, ``--scheduler``, ``--connect-timeout``, ``--force`` and ``--batch-size`` of a batch command."""
    f = click.option("--batch-size", default=64, show_default=True, type=int, metavar="N",
                     help="Files per job (and per batch through a learned model).")(f)
    f = click.option("--force", is_flag=True,
                     help="Redo every output, also those the output folder's record says were made the same way "
                          "(docs/batch.md), and allow an output that is one of the inputs or a read-only file.")(f)
    f = click.option("--connect-timeout", default=CONNECT_SECONDS, show_default=True, type=float, metavar="SECONDS",
                     callback=_executor_option, help="Give up reaching the --scheduler after this long.")(f)
    f = click.option("--scheduler", metavar="ADDRESS",
                     help="Run the batch on a Dask distributed cluster, e.g. tcp://host:8786.")(f)
    f = click.option("--workers", type=int, metavar="N", callback=_executor_option,
                     help="Local worker processes for a batch [default: one per idle core, when the inputs are "
                          "large enough to pay for starting them (8 MB each), else 1]; with --scheduler, jobs "
                          "kept in flight.")(f)
    return f


def run_batch(inputs, outdir, fmt, job, spec, workers, scheduler, connect_timeout, force, batch_size, as_json,
              verb, check=None) -> None:
    """Run a many-in / folder-out command: plan, check, progress bar over files, one error line per failed
    input, a summary; raises :class:`BatchFailed` (exit 1) when any input failed."""
    import importlib

    from keyfill.io.batch import plan, run

    items = plan(inputs, outdir, fmt, force)
    if check is not None:
        check()
    module, attr = job.split(":")
    fn = getattr(importlib.import_module(module), attr)
    finished = set()

    def on_chunk(outcomes):
        bar.update(len(outcomes))
        finished.update(f["input"] for f in outcomes if f["status"] != "failed")

    with progress(total=len(items), unit="file", desc="files") as bar:
        try:
            summary = run(items, fn, spec, workers=workers, scheduler=scheduler, force=force, chunk=batch_size,
                          connect_timeout=connect_timeout, on_chunk=on_chunk)
        except KeyboardInterrupt as e:  # the line says what is done (the record keeps it) and how to go on
            e.detail = f"{len(finished)} of {len(items)} done; run the same command again to finish"
            raise
    summary.output = str(outdir)
    for f in summary.failed:  # the library's words as flags, on the error lines and in --json alike
        f["error"] = flag_words(f["error"], f.pop("params", ()))
        click.echo(f"keyfill: error: {f['error']}", err=True)
    if as_json:
        emit_json(summary.to_dict())
    else:
        say(summary.line(verb))
    if summary.failed:
        from keyfill.errors import BatchFailed

        raise BatchFailed(f"{len(summary.failed)} of {len(items)} inputs failed")
