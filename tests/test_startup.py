"""Start-up (issue 44): a command imports only the heavy modules it uses, and what decides that stays cheap.

The import checks run the real ``keyfill`` in a fresh interpreter and read ``sys.modules`` at its exit, so a
module-level import of scipy, torch, pxr, onnxruntime or tqdm anywhere on a command's path fails them.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

import pytest

from keyfill import parallel
from keyfill.cli import common
from keyfill.learn import installed_models

DATA = Path(__file__).parent / "data"
SMALL_BVH = DATA / "cmu_02_03_cgspeed_first4frames.bvh"
#: modules a command imports only where it uses them
HEAVY = ("scipy", "torch", "pxr", "onnxruntime", "tqdm", "importlib.metadata", "multiprocessing",
         "concurrent.futures", "keyfill.parallel", "safetensors", "matplotlib", "numpy.ma")

#: runs keyfill's command line as ``keyfill`` does and prints the heavy modules loaded at exit (JSON, stderr)
PROBE = """
import atexit, json, sys
heavy = {heavy!r}
atexit.register(lambda: print("LOADED=" + json.dumps(sorted(m for m in heavy if m in sys.modules)), file=sys.stderr))
from keyfill.cli.main import entry_point
sys.argv = ["keyfill", *{args!r}]
entry_point()
"""


def loaded(args: list[str], tmp_path: Path) -> set[str]:
    """The modules of :data:`HEAVY` that ``keyfill ARGS`` has imported when it exits (it must succeed)."""
    code = PROBE.format(heavy=HEAVY, args=[str(a) for a in args])
    env = {**os.environ, "KEYFILL_CACHE": str(tmp_path / "cache")}
    proc = subprocess.run([sys.executable, "-c", code], check=False, capture_output=True, text=True, cwd=tmp_path,
                          env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    line = next(x for x in proc.stderr.splitlines() if x.startswith("LOADED="))
    return set(json.loads(line.removeprefix("LOADED=")))


def test_cubic_complete_imports_no_heavy_module(tmp_path):
    out = tmp_path / "out.bvh"
    assert loaded(["complete", SMALL_BVH, "--keys", "0,3", "-o", out], tmp_path) == set()
    assert out.stat().st_size > 0


def test_info_imports_no_heavy_module(tmp_path):
    assert loaded(["info", SMALL_BVH], tmp_path) == set()


@pytest.mark.skipif(importlib.util.find_spec("onnxruntime") is None
                    or installed_models.shipped("bandai2-transformer") is None,
                    reason="needs onnxruntime and the shipped human models")
def test_transformer_through_onnx_imports_onnxruntime_only(tmp_path):
    """The shipped transformer runs its graph: onnxruntime, no torch, and no entry-point machinery to find
    the model (the guard, which searches the model's poses with scipy, is off here)."""
    out = tmp_path / "out.bvh"
    got = loaded(["complete", DATA / "bvhtoolbox_test_freebvh_mixamo.bvh", "--key-every", "10",
                  "--method", "transformer", "--guard", "off", "-o", out], tmp_path)
    assert "onnxruntime" in got
    assert not got & {"torch", "scipy", "pxr", "tqdm", "importlib.metadata", "safetensors", "multiprocessing"}


@pytest.mark.parametrize("group", [installed_models.GROUP, "console_scripts", "pytest11"])
def test_entry_points_are_those_importlib_metadata_finds(group):
    ours = sorted(installed_models.entry_points(group))
    theirs = sorted((e.name, e.value) for e in entry_points(group=group))
    assert ours == theirs


def test_entry_point_sections_and_values():
    text = "# a comment\n[console_scripts]\nx = a:b\n\n[keyfill.models]\n m-1 = pkg.mod:OBJ.path [extra]\n"
    assert installed_models._section(text, "keyfill.models") == [("m-1", "pkg.mod:OBJ.path [extra]")]
    assert installed_models._folder("keyfill.learn.installed_models:BUILTIN") == installed_models.BUILTIN
    assert installed_models._folder("keyfill.no_such_module:X") is None
    assert installed_models._folder("not a value!") is None


def test_delayed_bar_is_made_only_after_its_delay(monkeypatch):
    made = []

    class Bar:
        def __init__(self, done):
            self.n = done
            made.append(self)

        def update(self, n):
            self.n += n

        def close(self):
            self.closed = True

    monkeypatch.setattr(common, "progress_shown", lambda: True)
    late = common.DelayedBar(Bar, delay=3600.0)
    late.update(5)
    late.close()
    assert made == []  # a task shorter than the delay draws nothing
    now = common.DelayedBar(Bar, delay=0.0)
    now.update(2)
    now.update(3)
    now.close()
    assert len(made) == 1 and made[0].n == 5 and made[0].closed
    monkeypatch.setattr(common, "progress_shown", lambda: False)
    hidden = common.DelayedBar(Bar, delay=0.0)
    hidden.update(1)
    hidden.close()
    assert len(made) == 1  # not a terminal, or -q: never a bar


@pytest.mark.parametrize("load, jobs, size, expected", [
    (0.0, 4, 64 << 20, 4),  # idle machine, work enough for every core
    (0.0, 2, 64 << 20, 2),  # one worker per job at most
    (0.0, 4, 20 << 20, 2),  # 20 MB pays for two workers, not four
    (0.0, 4, 1 << 20, 1),  # small inputs: starting workers costs more than it saves
    (3.6, 4, 64 << 20, 1),  # four busy cores of four: no more processes
    (2.2, 4, 64 << 20, 2),  # two idle cores
])
def test_default_workers_follow_idle_cores_and_work(monkeypatch, load, jobs, size, expected):
    monkeypatch.setattr(parallel, "available_cpus", lambda: 4)
    monkeypatch.setattr(parallel.os, "getloadavg", lambda: (load, load, load))
    assert parallel.default_workers(jobs, size) == expected
