"""Records that tell the truth (issue 48): a batch record covers every file of an output (a ``.gltf`` and its
``.bin``), two batches into one folder take turns, and a read-only output is replaced only with --force."""

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
from conftest import DATA, one_error_line, run

from keyfill import io
from keyfill.io import batch

ROOT = Path(__file__).resolve().parents[1]
MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"


def summary_of(capsys, *args) -> dict:
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    return json.loads(out)


def statuses(summary: dict) -> dict[str, str]:
    return {Path(f["output"]).name: f["status"] for f in summary["files"]}


@pytest.fixture()
def walks(tmp_path) -> Path:
    """Two motions of one skeleton whose glTF buffers have the same size and other bytes."""
    src = tmp_path / "in"
    src.mkdir()
    motion = io.load(MIXAMO)
    io.save(motion, src / "a.bvh")
    rot = motion.rotations.copy()
    rot[:, 1] = rot[::-1, 1]
    io.save(motion.replace(rotations=rot), src / "b.bvh")
    return src


def test_a_gltf_output_is_its_json_and_its_bin(walks, tmp_path, capsys):
    out = tmp_path / "out"
    base = ("convert", walks, "-o", out, "--format", "gltf")
    assert statuses(summary_of(capsys, *base)) == {"a.gltf": "done", "b.gltf": "done"}
    entry = json.loads((out / batch.RECORD).read_text())["outputs"]["a.gltf"]
    assert sorted(entry["files"]) == ["a.bin"]
    assert (out / "a.bin").stat().st_size == (out / "b.bin").stat().st_size
    assert statuses(summary_of(capsys, *base)) == {"a.gltf": "skipped", "b.gltf": "skipped"}

    # swapped: each .gltf now names the other's buffer bytes (moved, so each keeps its modification time)
    os.replace(out / "a.bin", tmp_path / "x.bin")
    os.replace(out / "b.bin", out / "a.bin")
    os.replace(tmp_path / "x.bin", out / "b.bin")
    summary = summary_of(capsys, *base)
    assert statuses(summary) == {"a.gltf": "redone", "b.gltf": "redone"}
    assert summary["files"][0]["stale"] == ["output changed since it was written"]
    for name in ("a", "b"):  # each output reads back as its own input again
        assert abs(io.load(out / f"{name}.gltf").rotations - io.load(walks / f"{name}.bvh").rotations).max() < 1e-5

    # truncated
    with open(out / "b.bin", "r+b") as f:
        f.truncate(100)
    assert statuses(summary_of(capsys, *base)) == {"a.gltf": "skipped", "b.gltf": "redone"}
    assert io.load(out / "b.gltf").num_frames == io.load(walks / "b.bvh").num_frames

    # missing
    os.remove(out / "a.bin")
    assert statuses(summary_of(capsys, *base)) == {"a.gltf": "redone", "b.gltf": "skipped"}
    assert sorted(p.name for p in out.iterdir()) == [batch.RECORD, "a.bin", "a.gltf", "b.bin", "b.gltf"]


