"""Mutation fuzzing of keyfill's inputs: BVH text, USD text, edit TOML, model folders, glTF files and command
lines (:mod:`fuzz_options`).

Every case is a seed input (a test fixture, an example, the shipped model)
changed by a few random mutations, fed to the library (and, for some cases,
to the CLI) in this process. A :class:`KeyfillError` is a *clean* error; any
other exception, a ``keyfill: error: internal error`` line, a warning (numpy's
overflow warnings, say: a user of the CLI would see it printed), a file that
keyfill writes but cannot read back, running out of memory or a hang is a *finding*.

``tests/test_fuzz.py`` runs a few hundred cases through hypothesis in
``make test``. ``make fuzz`` runs this module as a script::

    python tests/fuzzing.py --cases 100000 --jobs 2 --mem-mb 2048 --timeout 20

Cases run in ``--jobs`` worker processes, each under an address-space limit
(``RLIMIT_AS``: its size after start-up plus ``--mem-mb``); a worker that
spends more than ``--timeout`` seconds on one case is killed and the case
counted as a hang. Case ``i`` depends only on ``(--seed, i)``; findings are
written to ``--out`` (default ``out/fuzz``) with their traceback, to become
regression fixtures in ``tests/data/regress/``.
"""

from __future__ import annotations

import argparse
import contextlib
import io as _io
import json
import os
import random
import re
import shutil
import sys
import tempfile
import time
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
DATA = HERE / "data"
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))

import fuzz_options

#: (runs before 2026-12-03 had the first five only: a case number of theirs is another input now)
KINDS = ("bvh", "usd", "toml", "model", "gltf", "argv")
SUFFIX = {"bvh": ".bvh", "usd": ".usda", "toml": ".toml", "model": "", "gltf": ".glb", "argv": ".json"}

# --- seeds ------------------------------------------------------------------------------------------

LAMP_CURVES = ROOT / "examples" / "edit" / "lamp_nod_curves.usda"
LAMP_KEYS = ROOT / "examples" / "lamp" / "keys.usda"
ARNN_MODEL = ROOT / "keyfill" / "learn" / "models" / "lamp-arnn"

#: an edit file that uses every field (the lamp curves have keys 0, 10, 20, 30)
RICH_TOML = """tolerance = 0.001
epsilon = 0.0001
pins = ["base", { joint = "head", offset = [0, 0.12, 0] }]
lock = ["leg"]
break_tangents = false

[limits]
"neck.Zrotation" = [-120, 0]
head = [-90, 90]

[stiffness]
head = 10
"neck.Zrotation" = 2.5

[[contact]]
joint = "base"
frames = [10, 20]

[[edit]]
joint = "head"
offset = [0, 0.12, 0]
frame = 15
target = [0.1, 0.3, 0.0]
orientation = [1, 0, 0, 0]
hold = [12]
pins = [{joint = "neck", offset = [0, 0.1, 0]}]
contacts = [{joint = "base", frames = [0, 10]}]

[[edit]]
time = 24.5
timing = 2.0
joint = "head"
"""


def seeds(kind: str) -> list[bytes]:
    """The unmutated inputs of ``kind`` (for models: a JSON of the folder's two files, see :func:`_model_files`)."""
    if kind == "bvh":
        return [p.read_bytes() for p in sorted(DATA.glob("*.bvh"))]
    if kind == "usd":
        out = [LAMP_KEYS.read_bytes(), (ROOT / "examples" / "lamp" / "truth.usda").read_bytes()]
        small = [p for p in sorted((ROOT / "examples").rglob("*.usda")) if p.stat().st_size < 200_000]
        small += sorted((DATA / "regress").glob("*.usda"))
        out += [p.read_bytes() for p in small if p.read_bytes() not in out]
        return out
    if kind == "toml":
        return [(ROOT / "examples" / "edit" / "lamp_lift.toml").read_bytes(), RICH_TOML.encode()]
    if kind == "model":
        return [_pack(ARNN_MODEL)]
    if kind == "gltf":
        return _gltf_seeds()
    if kind == "argv":
        return fuzz_options.seeds()
    raise ValueError(kind)


