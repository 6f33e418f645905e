"""``keyfill evaluate``: score an in-betweening method or model with a benchmark protocol."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, progress, say
from keyfill.errors import UsageError


def _lengths(text: str) -> tuple[int, ...]:
    try:
        values = tuple(int(t) for t in text.replace(" ", "").split(",") if t)
    except ValueError:
        raise UsageError(f"--lengths takes transition lengths separated by commas, like 5,15,30; got {text!r}") from None
    if not values:
        raise UsageError("--lengths needs at least one transition length")
    return values


def _lafan1(method_or_model, data, test_pattern, train_pattern, lengths, fold_root, facing_axis, baselines, device):
    """The LaFAN1 protocol: returns (results, summary)."""
    from keyfill.learn import benchmark

    label, method = benchmark.resolve_method(method_or_model, device)
    methods = {label: method}
    if baselines:
        for name in ("zero-velocity", "interpolation"):
            methods.setdefault(name, benchmark.BASELINES[name])
    proto = benchmark.lafan1(
        data,
        test_pattern or benchmark.LAFAN1_TEST_PATTERNS,
        train_pattern,
        fold=fold_root if fold_root is not None else getattr(method, "folded", None),
        facing_axis=facing_axis,
        progress=lambda files: progress(files, desc="reading clips", unit="file"),
    )
    return benchmark.evaluate(methods, proto.test, proto.stats, lengths), proto.info


#: protocol name -> function; a new protocol is one more entry and one library call.
PROTOCOLS = {"lafan1": _lafan1}
#: model kind (``config.json`` of a model folder) -> the protocol that scores it
PROTOCOL_OF_KIND = {"transformer": "lafan1", "arnn": "keys"}
#: method names of both protocols (never read as paths)
METHOD_NAMES = ("zero-velocity", "linear", "interpolation", "cubic", "cubic-variables", "arnn")


def _model_kind(method_or_model: str) -> str | None:
    """The kind of the model folder METHOD_OR_MODEL, or None for a method name or a missing path."""
    from pathlib import Path

    if method_or_model in METHOD_NAMES or not Path(method_or_model).exists():
        return None
    from keyfill.learn.modelfile import read_config

    return read_config(method_or_model)["kind"]


def _protocol(method_or_model: str, data, protocol: str | None) -> str:
    """The protocol to run: as asked, else the one for the model's kind, else the one for DATA."""
    kind = _model_kind(method_or_model)
    if kind is not None and kind not in PROTOCOL_OF_KIND:
        raise UsageError(f"{method_or_model}: keyfill evaluate cannot score {kind!r} models")
    want = PROTOCOL_OF_KIND.get(kind)
    if protocol is None:
        protocol = want or ("keys" if _is_lamp_dataset(data) else "lafan1")
    if want is not None and protocol != want:
        raise UsageError(f"{method_or_model}: a model of kind {kind!r} is scored with --protocol {want}, not {protocol}")
    return protocol


def _is_lamp_dataset(data) -> bool:
    """DATA is one folder made by 'keyfill simulate' (it has a manifest.jsonl)."""
    from pathlib import Path

    return len(data) == 1 and (Path(data[0]) / "manifest.jsonl").is_file()


def _keys(method_or_model, data, baselines, as_json):
    """The lamp protocol (Zhang & van de Panne 2018, Tables 1 and 2) on a 'keyfill simulate' folder."""
    from keyfill.learn import lamp_eval

    if len(data) != 1:
        raise UsageError("the keys protocol takes one dataset folder made by 'keyfill simulate'")
    reports, info = lamp_eval.protocol(method_or_model, data[0], baselines=baselines)
    if as_json:
        emit_json({"protocol": "keys", "method": method_or_model, **info,
                   "results": {r.method: r.as_dict() for r in reports}})
        return
    say(f"keys: {info['test_sequences']} test sequences of {info['data']} ({info['test_first']} .. "
        f"{info['test_last']}), completed with all keys and with 1-2 keys deleted; losses on standardised "
        f"variables (total = key + frame)")
    click.echo(lamp_eval.format_table(reports))


@click.command()
@click.argument("method_or_model")
@click.argument("data", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("--protocol", type=click.Choice(sorted([*PROTOCOLS, "keys"])), default=None,
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
    LERP of the root, SLERP of rotations), cubic, or a model folder written by
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
    protocol = _protocol(method_or_model, data, protocol)
    if protocol == "keys":
        return _keys(method_or_model, data, baselines, as_json)
    from keyfill.learn import benchmark

    results, info = PROTOCOLS[protocol](method_or_model, data, test_pattern, train_pattern, _lengths(lengths),
                                        fold_root, facing_axis, baselines, device)
    if as_json:
        emit_json({"protocol": protocol, "method": method_or_model, **info,
                   "results": {m: {str(n): v for n, v in r.items()} for m, r in results.items()}})
        return
    say(f"{protocol}: {info['test_windows']} test windows from {info['test_clips']} clips, "
        f"statistics from {info['train_windows']} windows of {info['train_clips']} clips")
    short = info.get("test_clips_too_short", 0) + info.get("train_clips_too_short", 0)
    if short:
        say(f"skipped {info['test_clips_too_short']} test and {info['train_clips_too_short']} training clips "
            f"shorter than a window")
    click.echo(benchmark.format_table(results))
