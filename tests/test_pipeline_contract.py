"""The pipeline contract of issue 32: batch outputs know how they were made (a re-run redoes what another recipe
made and skips only what the same one made), no command overwrites its input, a bad --scheduler fails fast."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, run

from keyfill import io
from keyfill.io import batch
from keyfill.limits import CONNECT_SECONDS

ROOT = Path(__file__).resolve().parents[1]
LAMP_KEYS = ROOT / "examples" / "lamp" / "keys.usda"
LAMP_CURVES = ROOT / "examples" / "edit" / "lamp_nod_curves.usda"
LAMP_EDIT = ROOT / "examples" / "edit" / "lamp_lift.toml"
MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"


def summary_of(capsys, *args) -> dict:
    code, out, err = run(capsys, *args, "--json")
    assert code == 0, err
    return json.loads(out)


def counts(summary: dict) -> tuple[int, int, int, int]:
    return summary["done"], summary["redone"], summary["skipped"], summary["failed"]


def stamps(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.glob("*.bvh"))}


@pytest.fixture()
def clips(tmp_path):
    src = tmp_path / "clips"
    src.mkdir()
    for name in ("a", "b", "c"):
        shutil.copy(MIXAMO, src / f"{name}.bvh")
    return src


# --- batch outputs know how they were made ------------------------------------------------------------


def test_an_unchanged_rerun_skips_and_changed_options_redo(clips, tmp_path, capsys):
    out = tmp_path / "out"
    base = ("complete", clips, "-o", out, "--key-every", "5")
    assert counts(summary_of(capsys, *base)) == (3, 0, 0, 0)
    before = stamps(out)
    assert counts(summary_of(capsys, *base)) == (0, 0, 3, 0)
    assert stamps(out) == before  # not rewritten
    # the mtime rule of old would skip all of these: the outputs are newer than the inputs
    for extra, option in ((("--key-every", "10"), "key_every"), (("--key-every", "10", "--method", "linear"), "method"),
                          (("--key-every", "10", "--method", "linear", "--seed", "7"), "seed")):
        summary = summary_of(capsys, "complete", clips, "-o", out, *extra)
        assert counts(summary) == (0, 3, 0, 0), option
        assert {tuple(f["stale"]) for f in summary["files"]} == {(f"made with other {option}",)}
    # the last run's files are what --key-every 10 --method linear gives (not the first run's)
    code, _, err = run(capsys, "complete", clips / "a.bvh", "-o", tmp_path / "single.bvh", "--key-every", "10",
                       "--method", "linear")
    assert code == 0, err
    got, want = io.load(out / "a.bvh"), io.load(tmp_path / "single.bvh")
    assert np.abs(got.rotations - want.rotations).max() < 1e-6 and (out / "a.bvh").read_bytes() != before["a.bvh"][0]
    summary = summary_of(capsys, "complete", clips, "-o", out, "--key-every", "10", "--method", "linear", "--seed", "7",
                         "--force")
    assert counts(summary) == (0, 3, 0, 0) and {tuple(f["stale"]) for f in summary["files"]} == {("force",)}
    code, _, err = run(capsys, "complete", clips, "-o", out, "--key-every", "10", "--method", "linear", "--seed", "7")
    assert code == 0 and "skipped 3 made the same way before (--force redoes them)" in err


def test_the_input_content_counts_not_its_time(clips, tmp_path, capsys):
    out = tmp_path / "out"
    base = ("complete", clips, "-o", out, "--key-every", "5")
    summary_of(capsys, *base)
    later = time.time_ns() + 10**9
    os.utime(clips / "a.bvh", ns=(later, later))  # touched, same bytes: still made the same way
    assert counts(summary_of(capsys, *base)) == (0, 0, 3, 0)
    motion = io.load(clips / "b.bvh")
    rot = motion.rotations.copy()
    rot[:, 0] = rot[::-1, 0]
    io.save(motion.replace(rotations=rot), clips / "b.bvh")
    (out / "c.bvh").write_bytes((out / "c.bvh").read_bytes() + b"\n")  # an output changed by someone else
    summary = summary_of(capsys, *base)
    assert counts(summary) == (0, 2, 1, 0)
    stale = {Path(f["input"]).name: f.get("stale") for f in summary["files"]}
    assert stale == {"a.bvh": None, "b.bvh": ["input changed"], "c.bvh": ["output changed since it was written"]}
    assert counts(summary_of(capsys, *base)) == (0, 0, 3, 0)


def test_another_model_redoes_and_a_copy_of_the_same_model_skips(tmp_path, capsys):
    from safetensors.numpy import load_file, save_file

    from keyfill.learn.registry import get

    shipped = get("arnn").default_model()
    for name in ("m1", "m2"):
        shutil.copytree(shipped, tmp_path / name, ignore=shutil.ignore_patterns("*.onnx"))
    src = tmp_path / "hops"
    src.mkdir()
    shutil.copy(LAMP_KEYS, src / "hop.usda")
    out = tmp_path / "out"
    base = ("complete", src, "-o", out, "--method", "arnn", "--runtime", "torch")
    assert counts(summary_of(capsys, *base, "--model", tmp_path / "m1")) == (1, 0, 0, 0)
    first = (out / "hop.usda").read_bytes()
    # the model's identity is its content: the same weights in another folder made the same output
    assert counts(summary_of(capsys, *base, "--model", tmp_path / "m2")) == (0, 0, 1, 0)
    weights = tmp_path / "m2" / "weights.safetensors"
    tensors = load_file(weights)
    name = min(tensors)
    tensors[name] = tensors[name] + np.float32(0.05)
    save_file(tensors, weights)
    summary = summary_of(capsys, *base, "--model", tmp_path / "m2")
    assert counts(summary) == (0, 1, 0, 0) and summary["files"][0]["stale"] == ["made with other model"]
    assert (out / "hop.usda").read_bytes() != first
    # the shipped model (no --model) is a model of its own too
    assert counts(summary_of(capsys, *base))[1] == 1


def test_convert_records_its_outputs_too(clips, tmp_path, capsys):
    out = tmp_path / "usd"
    base = ("convert", clips, "-o", out, "--format", "usda")
    assert counts(summary_of(capsys, *base)) == (3, 0, 0, 0)
    assert counts(summary_of(capsys, *base)) == (0, 0, 3, 0)
    record = json.loads((out / batch.RECORD).read_text())
    assert sorted(record["outputs"]) == ["a.usda", "b.usda", "c.usda"]
    recipe = record["recipes"][record["outputs"]["a.usda"]["recipe"]]
    assert recipe["job"] == "keyfill.io.batch:convert_chunk"
    io.save(io.load(LAMP_KEYS), clips / "a.bvh")
    summary = summary_of(capsys, *base)
    assert counts(summary) == (0, 1, 2, 0) and summary["files"][0]["stale"] == ["input changed"]


def test_a_gltf_input_is_its_json_and_its_buffer(tmp_path, capsys):
    src = tmp_path / "in"
    src.mkdir()
    motion = io.load(MIXAMO)
    io.save(motion, src / "walk.gltf")
    rot = motion.rotations.copy()
    rot[:, 1] = rot[::-1, 1]
    io.save(motion.replace(rotations=rot), tmp_path / "other.gltf")
    assert (src / "walk.bin").is_file() and (tmp_path / "other.bin").stat().st_size == (src / "walk.bin").stat().st_size
    out = tmp_path / "out"
    base = ("convert", src, "-o", out, "--format", "bvh")
    assert counts(summary_of(capsys, *base)) == (1, 0, 0, 0)
    gltf = (src / "walk.gltf").read_bytes()
    shutil.copy(tmp_path / "other.bin", src / "walk.bin")  # the same .gltf, other buffer bytes
    assert (src / "walk.gltf").read_bytes() == gltf
    summary = summary_of(capsys, *base)
    assert counts(summary) == (0, 1, 0, 0) and summary["files"][0]["stale"] == ["input changed"]
    assert np.abs(io.load(out / "walk.bvh").rotations[:, 1] - rot[:, 1]).max() < 1e-4


def test_an_interrupted_run_keeps_the_record_of_what_it_finished(clips, tmp_path):
    from keyfill.learn.batch import CompleteSpec, complete_chunk
    from keyfill.learn.completion import CompleteOptions

    for name in ("d", "e"):
        shutil.copy(MIXAMO, clips / f"{name}.bvh")
    items = batch.plan([clips], tmp_path / "out")
    spec = CompleteSpec("cubic", CompleteOptions(), key_every=5)
    calls = []

    def stop(done):
        calls.append(len(done))
        if len(calls) == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):  # after two chunks of two
        batch.run(items, complete_chunk, spec, workers=1, chunk=2, on_chunk=stop)
    record = json.loads((tmp_path / "out" / batch.RECORD).read_text())
    assert sorted(record["outputs"]) == ["a.bvh", "b.bvh", "c.bvh", "d.bvh"]
    resumed = batch.run(items, complete_chunk, spec, workers=1, chunk=2)
    assert [f["status"] for f in resumed.files] == ["skipped"] * 4 + ["done"]
    # an output that was written but is missing from the record (killed between the two) is redone
    record = json.loads((tmp_path / "out" / batch.RECORD).read_text())
    record["outputs"].pop("b.bvh")
    (tmp_path / "out" / batch.RECORD).write_text(json.dumps(record))
    again = batch.run(items, complete_chunk, spec, workers=1, chunk=2)
    assert [f["status"] for f in again.files] == ["skipped", "redone", "skipped", "skipped", "skipped"]
    assert again.files[1]["stale"] == ["no record of how the output was made"]


@pytest.mark.parametrize("content", [b"{not json", b'{"format": "something-else", "outputs": {}}',
                                     b'{"format": "keyfill-outputs", "version": 99, "recipes": {}, "outputs": {}}',
                                     b'{"format": "keyfill-outputs", "version": 1, "recipes": {}, "outputs": [1]}',
                                     b"\xff\xfe"])
def test_a_damaged_or_foreign_record_is_one_line_naming_it(clips, tmp_path, capsys, content):
    out = tmp_path / "out"
    base = ("complete", clips, "-o", out, "--key-every", "5")
    summary_of(capsys, *base)
    before = stamps(out)
    (out / batch.RECORD).write_bytes(content)
    code, stdout, err = run(capsys, *base)
    assert code == 2 and stdout == ""
    assert err.startswith(f"keyfill: error: {out / batch.RECORD}: ") and len(err.strip().splitlines()) == 1, err
    assert "give --force" in err and "Traceback" not in err
    assert stamps(out) == before and (out / batch.RECORD).read_bytes() == content  # nothing touched
    summary = summary_of(capsys, *base, "--force")  # --force starts a new record
    assert counts(summary) == (0, 3, 0, 0)
    assert counts(summary_of(capsys, *base)) == (0, 0, 3, 0)


# --- never overwrite an input -----------------------------------------------------------------------


def one_error(code: int, err: str) -> str:
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1 and lines[0].startswith("keyfill: error: "), (code, err)
    return lines[0]


@pytest.mark.parametrize("how", ["same", "symlink", "hardlink", "relative"])
def test_complete_and_convert_never_overwrite_their_input(tmp_path, capsys, monkeypatch, how):
    walk = tmp_path / "walk.bvh"
    shutil.copy(MIXAMO, walk)
    original = walk.read_bytes()
    dst = walk
    if how == "symlink":
        dst = tmp_path / "link.bvh"
        dst.symlink_to(walk)
    elif how == "hardlink":
        dst = tmp_path / "hard.bvh"
        os.link(walk, dst)
    elif how == "relative":
        monkeypatch.chdir(tmp_path)
        dst = Path("sub/../walk.bvh")
        (tmp_path / "sub").mkdir()
    for args in (("complete", walk, "--key-every", "3", "-o", dst), ("convert", walk, dst),
                 ("complete", walk, "--key-every", "3", "-o", dst, "--json")):
        code, _, err = run(capsys, *args)
        line = one_error(code, err)
        assert f"-o {dst} is the input {walk}" in line and "--force" in line
        assert walk.read_bytes() == original
    # the input through a link, the output the real file
    if how == "symlink":
        code, _, err = run(capsys, "complete", dst, "--key-every", "3", "-o", walk)
        one_error(code, err)
        assert walk.read_bytes() == original
    # --force says so (the output replaces the name -o gives; a link there is replaced, not written through)
    code, _, err = run(capsys, "complete", walk, "--key-every", "3", "-o", dst, "--force")
    assert code == 0, err
    assert Path(dst).read_bytes() != original


def test_retarget_and_edits_never_overwrite_their_inputs(tmp_path, capsys):
    walk, rig = tmp_path / "walk.bvh", tmp_path / "rig.bvh"
    shutil.copy(MIXAMO, walk)
    shutil.copy(CMU, rig)
    curves, edit = tmp_path / "curves.usda", tmp_path / "edit.toml"
    shutil.copy(LAMP_CURVES, curves)
    shutil.copy(LAMP_EDIT, edit)
    before = {p: p.read_bytes() for p in (walk, rig, curves, edit)}
    for args in (("retarget", walk, "--to", rig, "-o", walk), ("retarget", walk, "--to", rig, "-o", rig),
                 ("edit-tangents", curves, "--edit", edit, "-o", curves),
                 ("pose", curves, "--edit", edit, "--frame", "10", "-o", curves)):
        code, _, err = run(capsys, *args)
        assert "is the input" in one_error(code, err)
    assert {p: p.read_bytes() for p in before} == before


def test_a_batch_never_writes_over_one_of_its_inputs(tmp_path, capsys):
    src = tmp_path / "in"
    src.mkdir()
    for name in ("a", "b"):
        shutil.copy(MIXAMO, src / f"{name}.bvh")
    before = {p.name: p.read_bytes() for p in src.iterdir()}
    # its own input: the output folder is the input's folder, or a link to it
    (tmp_path / "linked").symlink_to(src)
    for outdir in (src, tmp_path / "linked"):
        code, _, err = run(capsys, "complete", src / "a.bvh", src / "b.bvh", "-o", outdir, "--key-every", "5")
        line = one_error(code, err)
        assert "the output of" in line and "would overwrite that input" in line and "--force" in line
    # another input's file: out/a.bvh is a hard link of in/b.bvh
    (tmp_path / "out").mkdir()
    os.link(src / "b.bvh", tmp_path / "out" / "a.bvh")
    code, _, err = run(capsys, "complete", src / "a.bvh", src / "b.bvh", "-o", tmp_path / "out", "--key-every", "5")
    assert f"the output of {src / 'a.bvh'} is the input {src / 'b.bvh'}" in one_error(code, err)
    assert {p.name: p.read_bytes() for p in src.iterdir()} == before
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["a.bvh"]
    code, _, err = run(capsys, "complete", src / "a.bvh", src / "b.bvh", "-o", src, "--key-every", "5", "--force")
    assert code == 0, err
    assert (src / "a.bvh").read_bytes() != before["a.bvh"]


# --- a bad --scheduler fails fast -------------------------------------------------------------------


@pytest.mark.parametrize("command", ["complete", "simulate"])
@pytest.mark.parametrize("address,timeout,bound", [("tcp://127.0.0.1:9", "2", 2.0), ("localhost", "2", 2.0),
                                                   ("tcp://127.0.0.1:9", None, CONNECT_SECONDS)])
def test_a_bad_scheduler_is_one_line_within_the_timeout(tmp_path, command, address, timeout, bound):
    pytest.importorskip("distributed")
    if command == "simulate":
        pytest.importorskip("pybullet")
        cmd = [sys.executable, "-m", "keyfill", "simulate", "-o", str(tmp_path / "out"), "--count", "1"]
    else:
        cmd = [sys.executable, "-m", "keyfill", "complete", str(LAMP_KEYS), str(MIXAMO), "-o", str(tmp_path / "out"),
               "--key-every", "5"]
    cmd += ["--scheduler", address]
    if timeout is not None:
        cmd += ["--connect-timeout", timeout]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    t0 = time.monotonic()
    proc = subprocess.run(cmd, check=False, env=env, capture_output=True, text=True, timeout=60)
    seconds = time.monotonic() - t0
    lines = proc.stderr.splitlines()
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("keyfill: error: ") and "--scheduler" in lines[0]
    assert "Exception ignored" not in proc.stderr and "Traceback" not in proc.stderr
    # the timeout, plus the start of a Python process (a few seconds on a loaded machine)
    assert seconds < bound + 4.0, seconds
    assert not (tmp_path / "out").exists()


def test_the_connect_timeout_default_is_a_few_seconds_and_one_value(capsys):
    """--connect-timeout defaults to limits.CONNECT_SECONDS in every command and library entry point."""
    import inspect

    from keyfill import parallel
    from keyfill.sim import runner

    assert 1.0 <= CONNECT_SECONDS <= 5.0
    for fn in (parallel.executor, parallel.check_options, batch.run, runner.simulate, runner.check_arguments):
        assert inspect.signature(fn).parameters["connect_timeout"].default == CONNECT_SECONDS, fn
    for command in ("complete", "convert", "retarget", "simulate"):
        code, out, _ = run(capsys, command, "--help")
        assert code == 0 and f"[default: {CONNECT_SECONDS}]" in " ".join(out.split()), command