def _gltf_seeds() -> list[bytes]:
    """What keyfill writes (a .glb, a .gltf with its buffer embedded) and a character with a mesh under an
    Armature node (``tests/test_gltf.py``'s hand-built rig)."""
    from test_gltf import character, glb

    from keyfill import io
    from keyfill.io import gltf_write

    with tempfile.TemporaryDirectory() as tmp:
        motion = io.load(DATA / "edge_layouts_crlf.bvh")
        io.save(motion, Path(tmp) / "a.glb")
        gltf_write.write(io.load(DATA / "cmu_02_03_cgspeed_first4frames.bvh"), Path(tmp) / "b.gltf", sidecar=None)
        return [(Path(tmp) / "a.glb").read_bytes(), (Path(tmp) / "b.gltf").read_bytes(), glb(*character()[:2])]


def _glb_chunks(data: bytes) -> tuple[bytes, bytes] | None:
    """``(JSON chunk, the rest after it)`` of a well-formed start of a .glb, else None."""
    if data[:4] != b"glTF" or len(data) < 20:
        return None
    n = int.from_bytes(data[12:16], "little")
    return (data[20: 20 + n], data[20 + n:]) if 20 + n <= len(data) else None


def _pack(folder: Path) -> bytes:
    """A model folder as one byte string: the config text, a separator line, the weights."""
    return (folder / "config.json").read_bytes() + b"\n@@WEIGHTS@@\n" + (folder / "weights.safetensors").read_bytes()


def _model_files(data: bytes) -> tuple[bytes, bytes]:
    config, _sep, weights = data.partition(b"\n@@WEIGHTS@@\n")
    return config, weights


# --- mutations ---------------------------------------------------------------------------------------

NUMBERS = [
    b"0", b"-0", b"1", b"-1", b"2", b"3", b"4", b"6", b"7", b"0.5", b"1e39", b"-1e39", b"1e-320", b"1e308", b"1e309",
    b"-1e309", b"nan", b"inf", b"-inf", b"NaN", b"1_0", b"0x10", b"1e", b"+.5e-3", b"99999999999", b"4294967296",
    b"18446744073709551616", b"9" * 30, b"9" * 400, b"1e999999", b"100000000", b"1000000", b"10000000", b"-2147483648",
    b"30000", b"65536", b"1e9", b"0.0333333", b"true", b"null", b'"x"', b"[]", b"{}",
]
WORDS = [
    b"HIERARCHY", b"ROOT", b"JOINT", b"End", b"Site", b"{", b"}", b"OFFSET", b"CHANNELS", b"MOTION", b"Frames:",
    b"Frame Time:", b"Xrotation", b"Wrotation", b"Xposition", b"def", b"over", b"class", b"(", b")", b"[", b"]",
    b"=", b'"', b"'", b",", b"\n", b"\r\n", b"\t", b"\x00", b"\xff\xfe", b"\xc3", b"#", b"[[edit]]", b"[limits]",
    b"[stiffness]", b"[[contact]]", b"timeSamples", b"customData", b"dictionary", b"token[]", b"int[]",
    b"string[]", b"double3[]", b"quatf[]", b"float3[]", b"matrix4d[]", b"uniform", b"rel", b"</Root>",
    b"timeCodesPerSecond", b"endTimeCode", b"startTimeCode", b"keys", b"names", b"channels", b"joint", b"frame",
    b"time", b"move", b"target", b"timing", b"epsilon", b"hidden_size", b"sizes", b"arch", b"kind", b"skeleton",
    b"normalizer", b"mean", b"std", b"parents", b"offsets", b"version", b"format", b"architecture",
]
#: words of glTF's JSON, for the mutations of glTF inputs
GLTF_WORDS = [
    b"nodes", b"children", b"skins", b"joints", b"inverseBindMatrices", b"animations", b"channels", b"samplers",
    b"sampler", b"target", b"node", b"path", b"translation", b"rotation", b"scale", b"weights", b"matrix", b"input",
    b"output", b"interpolation", b"STEP", b"CUBICSPLINE", b"accessors", b"bufferView", b"bufferViews", b"byteOffset",
    b"byteLength", b"byteStride", b"count", b"componentType", b"5126", b"5121", b"normalized", b"type", b"VEC4",
    b"MAT4", b"SCALAR", b"sparse", b"buffers", b"uri", b"../case.bin", b"/etc/passwd", b"data:,", b"extras",
    b"keyfill", b"fps", b"metersPerUnit", b"upAxis", b"endSites", b"keyMask",
]
_NUM = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_TOKEN = re.compile(rb"[^\s\[\]{}(),=\"']+")


