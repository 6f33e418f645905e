"""The transformer's realism terms (issue 30): foot sliding over contact labels and excess jerk, both off by
default; hand-computed values, labels windowed and mirrored as the training windows are."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from test_humanoid_roles import family

from keyfill import rotations as R
from keyfill.characters.humanoid import map_roles
from keyfill.learn.corpus import Corpus
from keyfill.learn.realism_terms import corpus_contacts, excess_jerk_loss, foot_sliding_loss
from keyfill.learn.transformer import config as TC
from keyfill.learn.transformer import network as TN
from keyfill.learn.transformer.task import TrainConfig, TransformerTask, sample_layout

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TINY = TC.ModelConfig(layers=1, d_model=16, heads=2, ffn=32, dropout=0.0, max_frames=65)
TRAINING = TrainConfig(epochs=1, batch_size=8, window=65, window_offset=10, val_fraction=0.0)


def test_foot_sliding_by_hand():
    feet = torch.zeros(1, 3, 2, 3)
    feet[0, :, 0] = torch.tensor([[0, 0, 0], [0.1, 0, 0], [0.1, 5, 0.2]])  # moves 1 then 2 per second
    feet[0, :, 1] = torch.tensor([[0, 0, 0], [0, 0, 0.3], [0.4, 0, 0.3]])  # never in contact on two frames
    contact = torch.tensor([[[True, True], [True, False], [True, True]]])
    # joint 0: speeds (1, 0) and (0, 2) m/s at 10 fps (the up axis, y, does not count); joint 1: no pair
    assert float(foot_sliding_loss(feet, contact, fps=10, up=1)) == pytest.approx((1 + 4) / 2)
    assert float(foot_sliding_loss(feet, contact, fps=10, up=1, pairs=torch.tensor([[1.0, 0.0]]))) == pytest.approx(1)
    assert float(foot_sliding_loss(feet, contact & False, fps=10, up=1)) == 0


def test_excess_jerk_by_hand():
    pred = torch.zeros(1, 5, 1, 3, requires_grad=True)
    true = torch.zeros(1, 5, 1, 3)
    with torch.no_grad():
        pred[0, 3, 0, 0] = 1  # x = 0 0 0 1 0: third differences 1, -3
    true[0, 4, 0, 0] = 4  # x = 0 0 0 0 4: third differences 0, 4
    # excess max(1 - 0, 0) = 1 and max(3 - 4, 0) = 0 (smoother than the truth costs nothing), mean 0.5, x scale 2
    loss = excess_jerk_loss(pred, true, scale=2.0)
    assert float(loss.detach()) == pytest.approx(1.0)
    assert float(excess_jerk_loss(pred, true, 2.0, quads=torch.tensor([[0.0, 1.0]])).detach()) == 0
    assert float(excess_jerk_loss(pred, true, 2.0, quads=torch.tensor([[1.0, 0.0]])).detach()) == pytest.approx(2.0)
    loss.backward()
    assert torch.isfinite(pred.grad).all()  # still joints too: the norm's gradient is clamped


def stand_on_one_leg(skeleton, frames: int = 150, seed: int = 0):
    """Walks forward for 50 frames, then stands on the right leg with the left knee raised: the right foot
    is planted and the left is in the air, so the contact labels tell the sides apart."""
    roles = map_roles(skeleton)
    rng = np.random.default_rng(seed)
    J, t = skeleton.num_joints, np.arange(frames) / 30.0
    phase = 2 * np.pi * 1.8 * t
    euler = rng.uniform(0.0, 0.02, (J, 3)) * np.sin(phase[:, None, None] + rng.uniform(0, 6.3, (J, 3)))
    walking = t < 50 / 30
    for side, sign in (("l", 1.0), ("r", -1.0)):
        euler[walking, roles.limbs[f"thigh_{side}"], 1] = 0.4 * sign * np.sin(phase[walking])
    euler[~walking, roles.limbs["thigh_l"], 1] = -1.0
    euler[~walking, roles.limbs["shin_l"], 1] = 1.2
    root = np.stack([0 * t, 89 + 0 * t, 110 * np.minimum(t, 50 / 30)], -1)
    return R.quat_continuous_np(R.euler_to_quat(euler, "ZXY"), axis=0), root


@pytest.fixture(scope="module")
def corpus():
    sk = family("lafan1")
    clips = [stand_on_one_leg(sk, 150 + 10 * i, seed=i) for i in range(3)]
    starts = np.concatenate([[0], np.cumsum([len(q) for q, _ in clips])])
    return Corpus(sk, tuple(f"stand_{i}.bvh" for i in range(3)), np.concatenate([q for q, _ in clips]),
                  np.concatenate([r for _, r in clips]), starts, 30.0, False)


def test_contact_labels_are_windowed_and_mirrored_as_the_windows(corpus):
    cfg = dataclasses.replace(TINY, foot_weight=0.5)
    task = TransformerTask(corpus, cfg, TRAINING, seed=0)
    labels, joints = corpus_contacts(corpus)
    roles = map_roles(corpus.skeleton)
    cols = {corpus.skeleton.names[j]: i for i, j in enumerate(joints)}
    left, right = cols[corpus.skeleton.names[roles.limbs["foot_l"]]], cols[corpus.skeleton.names[roles.limbs["foot_r"]]]
    # standing: the right foot is planted, the left is not
    assert labels[100:140, right].all() and not labels[100:140, left].any()
    frames, _, _ = corpus.window_frames(TRAINING.window, TRAINING.window_offset)
    np.testing.assert_array_equal(task.data.contacts, labels[frames])
    assert task.mirror is not None and task.contact_swap[left] == right and task.contact_swap[right] == left
    torch.manual_seed(0)
    task.build(None)
    batch = next(task.batches(0))
    # the draws of batches(0), as the task makes them
    rng = np.random.default_rng([0, 0])
    rng.integers(2**62)
    order = rng.permutation(len(task.data.quats))
    _, T, _ = sample_layout(rng, TRAINING.layouts, TRAINING.window, TRAINING.gap_sampling)
    idx = order[:TRAINING.batch_size]
    flip = rng.random(len(idx)) < 0.5
    assert flip.any() and not flip.all()
    want = task.data.contacts[idx, :T].copy()
    want[flip] = want[flip][..., task.contact_swap]
    np.testing.assert_array_equal(batch[5].numpy(), want)
    # the same windows, layouts and mirroring as without the term
    plain = TransformerTask(corpus, TINY, TRAINING, seed=0)
    torch.manual_seed(0)
    plain.build(None)
    plain_batch = next(plain.batches(0))
    assert len(plain_batch) == 5 and plain.data.contacts is None
    for a, b in zip(plain_batch, batch[:5]):
        assert torch.equal(a, b)


def test_the_terms_add_to_the_total_with_their_weights(corpus):
    cfg = dataclasses.replace(TINY, foot_weight=0.5, smooth_weight=0.01)
    task = TransformerTask(corpus, cfg, TRAINING, seed=0)
    torch.manual_seed(0)
    task.build(None)
    batch = next(task.batches(0))
    x, y, gq, gr, kinds = batch[:5]
    with torch.no_grad():
        pred = task.model.network(x, kinds)
        out = task.losses(pred, batch)
        base = TN.losses(task.model.features, pred, y, gq, gr, kinds, cfg)
        truth = task.losses(y, batch)  # the true window has no jerk beyond its own
    assert float(out["foot"]) > 0 and float(out["smooth"]) > 0
    assert float(out["total"]) == pytest.approx(float(base["total"] + 0.5 * out["foot"] + 0.01 * out["smooth"]),
                                                rel=1e-6)
    assert float(truth["smooth"]) < 1e-3 * float(out["smooth"])
    off = TransformerTask(corpus, TINY, TRAINING, seed=0)
    torch.manual_seed(0)
    off.build(None)
    with torch.no_grad():
        plain = off.losses(off.model.network(x, kinds), batch[:5])
    assert set(plain) == {"total", "position", "rotation", "kinematics"}


def test_weights_default_off_and_are_not_recorded():
    cfg = TC.ModelConfig()
    assert cfg.foot_weight == 0 and cfg.smooth_weight == 0
    assert "foot_weight" not in cfg.recorded() and "smooth_weight" not in cfg.recorded()
    on = TC.ModelConfig(foot_weight=0.3, smooth_weight=1e-4).recorded()
    assert on["foot_weight"] == 0.3 and on["smooth_weight"] == 1e-4
    with pytest.raises(Exception, match="foot_weight"):
        TC.ModelConfig(foot_weight=-1)


def test_a_run_with_the_terms_logs_them_and_records_their_weights(corpus, tmp_path, monkeypatch):
    import json

    from keyfill.learn.transformer.model import load
    from keyfill.learn.transformer.task import train

    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))
    cfg = dataclasses.replace(TINY, foot_weight=0.3, smooth_weight=2.5e-4)
    model = train(corpus, tmp_path / "m", cfg, TRAINING, seed=0)
    log = [json.loads(line) for line in (tmp_path / "m.log.jsonl").read_text().splitlines()]
    assert log[-1]["loss_foot"] > 0 and log[-1]["loss_smooth"] > 0
    arch = json.loads((tmp_path / "m" / "config.json").read_text())["architecture"]
    assert arch["foot_weight"] == 0.3 and arch["smooth_weight"] == 2.5e-4
    assert model.info["contact_columns"] == 4 and load(tmp_path / "m").config == cfg
