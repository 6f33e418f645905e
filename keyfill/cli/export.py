"""``keyfill export``: a learned model as an ONNX graph, to run without torch."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, say


@click.command()
@click.argument("model")
@click.option("-o", "--output", "dst", type=click.Path(dir_okay=False),
              help="The graph file [default: model.onnx in the model folder].")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def export(model, dst, as_json):
    """Write the network of MODEL (a model folder, or a method's name for its built-in model) as an ONNX graph.

    The graph's metadata holds the model's config (normalisation, skeleton,
    architecture), the contract of its inputs and outputs (docs/onnx.md) and
    the SHA-256 of the weights it came from: `keyfill complete --runtime onnx`
    refuses a graph beside other weights. With the graph in the model folder
    (the default output), `keyfill complete` uses it automatically when
    onnxruntime is installed, and imports no torch. Exportable methods:
    {methods}.

    \b
    Examples:
      keyfill export models/walk                     # writes models/walk/model.onnx
      keyfill export arnn -o lamp-arnn.onnx          # the built-in lamp model
      keyfill complete keys.usda --method arnn --model lamp-arnn.onnx -o filled.usda
    """
    from pathlib import Path

    from keyfill.errors import NoSuchFile, UsageError
    from keyfill.learn.modelfile import model_folder
    from keyfill.learn.onnx import GRAPH
    from keyfill.learn.registry import METHODS, exportable, load_model

    if model in METHODS:
        folder = METHODS[model].default_model()
        if dst is None and folder is not None:
            raise UsageError(f"the built-in {model} model's folder is part of keyfill; give -o FILE.onnx")
    elif not Path(model).exists():  # a missing path is a usage error, as in every command
        raise NoSuchFile(model, f"no such model folder, nor a method's name ({', '.join(METHODS)})")
    else:
        folder = model_folder(model)
    label, method, loaded = load_model(model)
    if method.export is None:
        raise UsageError(f"{method.name} models cannot be exported yet; exportable: "
                         f"{', '.join(m.name for m in exportable())}")
    out = Path(dst) if dst is not None else Path(folder) / GRAPH
    if out.suffix.lower() != ".onnx":
        raise UsageError(f"{out}: an ONNX graph file ends in .onnx")
    module, attr = method.export.split(":")
    import importlib

    getattr(importlib.import_module(module), attr)(loaded, Path(folder), out)
    if model in METHODS:
        label = f"the built-in {Path(folder).name} model"
    info = {"input": model, "output": str(out), "model": Path(folder).name, "model_path": str(Path(folder).resolve()),
            "kind": method.name, "bytes": out.stat().st_size}
    if as_json:
        emit_json(info)
    else:
        say(f"wrote {out} ({out.stat().st_size / 1024:.0f} KiB): the {method.name} network of {label}")


def _exportable() -> str:
    from keyfill.learn.registry import exportable

    return ", ".join(m.name for m in exportable())


export.help = export.help.replace("{methods}", _exportable())
