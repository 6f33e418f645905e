"""SIGTERM and SIGKILL in the middle of a write: no leftovers after the next run, the same dataset on resume."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from keyfill import io
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


# --- every moment of complete and convert, start-up included (issue 48) ---------------------------------------

SIGNAL_NAMES = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated", signal.SIGHUP: "terminated"}
BATCH_FILES = 120


def _keyfill(*args) -> subprocess.Popen:
    """``python -m keyfill ARGS``: the program itself, as the console script runs it."""
    return subprocess.Popen([sys.executable, "-m", "keyfill", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=_env(), cwd=ROOT)


def _started(proc: subprocess.Popen) -> None:
    """Wait until keyfill's first module has run (it catches SIGTERM from then on: ``SigCgt`` in /proc); before
    that Python itself is starting, and the signal does what it does to any program."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read().decode()
        status = Path(f"/proc/{proc.pid}/status").read_text()
        caught = int(next(line for line in status.splitlines() if line.startswith("SigCgt:")).split()[1], 16)
        if caught >> (signal.SIGTERM - 1) & 1:
            return
        time.sleep(0.002)
    raise AssertionError("keyfill did not start within 30 s")


def _ended(proc: subprocess.Popen, sig: int) -> str:
    """Its exit code is 128 + the signal and nothing comes after one error line: that line."""
    _, err = proc.communicate(timeout=120)
    lines = err.decode().strip().splitlines()
    assert proc.returncode == 128 + sig, err.decode()
    assert "Traceback" not in err.decode() and "Warning" not in err.decode(), err.decode()
    return lines[-1]


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if ".part" in p.name or "probe" in p.name)


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("clips")
    for i in range(BATCH_FILES):
        shutil.copy(BVH, folder / f"c{i:03d}.bvh")
    return folder


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="needs /proc")
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.parametrize("after", [0.0, 0.1, 0.25])
def test_a_signal_while_convert_starts_ends_it(tmp_path, sig, after):
    """From keyfill's first module on (click, keyfill and USD's modules loading: a SIGINT there was swallowed
    by USD's module set-up, and the command finished with exit 0) to the written file."""
    out = tmp_path / "walk.usda"
    proc = _keyfill("convert", BVH, out)
    _started(proc)
    time.sleep(after)
    proc.send_signal(sig)
    assert _ended(proc, sig) == f"keyfill: error: {SIGNAL_NAMES[sig]}"
    assert [p.name for p in tmp_path.iterdir()] in ([], ["walk.usda"])  # the whole file, or none
    if out.exists():
        assert io.load(out).num_frames == 4


IMPORT_STALLS = """
import sys, time
from pathlib import Path

class Stall:  # the import of USD's module takes a second: the test signals the command in the middle of it
    def find_spec(self, name, path=None, target=None):
        if name == "pxr.Usd":
            Path(sys.argv[-1] + ".importing").touch()
            time.sleep(1.0)
        return None

sys.meta_path.insert(0, Stall())
from keyfill.cli.main import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_during_an_import_is_raised_when_the_import_ends(tmp_path, sig):
    out = tmp_path / "walk.usda"
    proc = subprocess.Popen([sys.executable, "-c", IMPORT_STALLS, "convert", str(BVH), str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env(), cwd=tmp_path)
    marker = Path(str(out) + ".importing")
    deadline = time.monotonic() + 60
    while not marker.exists() and time.monotonic() < deadline:
        assert proc.poll() is None, proc.stderr.read().decode()
        time.sleep(0.01)
    marker.unlink()
    proc.send_signal(sig)
    assert _ended(proc, sig) == f"keyfill: error: {SIGNAL_NAMES[sig]}"
    assert list(tmp_path.iterdir()) == []


def _outputs(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.glob("*.usda") if not p.name.startswith(".")) if folder.exists() else []


def _recorded(folder: Path) -> list[str]:
    record = folder / ".keyfill-outputs.json"
    return sorted(json.loads(record.read_text())["outputs"]) if record.exists() else []


@pytest.mark.skipif(not Path("/proc/self/status").is_file(), reason="needs /proc")
@pytest.mark.parametrize("workers", [1, 2])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
@pytest.mark.parametrize("moment", ["start-up", "outputs"])
def test_a_signal_in_a_batch_keeps_what_it_finished_and_a_rerun_finishes(clips, tmp_path, workers, sig, moment):
    """Signalled while it starts or once outputs appear: exit 128 + the signal, the last line says how many
    are done and that the same command finishes; no temporary file; the record lists every output there is,
    and the re-run skips exactly those and does the rest."""
    out = tmp_path / "out"
    cmd = ("convert", clips, "-o", f"{out}/", "--format", "usda", "--workers", workers, "--batch-size", 8)
    proc = _keyfill(*cmd)
    _started(proc)
    if moment == "outputs":
        deadline = time.monotonic() + 60
        while len(_outputs(out)) < 12 and time.monotonic() < deadline:
            assert proc.poll() is None, proc.stderr.read().decode()
            time.sleep(0.005)
    proc.send_signal(sig)
    last = _ended(proc, sig)
    words = SIGNAL_NAMES[sig]
    done = _outputs(out)
    assert _leftovers(tmp_path) == []
    assert _recorded(out) == done
    if moment == "outputs":
        assert len(done) >= 12
    batch_line = f"keyfill: error: {words}: {len(done)} of {BATCH_FILES} done; run the same command again to finish"
    assert last in (f"keyfill: error: {words}", batch_line)  # the first: before the batch began
    assert moment == "start-up" or last == batch_line
    if out.exists():
        assert sorted(p.name for p in out.iterdir()) == sorted(done + ([".keyfill-outputs.json"] if done else []))
    rerun = subprocess.run([sys.executable, "-m", "keyfill", *map(str, cmd), "--json"], check=False,
                           capture_output=True, env=_env(), cwd=ROOT, timeout=120)
    assert rerun.returncode == 0, rerun.stderr.decode()
    summary = json.loads(rerun.stdout)
    assert (summary["skipped"], summary["done"], summary["redone"]) == (len(done), BATCH_FILES - len(done), 0)
    assert _recorded(out) == _outputs(out) and len(_outputs(out)) == BATCH_FILES
