"""``keyfill evaluate``: score an in-betweening method or model with a benchmark protocol."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, progress, say
from keyfill.errors import UsageError
from keyfill.learn.protocols import PROTOCOLS


def _lengths(text: str) -> tuple[int, ...]:
    try:
        values = tuple(int(t) for t in text.replace(" ", "").split(",") if t)
    except ValueError:
        raise UsageError(f"--lengths takes transition lengths separated by commas, like 5,15,30; got {text!r}") from None
    if not values:
        raise UsageError("--lengths needs at least one transition length")
    return values


def _model(method_or_model: str) -> dict:
    """``model`` (an id: the folder's name) and ``model_path`` of what was scored (None for a baseline)."""
    from pathlib import Path

    from keyfill.learn.registry import METHODS

    m = METHODS.get(method_or_model)
    if m is not None:
        path = m.default_model() if m.learned else None
    else:  # a model folder, or a baseline only the protocols know (zero-velocity)
        path = Path(method_or_model) if Path(method_or_model).exists() else None
    return {"model": None if path is None else path.name, "model_path": None if path is None else str(path.resolve())}


@click.command()
@click.argument("method_or_model")
@click.argument("data", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("--protocol", type=click.Choice(sorted(PROTOCOLS)), default=None,
              help="Benchmark protocol. lafan1: Harvey et al. 2020 (L2Q, L2P, NPSS). keys: the hopping lamp's "
                   "test split with all keys and 1-2 keys deleted (Zhang & van de Panne 2018, Tables 1-2). "
                   "Default: keys when DATA is a 'keyfill simulate' folder, else lafan1.")
@click.option("--test-pattern", multiple=True, metavar="GLOB",
              help="Test clips: file names matching any of these shell patterns (repeatable). "
                   "Default: *subject5*, LaFAN1's test subject.")
@click.option("--train-pattern", multiple=True, metavar="GLOB",
              help="Clips for the training statistics (repeatable). Default: every clip that is not a test clip.")
@click.option("--lengths", default="5,15,30,45", show_default=True, metavar="LIST",
              help="Transition lengths to score (at most 45 with the protocol's 65-frame test windows).")
@click.option("--fold-root/--no-fold-root", default=None,
              help="Fold a static top joint (like Bandai's joint_Root) into the hips. "
                   "Default: as the model's corpus, else when the top joint is static.")
@click.option("--facing-axis", default="+Y", show_default=True, metavar="AXIS",
              help="The root joint's local axis that points forward (+Y as in the reference code).")
@click.option("--baselines/--no-baselines", default=True, show_default=True,
              help="Also score the zero-velocity and interpolation baselines.")
@click.option("--device", default="cpu", show_default=True, help="Torch device for a model.")
@click.option("--json", "as_json", is_flag=True, help="Print the scores as JSON on stdout.")
def evaluate(method_or_model, data, protocol, test_pattern, train_pattern, lengths, fold_root, facing_axis,
             baselines, device, as_json):
    """Score METHOD_OR_MODEL on the BVH clips in DATA (files or folders).

    METHOD_OR_MODEL is zero-velocity, linear (the protocol's interpolation:
    LERP of the root, SLERP of rotations), cubic, velocity (linear plus the
    fading velocity of the given frames beside a gap), or a model folder written by
    'keyfill train' (a transformer model is scored with the lafan1 protocol,
    an ARNN model with the keys protocol). Test and training clips are chosen
    by file name; the table shows L2Q, L2P and NPSS over the transition
    frames, and the scores relative to interpolation.

    \b
    Examples:
      keyfill evaluate linear lafan1/ --lengths 5,15,30
      keyfill evaluate models/bandai1-transformer bandai1/data --test-pattern '*_happy_*' \\
          --test-pattern '*_tired_*' --fold-root
      keyfill evaluate cubic bandai2/data --test-pattern '*_normal_*' --json
      keyfill evaluate arnn data/hops          (lamp models: the keys protocol)
    """
    from keyfill.learn.protocols import evaluate as run

    result = run(method_or_model, data, protocol, test_patterns=test_pattern, train_patterns=train_pattern,
                 lengths=_lengths(lengths), fold=fold_root, facing_axis=facing_axis, baselines=baselines,
                 device=device, progress=lambda files: progress(files, desc="reading clips", unit="file"))
    if as_json:
        emit_json({**result.as_json(), "input": list(data), "output": None, **_model(method_or_model)})
        return
    for line in result.lines:
        say(line)
    click.echo(result.table)
