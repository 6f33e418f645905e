"""Batch completion and conversion: many files in, one folder out; resuming, bad inputs, workers, Dask."""

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA

from keyfill import io
from keyfill.cli.main import main
from keyfill.io import batch
from keyfill.learn.batch import CompleteSpec, complete_chunk
from keyfill.learn.completion import CompleteOptions

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
LAMP_KEYS = EXAMPLES / "lamp" / "keys.usda"
MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def lamp_folder(folder: Path, count: int) -> Path:
    """``count`` lamp key files: the example's keys with the base moved and the keys thinned a little."""
    from keyfill.motion import Keys

    motion = io.load(LAMP_KEYS)
    (folder / "sub").mkdir(parents=True)
    for i in range(count):
        pos = motion.positions.copy()
        pos[:, 0, 0] += 0.1 * i
        keys = motion.keys.frames if i % 2 == 0 else np.delete(motion.keys.frames, [3])
        m = motion.replace(positions=pos, keys=Keys(keys))
        io.save(m, folder / ("sub" if i % 3 == 0 else ".") / f"hop_{i:02d}.usda", sparse=True)
    return folder


def outputs(folder: Path) -> dict[str, bytes]:
    """The motion files in ``folder`` (not its record of how they were made)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != batch.RECORD}


@pytest.fixture(scope="module")
def lamps(tmp_path_factory):
    return lamp_folder(tmp_path_factory.mktemp("lamps") / "in", 7)


def test_cubic_batch_writes_what_single_calls_write(tmp_path, capsys):
    src = tmp_path / "in"
    (src / "a").mkdir(parents=True)
    shutil.copy(MIXAMO, src / "a" / "walk.bvh")
    shutil.copy(LAMP_KEYS, src / "hop.usda")
    code, out, err = run(capsys, "complete", src, "-o", tmp_path / "out", "--key-every", "2", "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert (summary["inputs"], summary["done"], summary["skipped"], summary["failed"]) == (2, 2, 0, 0)
    assert sorted(outputs(tmp_path / "out")) == ["a/walk.bvh", "hop.usda"]
    for rel in ("a/walk.bvh", "hop.usda"):
        code, _, err = run(capsys, "complete", src / rel, "-o", tmp_path / Path(rel).name, "--key-every", "2")
        assert code == 0, err
        assert (tmp_path / "out" / rel).read_bytes() == (tmp_path / Path(rel).name).read_bytes()


def test_format_sets_the_suffix_and_globs_keep_relative_names(tmp_path, capsys):
    src = tmp_path / "in"
    (src / "deep").mkdir(parents=True)
    shutil.copy(MIXAMO, src / "deep" / "walk.bvh")
    shutil.copy(MIXAMO, src / "run.bvh")
    code, _out, err = run(capsys, "complete", f"{src}/**/*.bvh", "-o", tmp_path / "out/", "--key-every", "5",
                         "--format", "usda")
    assert code == 0, err
    assert sorted(outputs(tmp_path / "out")) == ["deep/walk.usda", "run.usda"]
    assert "completed 2 of 2 files" in err


def test_arnn_batch_matches_single_calls_and_any_worker_count(lamps, tmp_path, capsys):
    code, out, err = run(capsys, "complete", lamps, "-o", tmp_path / "one/", "--method", "arnn", "--batch-size", "3",
                         "--workers", "1", "--json")
    assert code == 0, err
    files = json.loads(out)["files"]
    assert [f["status"] for f in files] == ["done"] * 7 and all(f["arch"] == "arnn" for f in files)
    code, out, err = run(capsys, "complete", lamps, "-o", tmp_path / "two/", "--method", "arnn", "--batch-size", "3",
                         "--workers", "2")
    assert code == 0, err
    assert outputs(tmp_path / "one") == outputs(tmp_path / "two")
    # a file completed in a batch equals its single completion to float32 rounding; keys are exact
    rel = "sub/hop_03.usda"
    code, _, err = run(capsys, "complete", lamps / rel, "-o", tmp_path / "single.usda", "--method", "arnn")
    assert code == 0, err
    a, b = io.load(tmp_path / "one" / rel), io.load(tmp_path / "single.usda")
    assert np.abs(a.positions - b.positions).max() < 1e-5
    assert np.abs(a.rotations - b.rotations).max() < 1e-5
    k = io.load(lamps / rel).keys.frames
    assert np.array_equal(a.rotations[k], io.load(lamps / rel).rotations[k])


def test_interrupted_batch_resumes_to_the_same_bytes(lamps, tmp_path, capsys):
    code, _, err = run(capsys, "complete", lamps, "-o", tmp_path / "whole/", "--method", "arnn", "--batch-size", "3")
    assert code == 0, err
    items = batch.plan([lamps], tmp_path / "part")
    spec = CompleteSpec("arnn", CompleteOptions())
    for it in items:
        Path(it.dst).parent.mkdir(parents=True, exist_ok=True)

    def stop(done):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):  # stopped after the first chunk of 3
        batch.run(items, complete_chunk, spec, workers=1, chunk=3, on_chunk=stop)
    assert len(outputs(tmp_path / "part")) == 3
    assert [p.name for p in (tmp_path / "part").rglob(".*")] == [batch.RECORD]  # no temporary files left
    os.remove(tmp_path / "part" / "hop_01.usda")  # one of the first chunk lost too: recomputed in its batch
    code, out, err = run(capsys, "complete", lamps, "-o", tmp_path / "part/", "--method", "arnn", "--batch-size", "3",
                         "--json")
    assert code == 0, err
    summary = json.loads(out)
    assert (summary["done"], summary["skipped"]) == (5, 2)
    assert outputs(tmp_path / "part") == outputs(tmp_path / "whole")
    code, out, err = run(capsys, "complete", lamps, "-o", tmp_path / "part/", "--method", "arnn")
    assert code == 0 and "skipped 7 made the same way before (--force redoes them)" in err
    code, out, err = run(capsys, "complete", lamps, "-o", tmp_path / "part/", "--method", "arnn", "--force", "--json")
    assert code == 0 and json.loads(out)["redone"] == 7


def test_a_bad_input_is_reported_and_the_others_go_on(lamps, tmp_path, capsys):
    src = tmp_path / "in"
    shutil.copytree(lamps, src)
    (src / "broken.bvh").write_text("HIERARCHY\nROOT a\n{\n")
    shutil.copy(MIXAMO, src / "human.bvh")
    code, out, err = run(capsys, "complete", src, "-o", tmp_path / "out", "--method", "arnn", "--json")
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 2 and all(line.startswith("keyfill: error: ") for line in lines), err
    assert f"{src / 'broken.bvh'}:" in lines[0] and f"{src / 'human.bvh'}: this file records no keys" in lines[1]
    summary = json.loads(out)
    status = {Path(f["input"]).name: f["status"] for f in summary["files"]}
    assert status.pop("broken.bvh") == "failed" and status.pop("human.bvh") == "failed"
    assert set(status.values()) == {"done"} and len(status) == 7
    written = outputs(tmp_path / "out")
    assert len(written) == 7 and not any(k.endswith(".bvh") for k in written)


def test_an_output_folder_that_is_a_file_is_refused(lamps, tmp_path, capsys):
    (tmp_path / "out").write_text("a file")
    code, _out, err = run(capsys, "complete", lamps, "-o", tmp_path / "out", "--method", "arnn")
    assert code == 2 and err.startswith("keyfill: error: -o ") and "is a file" in err
    assert (tmp_path / "out").read_text() == "a file"


def test_two_inputs_for_one_output_are_refused_before_any_work(tmp_path, capsys):
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        shutil.copy(LAMP_KEYS, tmp_path / d / "keys.usda")
    shutil.copy(LAMP_KEYS, tmp_path / "c.usda")
    code, _out, err = run(capsys, "complete", tmp_path / "c.usda", tmp_path / "a" / "keys.usda",
                         tmp_path / "b" / "keys.usda", "-o", tmp_path / "out")
    assert code == 2 and "would both be written to" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_dask_cluster_gives_the_bytes_of_a_local_run(lamps, tmp_path):
    distributed = pytest.importorskip("distributed")
    spec = CompleteSpec("arnn", CompleteOptions())
    local = batch.run(batch.plan([lamps], tmp_path / "local"), complete_chunk, spec, workers=1, chunk=3)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        remote = batch.run(batch.plan([lamps], tmp_path / "dask"), complete_chunk, spec, chunk=3,
                           scheduler=cluster.scheduler_address)
    assert [f["status"] for f in remote.files] == ["done"] * 7 == [f["status"] for f in local.files]
    assert outputs(tmp_path / "dask") == outputs(tmp_path / "local")


def test_convert_many_files_into_a_folder(tmp_path, capsys):
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(MIXAMO, src / "walk.bvh")
    shutil.copy(LAMP_KEYS, src / "hop.usda")
    code, out, err = run(capsys, "convert", src / "walk.bvh", src / "hop.usda", "-o", tmp_path / "out", "--format", "usda",
                         "--json")
    assert code == 0, err
    assert json.loads(out)["done"] == 2
    code, _, err = run(capsys, "convert", src / "walk.bvh", tmp_path / "walk.usda")
    assert code == 0
    assert (tmp_path / "out" / "walk.usda").read_bytes() == (tmp_path / "walk.usda").read_bytes()
    code, out, err = run(capsys, "convert", src / "walk.bvh", "-o", tmp_path / "out", "--format", "usda")
    assert code == 0 and "skipped 1" in err


def test_a_batch_runs_torch_on_one_thread_and_restores_it(lamps, tmp_path, monkeypatch):
    import torch

    from keyfill.learn import registry

    seen = []
    real = registry.complete_many
    monkeypatch.setattr(registry, "complete_many", lambda *a: seen.append(torch.get_num_threads()) or real(*a))
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        summary = batch.run(batch.plan([lamps], tmp_path / "o"), complete_chunk,
                            CompleteSpec("arnn", CompleteOptions(runtime="torch")), workers=1)
        assert [f["status"] for f in summary.files] == ["done"] * 7
        assert seen == [1] and torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)


def test_transformer_batch_sends_windows_of_one_layout_together(tmp_path, capsys, monkeypatch):
    import torch
    from synthetic_corpus import walker_motion, walker_skeleton

    from keyfill.learn.transformer import config as TC
    from keyfill.learn.transformer import model as T

    skeleton = walker_skeleton(static_root=False)
    with torch.random.fork_rng():
        torch.manual_seed(0)
        model = T.new_model(skeleton, TC.ModelConfig(layers=2, d_model=32, heads=4, ffn=64, dropout=0.0),
                            np.zeros(21), np.full(21, 30.0), folded=False)
        with torch.no_grad():
            for p in model.network.parameters():
                p.add_(0.05 * torch.randn(p.shape))
    model.save(tmp_path / "model")
    (tmp_path / "in").mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        io.save(walker_motion(skeleton, 50, rng), tmp_path / "in" / f"walk{i}.bvh")
    calls = []
    real = T.CompletionModel.complete_windows
    monkeypatch.setattr(T.CompletionModel, "complete_windows",
                        lambda self, q, r, k, **kw: calls.append(len(q)) or real(self, q, r, k, **kw))
    args = ("--method", "transformer", "--model", tmp_path / "model", "--key-every", "10", "--runtime", "torch")
    code, _out, err = run(capsys, "complete", tmp_path / "in", "-o", tmp_path / "out", "--workers", "1", *args)
    assert code == 0, err
    assert calls == [3]  # one window per clip, one layout: one call
    for i in range(3):
        code, _, err = run(capsys, "complete", tmp_path / "in" / f"walk{i}.bvh", "-o", tmp_path / f"single{i}.bvh",
                           *args)
        assert code == 0, err
        a, b = io.load(tmp_path / "out" / f"walk{i}.bvh"), io.load(tmp_path / f"single{i}.bvh")
        assert np.abs(a.positions - b.positions).max() < 1e-4 * np.abs(b.positions).max()


def test_an_unreachable_scheduler_is_one_error_and_writes_nothing(tmp_path, capsys):
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"
    code, _out, err = run(capsys, "complete", LAMP_KEYS, MIXAMO, "-o", tmp_path / "out", "--key-every", "5",
                         "--scheduler", address, "--connect-timeout", "1")
    assert code == 2 and err.startswith(f"keyfill: error: cannot reach the --scheduler {address} within "
                                        "--connect-timeout 1 s")
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "out").exists()


def test_a_killed_batch_resumes_and_its_leftovers_go(tmp_path, capsys):
    import signal
    import subprocess
    import sys
    import time

    src = tmp_path / "in"
    src.mkdir()
    for i in range(40):
        shutil.copy(MIXAMO, src / f"walk{i:02d}.bvh")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "keyfill", "complete", str(src), "-o", str(out), "--key-every", "3",
           "--batch-size", "1", "--workers", "1", "--format", "usda"]
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    def finished():
        return [p for p in out.glob("*.usda") if not p.name.startswith(".")] if out.is_dir() else []

    while time.monotonic() < deadline and len(finished()) < 3:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done_before = len(finished())
    assert 3 <= done_before < 40, done_before
    (out / ".walk39.abc123.part.usda").write_text("half a file")  # what a kill during a write leaves
    code, stdout, err = run(capsys, "complete", src, "-o", out, "--key-every", "3", "--format", "usda", "--json")
    assert code == 0, err
    summary = json.loads(stdout)
    # an output written but not yet in the record when the kill came is redone, never taken as made
    assert summary["skipped"] + summary["redone"] >= done_before
    assert summary["done"] + summary["redone"] + summary["skipped"] == 40
    assert sorted(p.name for p in out.iterdir()) == [".keyfill-outputs.json"] + [f"walk{i:02d}.usda" for i in range(40)]
