"""The option parser's share of ``make fuzz`` (tests/fuzzing.py, kind ``argv``): random command lines.

A case is a command line of one of the cheap commands (:data:`COMMANDS`: reading, converting, completing with
the splines or the shipped transformer's graph, pictures, tangent editing, retargeting) built from a valid one
(:data:`SEEDS`) by one to four changes: an option's value becomes an awkward one (empty, negative, huge,
``nan``, ``1e400``, 300 characters, another path), an argument is dropped, repeated or swapped, an option of
the command (read from its click parameters) is added with a random value of its type, or a path becomes a
special one (a folder, a missing file, ``/dev/zero``, a FIFO). It runs through ``keyfill.cli.main.main`` in
the case's own folder with an empty standard input; exit 0, or 1/2 with one ``keyfill: error:`` line, is
clean, and anything else (an internal error, a traceback, another exit code) is a finding.

Left out because they are slow by design or start other processes: ``train``, ``simulate``, ``export``,
``library``, ``evaluate``, ``--workers``, ``--scheduler``, and ``--debug`` (which prints tracebacks on purpose).
"""

from __future__ import annotations

import contextlib
import io as _io
import json
import os
import random
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATA = HERE / "data"

#: placeholders of the seed lines -> files (``{work}`` is the case's folder, made fresh for each case)
FILES = {
    "cmu": str(DATA / "cmu_02_03_cgspeed_first4frames.bvh"),
    "edges": str(DATA / "edge_layouts_crlf.bvh"),
    "lamp": str(ROOT / "examples" / "lamp" / "keys.usda"),
    "human": str(ROOT / "examples" / "human" / "keys_15.usda"),
    "glb": str(ROOT / "examples" / "mixamo_keys.glb"),
    "curves": str(ROOT / "examples" / "edit" / "lamp_nod_curves.usda"),
    "edit": str(ROOT / "examples" / "edit" / "lamp_lift.toml"),
}
COMMANDS = ("info", "convert", "complete", "plot", "preview", "edit-tangents", "pose", "retarget")
SKIPPED_OPTIONS = {"--workers", "--scheduler", "--connect-timeout", "--debug", "--help", "--version"}
#: valid command lines the mutations start from
SEEDS = [
    ["info", "{cmu}"],
    ["info", "{lamp}", "--json"],
    ["info", "{cmu}", "--rig", "--up-axis", "Z", "--meters-per-unit", "0.0254"],
    ["convert", "{cmu}", "{work}/out.usda"],
    ["convert", "{edges}", "{work}/out.bvh", "--bvh-layout", "full"],
    ["convert", "{glb}", "{work}/out.bvh"],
    ["convert", "{lamp}", "{work}/curves.usda", "--curves", "--keys", "0,10,20,30"],
    ["convert", "{cmu}", "{edges}", "-o", "{work}/o/", "--format", "glb"],
    ["complete", "{cmu}", "--keys", "0,3", "-o", "{work}/out.bvh"],
    ["complete", "{lamp}", "-o", "{work}/out.usda", "--method", "linear"],
    ["complete", "{cmu}", "--key-every", "2", "-o", "{work}/out.glb", "--feet", "lock", "--seed", "3"],
    ["complete", "{human}", "-o", "{work}/out.usda", "--method", "transformer", "--runtime", "onnx"],
    ["complete", "{human}", "--key-joints", "Hips", "--key-positions", "--method", "gan", "-o", "{work}/p.bvh"],
    ["plot", "{lamp}", "-o", "{work}/p.png", "--frames", "0:20"],
    ["plot", "{cmu}", "{cmu}", "--labels", "a,b", "--positions", "-o", "{work}/p.png"],
    ["preview", "{cmu}", "-o", "{work}/p.png", "--view", "3d", "--size", "160x120"],
    ["preview", "{lamp}", "-o", "{work}/p.gif", "--step", "3", "--size", "96x96"],
    ["edit-tangents", "{curves}", "--edit", "{edit}", "-o", "{work}/e.usda"],
    ["retarget", "{cmu}", "--to", "{cmu}", "-o", "{work}/r.bvh"],
]
VALUES = ["", "0", "-1", "1", "2", "7", "-0", "1e400", "-1e400", "nan", "inf", "1e-320", "9" * 40, "0x10", "1_0",
          " 3", "3 ", "0.5", "1,2", "3,1", "0,0", "0:0", "5:2", "-3:", ":", "a", "é", "\u0663", "x" * 300, "%00",
          "0,1,2,3,4,5,6,7,8,9", "Hips", "NoSuchJoint", "160x120", "0x0", "99999x99999", "Z", "X", "full", "on"]
