"""The one training loop: data-parallel training with torchrun, checkpoints of the right kind, the registry."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch
from safetensors.torch import load_file
from synthetic_corpus import write_corpus

from keyfill.cli.main import main
from keyfill.learn import registry
from keyfill.learn.modelfile import CONFIG, WEIGHTS

pytestmark = pytest.mark.usefixtures("one_torch_thread")

#: a tiny transformer without dropout: the only per-process randomness of data-parallel training
TINY = {"model": {"layers": 1, "d_model": 16, "heads": 2, "ffn": 32, "dropout": 0.0, "max_frames": 65},
        "training": {"epochs": 2, "batch_size": 8, "lr": 2e-3, "warmup_epochs": 0.2, "decay_every": 1,
                     "window": 65, "window_offset": 20, "val_fraction": 0.25, "val_lengths": [5]}}


@pytest.fixture(scope="module")
def corpus_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("walkers")
    write_corpus(folder, styles=("happy", "tired"), clips_per_style=2, frames=(100, 130), seed=5)
    return folder


@pytest.fixture(scope="module")
def config(tmp_path_factory):
    path = tmp_path_factory.mktemp("config") / "tiny.json"
    path.write_text(json.dumps(TINY))
    return path


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))


def _train(corpus_dir, config, out, *extra):
    out.parent.mkdir(exist_ok=True)
    assert main(["-q", "train", "transformer", str(corpus_dir), "-o", str(out), "--config", str(config),
                 "--threads", "1", *extra]) == 0


def _torchrun(corpus_dir, config, out, nproc, *extra):
    out.parent.mkdir(exist_ok=True)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", f"--nproc-per-node={nproc}",
           "-m", "keyfill", "-q", "train", "transformer", str(corpus_dir), "-o", str(out), "--config", str(config),
           "--threads", "1", *extra]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return done


def _weights(folder):
    return load_file(str(folder / WEIGHTS))


def _assert_close(a, b):
    assert a.keys() == b.keys()
    for k in a:
        assert torch.allclose(a[k], b[k], rtol=1e-4, atol=1e-5), (k, (a[k] - b[k]).abs().max())


def test_two_processes_train_the_model_one_process_trains(corpus_dir, config, tmp_path):
    """torchrun with 2 gloo processes, each on half of every batch, gives the 1-process model; rank 0 alone writes."""
    _train(corpus_dir, config, tmp_path / "one" / "m")
    _torchrun(corpus_dir, config, tmp_path / "two" / "m", 2)
    one, two = _weights(tmp_path / "one" / "m"), _weights(tmp_path / "two" / "m")
    _assert_close(one, two)
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == ["m", "m.checkpoint.pt", "m.log.jsonl"]
    rows = [json.loads(line) for line in (tmp_path / "two" / "m.log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows] == [1, 2]  # one writer: no row twice
    rows_one = [json.loads(line) for line in (tmp_path / "one" / "m.log.jsonl").read_text().splitlines()]
    assert rows[-1]["loss_total"] == pytest.approx(rows_one[-1]["loss_total"], rel=1e-4)
    assert rows[-1]["val_L2P_5"] == pytest.approx(rows_one[-1]["val_L2P_5"], rel=1e-3)


def test_resume_across_process_counts(corpus_dir, config, tmp_path):
    """One epoch on 2 processes, resumed to two on 1 process: the 2-epoch 1-process model."""
    _train(corpus_dir, config, tmp_path / "whole")
    _torchrun(corpus_dir, config, tmp_path / "m", 2, "--epochs", "1")
    _train(corpus_dir, config, tmp_path / "m", "--resume")
    _assert_close(_weights(tmp_path / "whole"), _weights(tmp_path / "m"))


def test_a_checkpoint_of_another_kind_or_configuration_is_refused(corpus_dir, config, tmp_path, capsys):
    from keyfill.learn.arnn.model import DEFAULT_MODEL

    _train(corpus_dir, config, tmp_path / "m", "--epochs", "1")
    before = (tmp_path / "m.log.jsonl").read_bytes()
    # another configuration: one line naming the difference, nothing written
    assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "m"), "--config", str(config),
                 "--resume", "--seed", "3"]) == 2
    assert capsys.readouterr().err.strip().endswith("was made with other settings (--seed 0, now 3); "
                                                   "give the same options to resume")
    other = tmp_path / "other.json"
    other.write_text(json.dumps({**TINY, "training": {**TINY["training"], "lr": 1e-3}}))
    assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "m"), "--config", str(other),
                 "--resume"]) == 2
    assert "(training.lr=0.002, now 0.001)" in capsys.readouterr().err
    # another kind: a lamp ARNN checkpoint given to the transformer
    arnn_ckpt = tmp_path / "arnn.checkpoint.pt"
    from keyfill.learn.checkpoints import CHECKPOINT_FORMAT

    torch.save({"format": CHECKPOINT_FORMAT, "kind": "arnn"}, arnn_ckpt)
    assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "m"), "--config", str(config),
                 "--resume", "--checkpoint", str(arnn_ckpt)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"keyfill: error: --resume: {arnn_ckpt} is a checkpoint of a 'arnn' model, not 'transformer'"
    assert (tmp_path / "m.log.jsonl").read_bytes() == before
    assert DEFAULT_MODEL.is_dir()


def test_a_model_folder_of_an_unknown_kind_lists_the_known_kinds(tmp_path, capsys):
    folder = tmp_path / "alien"
    folder.mkdir()
    (folder / CONFIG).write_text(json.dumps({"format": "keyfill-model", "version": 1, "kind": "diffusion",
                                             "skeleton": {"names": ["a"], "parents": [-1], "offsets": [[0, 0, 0]]}}))
    (folder / WEIGHTS).write_bytes(b"")
    clip = tmp_path / "c.bvh"
    from synthetic_corpus import walker_motion, walker_skeleton

    from keyfill import io

    io.save(walker_motion(walker_skeleton(), 20, np.random.default_rng(0)), clip)
    for args in (["evaluate", str(folder), str(tmp_path)],
                 ["complete", str(clip), "-o", str(tmp_path / "o.bvh"), "--keys", "0,19", "--method", "transformer", "--model",
                  str(folder)]):
        assert main(args) == 1
        err = capsys.readouterr().err.strip()
        known = ", ".join(m.name for m in registry.learned())
        assert err == (f"keyfill: error: {folder}: a model of kind 'diffusion', which no method of this keyfill "
                       f"knows (known kinds: {known})")
    assert not (tmp_path / "o.bvh").exists()


def test_every_trainable_method_is_a_train_subcommand_and_a_complete_method(capsys):
    assert main(["train", "--help"]) == 0
    out = capsys.readouterr().out
    for m in registry.trainable():
        assert m.name in out and m.name in registry.METHODS
        spec = m.training_spec()
        assert spec.help and callable(spec.make_task)
    assert main(["complete", "--help"]) == 0
    out = capsys.readouterr().out
    assert all(m.name in out for m in registry.METHODS.values())
