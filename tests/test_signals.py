"""SIGTERM and SIGKILL in the middle of a write: no leftovers after the next run, the same dataset on resume."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from keyfill.cli.main import main
from keyfill.files import atomic_output, remove_stale

DATA = Path(__file__).parent / "data"
BVH = DATA / "cmu_02_03_cgspeed_first4frames.bvh"
ROOT = Path(__file__).resolve().parent.parent

# A convert whose USD writer writes half a file and then waits: the test signals it mid-write.
SLOW_CONVERT = """
import sys, time
from pathlib import Path
import keyfill.io.usd as usd
def slow_write(motion, path, **kw):
    Path(path).write_text("#usda 1.0\\n(half a file")
    Path(str(path) + ".started").touch()
    time.sleep(60)
usd.write = slow_write
from keyfill.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


def _start_slow_convert(tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    out = tmp_path / "out.usda"
    proc = subprocess.Popen([sys.executable, "-c", SLOW_CONVERT, "convert", str(BVH), str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env(), cwd=tmp_path)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not list(tmp_path.glob(".out.*.started")):
        assert proc.poll() is None, proc.stderr.read().decode()
        time.sleep(0.02)
    for marker in tmp_path.glob(".out.*.started"):
        marker.unlink()
    return proc, out


def test_sigterm_during_convert_leaves_nothing(tmp_path):
    proc, _out = _start_slow_convert(tmp_path)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 128 + signal.SIGTERM
    assert proc.stderr.read().decode().strip().splitlines()[-1] == "keyfill: error: terminated"
    assert list(tmp_path.iterdir()) == []


def test_sigkill_leftovers_go_with_the_next_convert(tmp_path, capsys):
    proc, out = _start_slow_convert(tmp_path)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    left = [p.name for p in tmp_path.iterdir()]
    assert left and all(n.startswith(".out.") and ".part" in n for n in left)
    # a USD export's own temporary file of the killed writer
    (tmp_path / (left[0].removesuffix(".usda") + ".AbC123")).write_bytes(b"x" * 100)
    other = tmp_path / ".other.k1.abcdefgh.part.usda"  # another output's: not this run's business
    other.write_text("x")
    assert main(["convert", str(BVH), str(out)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([".other.k1.abcdefgh.part.usda", "out.usda"])


def test_a_live_writers_temporary_file_is_kept(tmp_path):
    with atomic_output(tmp_path / "a.bvh") as tmp:
        tmp.write_text("x")
        assert remove_stale(tmp_path) == [] and tmp.exists()
    assert (tmp_path / "a.bvh").read_text() == "x"


def _simulate_cmd(folder: Path) -> list[str]:
    return [sys.executable, "-m", "keyfill", "simulate", "-o", str(folder), "--count", "3", "--seed", "0",
            "--workers", "1", "--iterations", "3"]


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("sig") / "ref"
    assert main(["simulate", "-o", str(folder), "--count", "3", "--seed", "0", "--workers", "1", "--iterations", "3"]) == 0
    return folder


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_resume_after_sigkill_mid_write_is_byte_identical(reference, tmp_path):
    """What a SIGKILL between writes can leave: a temporary motion file, a motion file whose record
    was never appended, a half line. The resumed build ends as the uninterrupted one."""
    folder = tmp_path / "killed"
    shutil.copytree(reference, folder)
    runs = (folder / "runs.jsonl").read_text().splitlines(keepends=True)
    manifest = (folder / "manifest.jsonl").read_text().splitlines(keepends=True)
    last = manifest[-1]
    import json

    last_file = json.loads(last)["file"]
    last_run = json.loads(last)["run"]
    (folder / "manifest.jsonl").write_text("".join(manifest[:-1]))
    (folder / "runs.jsonl").write_text("".join(r for r in runs if json.loads(r)["run"] < last_run) + '{"run": 7, "acc')
    (folder / last_file).write_bytes((folder / last_file).read_bytes()[:100])  # died before the record: a file left
    pid = _dead_pid()
    (folder / f".{Path(last_file).stem}.k{pid}.x1y2z3w4.part.usda").write_bytes(b"half")
    (folder / f".{Path(last_file).stem}.k{pid}.x1y2z3w4.part.QJUVY8").write_bytes(b"usd export temp")
    (folder / f".seq_00099.k{pid}.abcdefgh.part.usda").write_bytes(b"a run that is never needed again")
    subprocess.run(_simulate_cmd(folder), check=True, capture_output=True, env=_env())
    assert _snapshot(folder) == _snapshot(reference)


def test_sigterm_during_simulate_then_resume(reference, tmp_path):
    folder = tmp_path / "termed"
    proc = subprocess.Popen(_simulate_cmd(folder), stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env())
    runs = folder / "runs.jsonl"
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if runs.is_file() and runs.read_text().count("\n") >= 1:
            break
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    rc = proc.wait(timeout=60)
    assert rc in (0, 128 + signal.SIGTERM)
    assert not [p for p in folder.iterdir() if ".part" in p.name]
    subprocess.run(_simulate_cmd(folder), check=True, capture_output=True, env=_env())
    assert _snapshot(folder) == _snapshot(reference)