PATHS = ["{cmu}", "{lamp}", "{glb}", "{work}", "{work}/missing.bvh", "{work}/fifo.bvh", "/dev/zero", "/dev/null",
         "/dev/stdout",
         "{work}/o.fbx", "{work}/o.txt", "{work}/sub/", "{work}/out.bvh", "{work}/out.usdz", "{cmu}", "."]


def seeds() -> list[bytes]:
    return [json.dumps(s).encode() for s in SEEDS]


@contextlib.contextmanager
def _in_folder(work: Path):
    """In ``work`` (outputs with relative names land there), with an empty standard input."""
    old, stdin = os.getcwd(), sys.stdin
    os.chdir(work)
    sys.stdin = _io.TextIOWrapper(_io.BytesIO(b""))
    try:
        yield
    finally:
        os.chdir(old)
        sys.stdin = stdin


def _options(command: str) -> list[tuple[str, object]]:
    """``(flag, click type or None for a flag)`` of each option ``command`` takes (from click)."""
    import click

    from keyfill.cli.main import cli

    ctx = click.Context(cli)
    cmd = cli.get_command(ctx, command)
    out = []
    for p in cmd.params if cmd is not None else ():
        if isinstance(p, click.Option) and p.opts[-1] not in SKIPPED_OPTIONS and not p.hidden:
            out.append((p.opts[-1], None if p.is_flag else p.type))
    return out


def _value_for(kind, rnd: random.Random) -> str:
    import click

    if isinstance(kind, click.Choice) and rnd.random() < 0.6:
        return rnd.choice(list(kind.choices))
    if isinstance(kind, click.Path):
        return rnd.choice(PATHS)
    return rnd.choice(VALUES)


def mutate(data: bytes, rnd: random.Random) -> bytes:
    """One to four changes to the command line ``data`` (JSON); the command itself stays one of
    :data:`COMMANDS` (or, rarely, becomes another's)."""
    args = json.loads(data)
    for _ in range(rnd.choice((1, 1, 2, 3, 4))):
        op = rnd.randrange(8)
        i = rnd.randrange(1, len(args)) if len(args) > 1 else None
        if op <= 1 and i is not None:  # a value becomes an awkward one
            args[i] = rnd.choice(PATHS if "{" in args[i] or "/" in args[i] else VALUES)
        elif op == 2 and i is not None:
            del args[i]
        elif op == 3 and i is not None:
            args.insert(i, args[i])
        elif op == 4 and len(args) > 2:
            a, b = rnd.sample(range(1, len(args)), 2)
            args[a], args[b] = args[b], args[a]
        elif op <= 6:  # an option of the command with a value of its type
            options = _options(args[0])
            if options:
                flag, kind = rnd.choice(options)
                args[len(args) if i is None else rnd.randrange(1, len(args) + 1):0] = (
                    [flag] if kind is None else [flag, _value_for(kind, rnd)])
        else:
            args[0] = rnd.choice(COMMANDS)
    return json.dumps(args).encode()


def run(data: bytes, work: Path, cli) -> object:
    """Run the command line ``data`` in ``work`` through ``cli`` (:func:`tests.fuzzing._cli`), on copies of
    :data:`FILES` in ``work/in`` (a mutated line may name an input as an output: never the repository's)."""
    os.mkfifo(work / "fifo.bvh")
    (work / "in").mkdir()
    names = {"work": str(work)}
    for name, path in FILES.items():
        names[name] = str(shutil.copy(path, work / "in" / Path(path).name))
    args = json.loads(data)
    for name, value in names.items():
        args = [a.replace("{" + name + "}", value) for a in args]
    with _in_folder(work):
        return cli(args)
