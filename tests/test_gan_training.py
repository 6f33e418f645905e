"""The training task of both stages: a few steps reduce the losses; batches, state and config behave."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import run, synthetic_corpus, tiny_config

from keyfill.errors import ModelError, UsageError
from keyfill.learn.gan.task import GanTask
from keyfill.learn.modelfile import read_config

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def no_update(name, loss):
    """Score a batch without changing any weight."""


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return synthetic_corpus(tmp_path_factory.mktemp("gan_corpus") / "clips", clips_per_style=3)


@pytest.fixture(scope="module")
def path_model(corpus, tmp_path_factory):
    """A path predictor trained for a few steps, saved as a stage-"path" gan model."""
    task = GanTask(corpus, tiny_config(), "path")
    torch.manual_seed(0)
    nets = task.build(torch.Generator().manual_seed(0))
    log = run(task, nets, epochs=6)
    return task.save(tmp_path_factory.mktemp("gan_path") / "path-model", nets, [log[-1]])


def test_path_stage_reduces_eq5(corpus):
    task = GanTask(corpus, tiny_config(), "path")
    torch.manual_seed(0)
    nets = task.build(torch.Generator().manual_seed(0))
    fixed = task.path_batch(np.random.default_rng(123))
    before = task.step(fixed, no_update)[0]["path"]
    run(task, nets, epochs=6)
    after = task.step(fixed, no_update)[0]["path"]
    assert after < 0.7 * before
    assert task.validate(2)["path_loss"] > 0


def test_generator_stage_reduces_its_losses(corpus, path_model):
    task = GanTask(corpus, tiny_config(), "generator", path_model=path_model)
    torch.manual_seed(1)
    nets = task.build(torch.Generator().manual_seed(1))
    assert set(nets) == {"generator", "discriminator"}
    fixed = task.generator_batch(np.random.default_rng(321), task.train_pool)
    before = task.step(fixed, no_update)[0]
    frozen = {k: v.clone() for k, v in task.path_net.state_dict().items()}
    log = run(task, nets, epochs=3)
    after = task.step(fixed, no_update)[0]
    assert after["key_joint"] < 0.7 * before["key_joint"]
    assert after["key_root"] < 0.7 * before["key_root"]
    assert after["generator"] < 0.7 * before["generator"]
    assert after["d_adv"] < before["d_adv"]
    assert all(np.isfinite(v) for entry in log for v in entry.values())
    # the path predictor stayed frozen
    assert all(torch.equal(frozen[k], v) for k, v in task.path_net.state_dict().items())
    scores = task.validate(2)
    assert set(scores) == {"key_joint_error", "key_root_error"} and all(v >= 0 for v in scores.values())
    saved = task.save(path_model.parent / "full", nets, log)
    cfg = read_config(saved, kind="gan")
    assert cfg["stage"] == "full" and cfg["ranges"]["driven"] and cfg["training"]["steps"] == task.steps


def test_batches_are_seeded_sharded_and_resumable(corpus, path_model):
    task = GanTask(corpus, tiny_config(), "generator", path_model=path_model)
    a, b = next(iter(task.batches(4))), next(iter(task.batches(4)))
    assert a.arrays.keys() == b.arrays.keys()
    assert all(np.array_equal(a.arrays[k], b.arrays[k]) for k in a.arrays)
    c = next(iter(task.batches(5)))
    assert not np.array_equal(a.arrays["dense"], c.arrays["dense"])
    halves = [task.shard(a, r, 2) for r in range(2)]
    assert sum(h.rows for h in halves) == a.rows
    assert np.array_equal(halves[1].arrays["real"], a.arrays["real"][1::2])
    task.steps = 2345
    other = GanTask(corpus, tiny_config(), "generator", path_model=path_model)
    other.load_state_dict(json.loads(json.dumps(task.state_dict())))
    assert other.steps == 2345
    assert task.cfg.root_weight(0) == 10 and task.cfg.root_weight(2345) == 12 and task.cfg.root_weight(10**6) == 80


def test_config_and_fingerprint(corpus, path_model, tmp_path):
    task = GanTask(corpus, tiny_config(), "generator", path_model=path_model)
    cfg = json.loads(json.dumps(task.config()))
    assert cfg["stage"] == "generator" and len(cfg["path_model"]) == 40 and cfg["gan"]["max_gap"] == 120
    fp = task.fingerprint()
    assert fp == GanTask(corpus, tiny_config(), "path").fingerprint()
    other = synthetic_corpus(tmp_path / "other", clips_per_style=2, seed=9)
    assert GanTask(other, tiny_config(), "path").fingerprint() != fp
    assert task.kind == "gan" and task.learning_rates(0, 0, 1) is None
    assert {type(o).__name__ for o in task.optimizers(task.build()).values()} == {"RMSprop"}


def test_stage_errors(corpus, tmp_path):
    with pytest.raises(UsageError, match="stage"):
        GanTask(corpus, tiny_config(), "everything")
    with pytest.raises(UsageError, match="path_model"):
        GanTask(corpus, tiny_config(), "generator")
    with pytest.raises(ModelError):
        GanTask(corpus, tiny_config(), "generator", path_model=tmp_path / "nothing")