def _spans(pattern, data: bytes, rnd: random.Random, limit: int = 200_000):
    """A random match of ``pattern`` in (the start of) ``data``, or None."""
    window_start = rnd.randrange(max(1, len(data) - limit)) if len(data) > limit else 0
    matches = [m.span() for m, _ in zip(pattern.finditer(data, window_start), range(2000))]
    return (window_start, matches[rnd.randrange(len(matches))]) if matches else None


def mutate(data: bytes, rnd: random.Random, kind: str) -> bytes:
    """``data`` changed by one to three random mutations.

    A model folder's config gets most of them; its weights file gets the rest,
    mostly in the safetensors header (the JSON that gives names, shapes and offsets).
    """
    if kind == "argv":
        return fuzz_options.mutate(data, rnd)
    if kind == "model":
        config, weights = _model_files(data)
        if rnd.random() < 0.8:
            config = mutate(config, rnd, "json")
        else:
            head = 8 + int.from_bytes(weights[:8], "little") if len(weights) >= 8 else 0
            if 8 < head <= len(weights) and rnd.random() < 0.7:
                header = mutate(weights[8:head], rnd, "json")
                length = len(header) if rnd.random() < 0.9 else head - 8  # a length that no longer fits, sometimes
                weights = length.to_bytes(8, "little") + header + weights[head:]
            else:
                weights = mutate(weights, rnd, "bytes")
        return config + b"\n@@WEIGHTS@@\n" + weights
    chunks = _glb_chunks(data) if kind == "gltf" else None
    if chunks is not None and rnd.random() < 0.9:  # mostly the JSON; the lengths mostly follow it
        text, rest = chunks
        if rnd.random() < 0.75:
            text = mutate(text, rnd, "gltf")
        else:
            rest = rest[:8] + mutate(rest[8:], rnd, "bytes")
        n = len(text) if rnd.random() < 0.9 else len(chunks[0])
        body = n.to_bytes(4, "little") + data[16:20] + text + rest
        total = 12 + len(body) if rnd.random() < 0.9 else len(data)
        return data[:8] + total.to_bytes(4, "little") + body
    for _ in range(rnd.choice((1, 1, 1, 2, 3))):
        data = _mutate_once(data, rnd, kind)
    return data


def _mutate_once(data: bytes, rnd: random.Random, kind: str) -> bytes:
    n = len(data)
    op = rnd.randrange(13)
    if op <= 2:  # a number becomes an interesting one (the commonest mutation)
        got = _spans(_NUM, data, rnd)
        if got:
            _, (a, b) = got
            return data[:a] + rnd.choice(NUMBERS) + data[b:]
    if op >= 11:  # a number changes a little or a lot, staying a plain number (inputs that may be accepted)
        got = _spans(_NUM, data, rnd)
        if got:
            _, (a, b) = got
            try:
                v = float(data[a:b])
            except ValueError:
                return data
            if not abs(v) < 1e300:
                return data
            v = rnd.choice((v + 1, v - 1, -v, v * 10, v / 10, v * 1e6, float(round(v)), 0.0))
            text = str(int(v)) if v.is_integer() and abs(v) < 1e15 and b"." not in data[a:b] else repr(v)
            return data[:a] + text.encode() + data[b:]
    if op == 3:  # a word becomes another word
        got = _spans(_TOKEN, data, rnd)
        if got:
            _, (a, b) = got
            return data[:a] + rnd.choice(WORDS + GLTF_WORDS if kind == "gltf" else WORDS) + data[b:]
    if op == 4 and n:  # delete a span
        a = rnd.randrange(n)
        return data[:a] + data[a + rnd.choice((1, 2, 8, 64, 1024)):]
    if op == 5 and n:  # repeat a line many times (deep nesting, long lists, many frames)
        lines = data.split(b"\n")
        i = rnd.randrange(len(lines))
        k = rnd.choice((2, 10, 100, 1000, 3000))
        return b"\n".join(lines[:i] + [lines[i]] * k + lines[i:])
    if op == 6 and n:  # insert a word or bytes
        a = rnd.randrange(n + 1)
        return data[:a] + rnd.choice(WORDS + [bytes([rnd.randrange(256)])]) + data[a:]
    if op == 7 and n:  # truncate
        return data[: rnd.randrange(n)]
    if op == 8 and n:  # swap two lines
        lines = data.split(b"\n")
        i, j = rnd.randrange(len(lines)), rnd.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
        return b"\n".join(lines)
    if op == 9 and n:  # duplicate a span elsewhere
        a = rnd.randrange(n)
        b = min(n, a + rnd.choice((4, 32, 256, 4096)))
        c = rnd.randrange(n + 1)
        return data[:c] + data[a:b] + data[c:]
    if op == 10 and n:  # flip a byte
        a = rnd.randrange(n)
        return data[:a] + bytes([data[a] ^ (1 << rnd.randrange(8))]) + data[a + 1:]
    return data