def test_a_read_only_output_is_refused_unless_force(walks, tmp_path, capsys):
    # one file
    out = tmp_path / "a.usda"
    assert run(capsys, "convert", walks / "a.bvh", out)[0] == 0
    out.chmod(0o444)
    before = out.read_bytes()
    for args in (("convert", walks / "b.bvh", out), ("complete", walks / "b.bvh", "--key-every", "5", "-o", out)):
        code, _, err = run(capsys, *args)
        assert code == 1
        assert one_error_line(err) == (f"keyfill: error: {out}: cannot write the output (a read-only file; give "
                                       "--force to replace it)")
        assert out.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == ["a.usda", "in"]
    assert run(capsys, "convert", walks / "b.bvh", out, "--force")[0] == 0
    assert out.read_bytes() != before
    # the .bin of a .gltf
    gltf = tmp_path / "g.gltf"
    assert run(capsys, "convert", walks / "a.bvh", gltf)[0] == 0
    (tmp_path / "g.bin").chmod(0o444)
    code, _, err = run(capsys, "convert", walks / "b.bvh", gltf)
    assert code == 1 and one_error_line(err).endswith("g.bin: cannot write the output (a read-only file; give "
                                                      "--force to replace it)")

    # a batch: the read-only output that must be redone fails on its own line, the others go on
    folder = tmp_path / "out"
    assert run(capsys, "convert", walks, "-o", folder, "--format", "usda")[0] == 0
    (folder / "a.usda").chmod(0o444)
    assert statuses(summary_of(capsys, "convert", walks, "-o", folder, "--format", "usda")) == {
        "a.usda": "skipped", "b.usda": "skipped"}  # up to date: nothing to write, nothing refused
    code, out_json, err = run(capsys, "convert", walks, "-o", folder, "--format", "usda", "--force", "--json")
    assert code == 0 and statuses(json.loads(out_json)) == {"a.usda": "redone", "b.usda": "redone"}
    (folder / "a.usda").chmod(0o444)
    kept = (folder / "a.usda").read_bytes()
    (folder / "b.usda").write_text("changed by hand")
    shutil.copy(walks / "b.bvh", walks / "a.bvh")  # a's input changed: its output must be redone
    code, _, err = run(capsys, "convert", walks, "-o", folder, "--format", "usda")
    assert code == 1
    line = (f"keyfill: error: {walks / 'a.bvh'}: {folder / 'a.usda'}: cannot write the output (a read-only file; "
            "give --force to replace it)")
    assert [e for e in err.splitlines() if e.startswith("keyfill: error:")] == [line]
    assert (folder / "a.usda").read_bytes() == kept and (folder / "b.usda").read_text() != "changed by hand"


def _keyfill(*args) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen([sys.executable, "-m", "keyfill", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env, cwd=ROOT)


def test_two_batches_into_one_folder_take_turns(tmp_path, capsys):
    """The second waits for the first (a note says so), then redoes what the first made with other options:
    every output and its record entry are of the second's recipe."""
    src = tmp_path / "in"
    src.mkdir()
    for i in range(60):
        shutil.copy(MIXAMO, src / f"c{i:02d}.bvh")
    out = tmp_path / "out"
    first = _keyfill("complete", src, "-o", f"{out}/", "--key-every", "5", "--workers", "1", "--batch-size", "4")
    deadline = time.monotonic() + 60
    while not list(out.glob("c*.bvh")) and time.monotonic() < deadline:
        assert first.poll() is None, first.stderr.read().decode()
        time.sleep(0.01)
    second = _keyfill("complete", src, "-o", f"{out}/", "--key-every", "7", "--workers", "1", "--json")
    _, err1 = first.communicate(timeout=300)
    out2, err2 = second.communicate(timeout=300)
    assert first.returncode == 0, err1.decode()
    assert second.returncode == 0, err2.decode()
    assert "another keyfill run is writing into this folder; waiting for it to end" in err2.decode()
    summary = json.loads(out2)
    assert summary["redone"] == 60 and all("made with other key_every" in f["stale"] for f in summary["files"])
    record = json.loads((out / batch.RECORD).read_text())
    assert {record["recipes"][e["recipe"]]["key_every"] for e in record["outputs"].values()} == {7}
    alone = tmp_path / "alone.bvh"
    assert run(capsys, "complete", src / "c00.bvh", "--key-every", "7", "-o", alone)[0] == 0
    assert all((out / f"c{i:02d}.bvh").read_bytes() == alone.read_bytes() for i in range(60))
    assert sorted(p.name for p in out.iterdir()) == sorted([batch.RECORD] + [f"c{i:02d}.bvh" for i in range(60)])


def test_a_run_waiting_for_the_folder_can_be_interrupted(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    with batch.folder_lock(out):
        proc = _keyfill("convert", CMU, "-o", f"{out}/", "--format", "usda")
        deadline = time.monotonic() + 60
        line = b""
        while b"waiting" not in line and time.monotonic() < deadline:
            line = proc.stderr.readline()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert err.decode().strip().splitlines()[-1] == ("keyfill: error: interrupted: 0 of 1 done; run the same command "
                                                     "again to finish")
    assert list(out.iterdir()) == []
