"""The training task of both stages in keyfill's one training loop: a few steps reduce the losses; batches,
state, resume and config behave."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import built, fit, synthetic_corpus, tiny_config

from keyfill.errors import ModelError, UsageError
from keyfill.learn import registry
from keyfill.learn.gan.task import GanTask
from keyfill.learn.gan.train_command import read_config
from keyfill.learn.modelfile import read_config as read_model_config

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def no_update(name, loss):
    """Score a batch without changing any weight."""


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return synthetic_corpus(tmp_path_factory.mktemp("gan_corpus") / "clips", clips_per_style=3)


@pytest.fixture(scope="module")
def path_model(corpus, tmp_path_factory):
    """A path predictor trained for a few steps, saved as a stage-"path" gan model."""
    task = GanTask(corpus, tiny_config(), "path", epochs=6)
    return fit(task, tmp_path_factory.mktemp("gan_path") / "path-model").model


def test_path_stage_reduces_eq5(corpus, tmp_path):
    task = GanTask(corpus, tiny_config(), "path", epochs=6)
    built(task)
    fixed = task.path_batch(np.random.default_rng(123))
    before = task.step(fixed, no_update)[0]["path"]
    out = fit(task, tmp_path / "m")
    task.nets["path"].train()
    after = task.step(fixed, no_update)[0]["path"]
    assert after < 0.7 * before
    assert len(out.history) == 6 and out.history[-1]["path_loss"] > 0
    assert read_model_config(out.model, kind="gan")["stage"] == "path"


def test_generator_stage_reduces_its_losses(corpus, path_model, tmp_path):
    task = GanTask(corpus, tiny_config(), "generator", path_model=path_model, epochs=3)
    nets = built(task, seed=1)
    assert set(nets) == {"generator", "discriminator"}
    fixed = task.generator_batch(np.random.default_rng(321), task.train_pool)
    before = task.step(fixed, no_update)[0]
    task.step_count = 0  # scoring counted as a step
    frozen = {k: v.clone() for k, v in task.path_net.state_dict().items()}
    out = fit(task, tmp_path / "full", seed=1)
    for net in task.nets.values():
        net.train()
    after = task.step(fixed, no_update)[0]
    assert after["key_joint"] < 0.7 * before["key_joint"]
    assert after["key_root"] < 0.7 * before["key_root"]
    assert after["generator"] < 0.7 * before["generator"]
    assert after["d_adv"] < before["d_adv"]
    assert all(np.isfinite(v) for row in out.history for v in row.values() if isinstance(v, float))
    # the path predictor stayed frozen
    assert all(torch.equal(frozen[k], v) for k, v in task.path_net.state_dict().items())
    row = out.history[-1]
    assert row["key_joint_error"] >= 0 and row["key_root_error"] >= 0 and "lr_generator" in row
    assert row["root_weight"] == 10 and "loss_root_weight" not in row and row["loss_key_joint"] > 0
    cfg = read_model_config(out.model, kind="gan")
    assert cfg["stage"] == "full" and cfg["ranges"]["driven"] and cfg["training"]["steps"] == 12


def test_resume_gives_the_same_model(corpus, path_model, tmp_path):
    straight = fit(GanTask(corpus, tiny_config(steps_per_epoch=2), "generator", path_model=path_model, epochs=2),
                   tmp_path / "straight", seed=3)
    ck = tmp_path / "half.checkpoint.pt"
    fit(GanTask(corpus, tiny_config(steps_per_epoch=2), "generator", path_model=path_model, epochs=1),
        tmp_path / "half", seed=3, checkpoint=ck)
    resumed = GanTask(corpus, tiny_config(steps_per_epoch=2), "generator", path_model=path_model, epochs=2)
    fit(resumed, tmp_path / "resumed", seed=3, checkpoint=ck, resume=True)
    assert resumed.step_count == 4
    a = (straight.model / "weights.safetensors").read_bytes()
    assert a == (tmp_path / "resumed" / "weights.safetensors").read_bytes()
    with pytest.raises(UsageError, match="other settings"):
        other = GanTask(corpus, tiny_config(steps_per_epoch=2, max_gap=100), "generator", path_model=path_model,
                        epochs=2)
        fit(other, tmp_path / "other", seed=3, checkpoint=ck, resume=True)


def test_batches_are_seeded_sharded_and_stateful(corpus, path_model):
    task = GanTask(corpus, tiny_config(), "generator", path_model=path_model)
    a, b = next(iter(task.batches(4))), next(iter(task.batches(4)))
    assert a.arrays.keys() == b.arrays.keys()
    assert all(np.array_equal(a.arrays[k], b.arrays[k]) for k in a.arrays)
    c = next(iter(task.batches(5)))
    assert not np.array_equal(a.arrays["dense"], c.arrays["dense"])
    N = task.cfg.sequence_frames
    for dense, mask in zip(a.arrays["dense"], a.arrays["key_mask"]):
        keys = np.flatnonzero(mask)
        assert keys[0] == 0 and N - 64 <= keys[-1] <= N - 1
        half = dense.shape[0] // 2  # pose channels, then the distance mask
        assert np.allclose(dense[:half, keys[-1] :], dense[:half, [keys[-1]]])  # the tail holds the last key
        assert np.allclose(dense[half, keys[-1] :], np.arange(N - keys[-1]) / task.cfg.mask_scale)
    halves = [task.shard(a, r, 2) for r in range(2)]
    assert sum(len(h) for h in halves) == len(a) == 2
    assert np.array_equal(halves[1].arrays["real"], a.arrays["real"][1::2])
    task.step_count = 2345
    other = GanTask(corpus, tiny_config(), "generator", path_model=path_model)
    other.load_state_dict(json.loads(json.dumps(task.state_dict())))
    assert other.step_count == 2345
    assert task.cfg.root_weight(0, 8000) == 10 and task.cfg.root_weight(2345, 8000) == 12
    assert task.cfg.root_weight(10**6, 8000) == 80
    assert task.steps(0) == 4 and task.epochs == 40 and GanTask(corpus, tiny_config(), "path").epochs == 40


def test_config_and_fingerprint(corpus, path_model, tmp_path):
    task = GanTask(corpus, tiny_config(), "generator", path_model=path_model)
    cfg = json.loads(json.dumps(task.config()))
    assert cfg["stage"] == "generator" and len(cfg["path_model"]) == 40 and cfg["gan"]["max_gap"] == 120
    assert "generator_epochs" not in cfg["gan"]  # epochs may change on --resume
    fp = task.fingerprint()
    assert fp == GanTask(corpus, tiny_config(), "path").fingerprint()
    other = synthetic_corpus(tmp_path / "other", clips_per_style=2, seed=9)
    assert GanTask(other, tiny_config(), "path").fingerprint() != fp
    assert task.kind == "gan" and task.learning_rates(0, 0, 1) is None
    assert {type(o).__name__ for o in task.optimizers(task.build(None)).values()} == {"RMSprop"}


def test_config_files_and_presets(tmp_path):
    assert read_config(None).preset == "cpu"
    assert read_config(None, "paper").widths["decoder"][0] == 1024
    f = tmp_path / "gan.json"
    f.write_text(json.dumps({"preset": "paper", "sequence_frames": 2048, "noise_dim": 0}))
    cfg = read_config(f, seed=7)
    assert cfg.preset == "paper" and cfg.sequence_frames == 2048 and cfg.noise_dim == 0 and cfg.seed == 7
    f.write_text(json.dumps({"no_such_setting": 1}))
    with pytest.raises(UsageError, match="no_such_setting"):
        read_config(f)


def test_stage_errors(corpus, tmp_path):
    with pytest.raises(UsageError, match="stage"):
        GanTask(corpus, tiny_config(), "everything")
    with pytest.raises(UsageError, match="path_model"):
        GanTask(corpus, tiny_config(), "generator")
    with pytest.raises(ModelError):
        GanTask(corpus, tiny_config(), "generator", path_model=tmp_path / "nothing")


def test_registry_entry():
    m = registry.get("gan")
    assert m.learned and m.protocol == "lafan1" and m.training_spec().make_task is not None
    assert m.default_model().name == "bandai2-gan"  # shipped; bandai2-gan-partial serves partial keys
    assert [o.name for o in m.training_spec().options][:2] == ["stage", "path_model"]


@pytest.mark.slow  # two torch processes start: about half a minute on the shared 2-core machine
def test_two_processes_train_the_path_predictor_one_process_trains(tmp_path, monkeypatch):
    """torchrun with 2 gloo processes, each on half of every batch, gives the 1-process path predictor.

    (The generator stage is ordinary data-parallel training but not equal to one process: Eq. 9's
    batch statistics are taken over each process's shard.)"""
    import os
    import subprocess
    import sys

    from gan_helpers import TINY_WIDTHS
    from safetensors.torch import load_file
    from synthetic_corpus import write_corpus

    from keyfill.cli.main import main

    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))
    clips = tmp_path / "clips"
    write_corpus(clips, clips_per_style=2, frames=(130, 200), seed=3)
    config = tmp_path / "tiny.json"
    config.write_text(json.dumps({"widths": TINY_WIDTHS, "steps_per_epoch": 3, "path_batch": 4,
                                  "sequence_frames": 256, "max_gap": 120, "val_fraction": 0.2, "lr_path": 3e-4}))
    args = ["-q", "train", "gan", str(clips), "--stage", "path", "--config", str(config), "--epochs", "2",
            "--threads", "1"]
    assert main([*args, "-o", str(tmp_path / "one")]) == 0
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node=2", "-m", "keyfill",
           *args, "-o", str(tmp_path / "two")]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    one = load_file(str(tmp_path / "one" / "weights.safetensors"))
    two = load_file(str(tmp_path / "two" / "weights.safetensors"))
    assert one.keys() == two.keys()
    for k in one:
        assert torch.allclose(one[k], two[k], rtol=1e-4, atol=1e-6), (k, (one[k] - two[k]).abs().max())