# --- running one case --------------------------------------------------------------------------------


@dataclass
class Outcome:
    status: str  # "ok", "clean" (a KeyfillError), "finding"
    detail: str = ""


_CACHE: dict = {}
#: joint-frames up to which an accepted motion is written back and read again
ROUND_TRIP_MAX = 200_000


def _lamp_curves():
    if "curves" not in _CACHE:
        from keyfill.io import usd_curves

        _CACHE["curves"] = usd_curves.read(LAMP_CURVES)
    return _CACHE["curves"]


def _lamp_keys():
    if "lamp" not in _CACHE:
        from keyfill import io

        _CACHE["lamp"] = io.load(LAMP_KEYS)
    return _CACHE["lamp"]


def _cli(args: list[str]) -> Outcome:
    from keyfill.cli.main import main

    err, out = _io.StringIO(), _io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        rc = main(args)
    text = err.getvalue()
    if "internal error" in text or "Traceback" in text:
        return Outcome("finding", "CLI: " + text.strip()[-2000:])
    if rc not in (0, 1, 2):
        return Outcome("finding", f"CLI exit code {rc}: {text.strip()[-500:]}")
    if rc != 0 and not text.strip().startswith("keyfill: error: "):
        return Outcome("finding", f"CLI exit {rc} without one error line: {text[-500:]!r}")
    return Outcome("ok" if rc == 0 else "clean", text.strip())


def _motion_case(path: Path, work: Path, with_cli: bool) -> Outcome:
    from keyfill import io
    from keyfill.errors import KeyfillError

    if with_cli:
        return _cli(["convert", str(path), str(work / ("cli.bvh" if path.suffix != ".bvh" else "cli.glb"))])
    try:
        motion = io.load(path)
    except KeyfillError as e:
        return Outcome("clean", str(e))
    # What keyfill accepts it must write, and what it writes it must read back (small motions: a
    # round trip of a long one takes seconds per format, which the benchmarks measure).
    if motion.num_frames * motion.num_joints > ROUND_TRIP_MAX:
        return Outcome("ok")
    for out in (work / "back.usda", work / "back.bvh") + ((work / "back.glb",) if path.suffix == ".glb" else ()):
        try:
            io.save(motion, out)
        except KeyfillError as e:
            if "cannot hold" in str(e) or "has no position channel" in str(e):
                continue  # a USD rotation that a BVH joint's channels cannot carry: a clean refusal
            return Outcome("clean", str(e))
        try:
            again = io.load(out)
        except KeyfillError as e:
            return Outcome("finding", f"written {out.suffix} cannot be read back: {e}")
        if again.num_frames != motion.num_frames or again.num_joints != motion.num_joints:
            return Outcome("finding", f"{out.suffix} round trip changed the size")
    return Outcome("ok")


def _toml_case(path: Path, rnd_mode: int) -> Outcome:
    from keyfill.edit import edits
    from keyfill.errors import KeyfillError

    mode, frame = [("tangents", None), ("tangents", None), ("pose", None), ("pose", 10.0)][rnd_mode % 4]
    try:
        edits.load(path, _lamp_curves(), mode=mode, frame=frame)
    except KeyfillError as e:
        return Outcome("clean", str(e))
    return Outcome("ok")


def _model_case(folder: Path) -> Outcome:
    """Complete the lamp's keys with the model in ``folder`` (through the registry, as ``keyfill complete`` does)."""
    from keyfill.errors import KeyfillError
    from keyfill.learn import registry

    try:
        kind = registry.method_for_model(folder).name
        motion = _lamp_keys()
        registry.complete(motion, motion.keys, kind, registry.CompleteOptions(model=str(folder)))
    except KeyfillError as e:
        return Outcome("clean", str(e))
    return Outcome("ok")


def run_case(kind: str, data: bytes, work: Path, variant: int = 0) -> Outcome:
    """Feed ``data`` (an input of ``kind``) to keyfill in ``work`` (an empty folder) and classify what happens."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # becomes an exception, so a finding
        warnings.simplefilter("error", UserWarning)
        return _run_case(kind, data, work, variant)


def _run_case(kind: str, data: bytes, work: Path, variant: int) -> Outcome:
    try:
        if kind == "argv":
            return fuzz_options.run(data, work, _cli)
        if kind == "model":
            folder = work / "model"
            folder.mkdir()
            config, weights = _model_files(data)
            (folder / "config.json").write_bytes(config)
            (folder / "weights.safetensors").write_bytes(weights)
            return _model_case(folder)
        path = work / ("case" + (".gltf" if kind == "gltf" and data[:1] == b"{" else SUFFIX[kind]))
        path.write_bytes(data)
        if kind == "toml":
            return _toml_case(path, variant)
        return _motion_case(path, work, with_cli=variant % 10 == 0)
    except MemoryError:
        return Outcome("finding", "memory: MemoryError\n" + traceback.format_exc()[-3000:])
    except RecursionError:
        return Outcome("finding", "RecursionError\n" + traceback.format_exc()[-3000:])
    except Exception as e:  # noqa: BLE001 - anything but a KeyfillError is what we look for
        return Outcome("finding", f"{type(e).__name__}: {e}\n" + traceback.format_exc()[-3000:])


def case(seed: int, i: int) -> tuple[str, bytes, int]:
    """Case ``i`` of the run seeded ``seed``: ``(kind, input, variant)``."""
    rnd = random.Random(f"{seed}:{i}")
    kind = KINDS[i % len(KINDS)]
    pool = _CACHE.setdefault(("seeds", kind), seeds(kind))
    data = pool[rnd.randrange(len(pool))]
    return kind, mutate(data, rnd, kind), rnd.randrange(1000)


# --- the driver (make fuzz) ----------------------------------------------------------------------------


def _worker(seed: int, indices, mem_mb: int, conn) -> None:
    import resource

    if not os.environ.get("KEYFILL_FUZZ_STDERR"):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)  # USD's warnings about the mutated files would drown the report
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import numpy  # noqa: F401 - imported before the limit, like the heavy modules below
    import torch

    torch.set_num_threads(1)
    from pxr import Usd  # noqa: F401

    import keyfill.io.gltf_write
    import keyfill.io.usd
    import keyfill.learn.arnn.model
    import keyfill.learn.registry  # noqa: F401

    _lamp_curves()
    _lamp_keys()
    for kind in KINDS:
        _CACHE[("seeds", kind)] = seeds(kind)
    with open("/proc/self/statm") as f:
        size = int(f.read().split()[0]) * resource.getpagesize()
    cap = size + mem_mb * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    conn.send(("ready", size // 2**20))
    with tempfile.TemporaryDirectory(prefix="keyfill-fuzz-") as tmp:
        for i in indices:
            kind, data, variant = case(seed, i)
            work = Path(tmp) / str(i)
            work.mkdir()
            conn.send(("start", i))
            t = time.perf_counter()
            out = run_case(kind, data, work, variant)
            seconds = time.perf_counter() - t
            shutil.rmtree(work, ignore_errors=True)
            conn.send(("done", i, kind, out.status, out.detail if out.status == "finding" else "", seconds))
    conn.send(("end",))


def drive(cases: int, jobs: int, seed: int, mem_mb: int, timeout: float, out_dir: Path, start: int = 0) -> dict:
    import multiprocessing as mp

    ctx = mp.get_context("spawn")
    out_dir.mkdir(parents=True, exist_ok=True)
    counts = {"inputs": 0, "ok": 0, "clean": 0, "findings": 0, "hangs": 0, "crashes": 0, "memory": 0}
    per_kind = {k: {"inputs": 0, "ok": 0, "clean": 0, "findings": 0, "seconds": 0.0} for k in KINDS}
    slowest = (0.0, None)
    t0 = time.time()

    def record_finding(i, kind, detail):
        counts["findings"] += 1
        per_kind[kind]["findings"] += 1
        _, data, variant = case(seed, i)
        name = f"{kind}-{seed}-{i}"
        (out_dir / (name + (SUFFIX[kind] or ".model"))).write_bytes(data)
        (out_dir / (name + ".txt")).write_text(f"variant {variant}\n{detail}\n")
        print(f"finding {name}: {detail.splitlines()[0][:200] if detail else ''}", flush=True)

    todo = [list(range(start + w, start + cases, jobs)) for w in range(jobs)]
    workers: dict[int, tuple] = {}

    def spawn(w):
        if not todo[w]:
            return
        parent, child = ctx.Pipe()
        p = ctx.Process(target=_worker, args=(seed, todo[w], mem_mb, child), daemon=True)
        p.start()
        child.close()
        workers[w] = (p, parent, None, None)  # process, pipe, current case, its start time

    for w in range(jobs):
        spawn(w)
    last_report = time.time()
    while workers:
        for w, (p, conn, cur, since) in list(workers.items()):
            while conn.poll(0.05 / max(1, len(workers))):
                try:
                    msg = conn.recv()
                except (EOFError, OSError):
                    p.join(timeout=10)
                    break
                if msg[0] == "start":
                    cur, since = msg[1], time.time()
                elif msg[0] == "done":
                    _, i, kind, status, detail, seconds = msg
                    todo[w].remove(i)
                    counts["inputs"] += 1
                    per_kind[kind]["inputs"] += 1
                    per_kind[kind]["seconds"] += seconds
                    if seconds > slowest[0]:
                        slowest = (seconds, f"{kind}-{seed}-{i}")
                    if status == "finding":
                        if detail.startswith("memory"):
                            counts["memory"] += 1
                        record_finding(i, kind, detail)
                    else:
                        counts[status] += 1
                        per_kind[kind][status] += 1
                    cur, since = None, None
                elif msg[0] == "end":
                    todo[w] = []
                workers[w] = (p, conn, cur, since)
            if cur is not None and since is not None and time.time() - since > timeout:
                p.kill()
                p.join()
                kind = KINDS[cur % len(KINDS)]
                counts["inputs"] += 1
                counts["hangs"] += 1
                per_kind[kind]["inputs"] += 1
                record_finding(cur, kind, f"hang: over {timeout:g} s")
                todo[w].remove(cur)
                del workers[w]
                spawn(w)
                continue
            if not p.is_alive():
                while True:  # whatever it sent before it ended
                    try:
                        if not conn.poll():
                            break
                        msg = conn.recv()
                    except (EOFError, OSError):
                        break
                    if msg[0] == "done":
                        _, i, kind, status, detail, seconds = msg
                        todo[w].remove(i)
                        counts["inputs"] += 1
                        per_kind[kind]["inputs"] += 1
                        if status == "finding":
                            record_finding(i, kind, detail)
                        else:
                            counts[status] += 1
                            per_kind[kind][status] += 1
                        cur = None
                    elif msg[0] == "start":
                        cur = msg[1]
                p.join()
                if todo[w] and cur is None:  # died between cases (making the next one): blame the next one
                    cur = todo[w][0]
                if todo[w] and cur is not None:  # died in a case: a crash (or the memory cap hit in C code)
                    kind = KINDS[cur % len(KINDS)]
                    counts["inputs"] += 1
                    counts["crashes"] += 1
                    per_kind[kind]["inputs"] += 1
                    record_finding(cur, kind, f"crash: worker exit code {p.exitcode}")
                    todo[w].remove(cur)
                del workers[w]
                if todo[w]:
                    spawn(w)
        if time.time() - last_report > 30:
            last_report = time.time()
            rate = counts["inputs"] / (time.time() - t0)
            print(f"  {counts['inputs']} inputs, {counts['clean']} clean errors, {counts['findings']} findings, "
                  f"{rate:.0f}/s", flush=True)
    seconds = time.time() - t0
    summary = {**counts, "seconds": round(seconds, 1), "per_kind": per_kind, "seed": seed, "jobs": jobs,
               "mem_mb": mem_mb, "timeout_s": timeout, "slowest_case_s": round(slowest[0], 2),
               "slowest_case": slowest[1]}
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=100_000)
    ap.add_argument("--start", type=int, default=0, help="first case index (to continue a run)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mem-mb", type=int, default=2048, help="address space each worker may add to its start-up size")
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds one case may take")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "fuzz")
    a = ap.parse_args(argv)
    s = drive(a.cases, a.jobs, a.seed, a.mem_mb, a.timeout, a.out, a.start)
    kinds = ", ".join(f"{k} {v['inputs']}" for k, v in s["per_kind"].items())
    print(f"fuzz: {s['inputs']} inputs ({kinds}), "
          f"{s['ok']} accepted, {s['clean']} clean errors, {s['findings']} findings "
          f"({s['memory']} memory, {s['hangs']} hangs, {s['crashes']} crashes) in {s['seconds']:.0f} s; "
          f"slowest case {s['slowest_case_s']} s")
    return 1 if s["findings"] else 0


if __name__ == "__main__":
    sys.exit(main())
