"""ARNN library: features, the three architectures, the curriculum, training, evaluation.

Data: tests/data/lamp_hops_seed1.npz, 12 sequences made by ``keyfill simulate --count 12 --seed 1``.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from conftest import DATA

from keyfill.learn.arnn import network as arnn_network
from keyfill.learn.arnn.features import conditioning, delete_keys, make_batch
from keyfill.learn.arnn.task import Schedule, Settings, loss_terms, sigmoid_ramp, train
from keyfill.learn.lamp_data import LampSequence, Normalizer, origin, relative, split
from keyfill.learn.protocols.keys import deleted_keys, evaluate
from keyfill.learn.training import TrainingDiverged, read_checkpoint


def lamp_sequences() -> list[LampSequence]:
    d = np.load(DATA / "lamp_hops_seed1.npz")
    return [LampSequence(v, k, str(n)) for v, k, n in zip(d["values"], d["keys"], d["names"])]


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def sequences():
    return lamp_sequences()


def _train(tmp_path, seqs, name="m", **kw):
    parts = split(seqs)
    settings = Settings(**{"epochs": 12, "batch_size": 4, "checkpoint_every": 5, "seed": 3, **kw})
    return train(parts["train"], parts["val"], settings, tmp_path / name, checkpoint=tmp_path / f"{name}.ckpt",
                 log=tmp_path / f"{name}.log.jsonl")


# --- features --------------------------------------------------------------------------------------


def test_normalizer_round_trip_and_relative_x(sequences):
    norm = Normalizer.fit(sequences)
    s = sequences[0]
    z = norm.encode(s.span)
    assert abs(z.mean()) < 1.5 and z.shape == (87, 6)
    assert np.allclose(norm.decode(z, origin(s.span[0])), s.span, atol=1e-12)
    # the same keys anywhere along x, or after whole turns of a joint, encode the same
    moved = s.span + np.array([5.0, 0, 2 * np.pi, 0, -4 * np.pi, 0])
    assert np.allclose(norm.encode(moved), z)
    assert np.allclose(relative(moved), relative(s.span))
    assert np.allclose(norm.decode(z, origin(moved[0])), moved, atol=1e-12)
    assert np.all(np.abs(relative(s.span)[0, 2:]) <= np.pi)
    assert Normalizer.from_json(json.loads(json.dumps(norm.to_json()))).std.tolist() == norm.std.tolist()


def test_conditioning_keys_and_relative_time():
    # two sequences: keys 0,4,6 (length 7) and 0,2 (length 3, padded to 7)
    frames = torch.arange(7, dtype=torch.float32)[None, :, None].repeat(2, 1, 6)
    is_key = torch.zeros(2, 7, dtype=torch.bool)
    is_key[0, [0, 4, 6]] = True
    is_key[1, [0, 2]] = True
    x_prev, x_next, t_rel, target_key = conditioning(frames, is_key)
    # frame t in (T_K, T_K+1]: frames 1-4 between keys 0 and 4, frames 5-6 between 4 and 6
    assert x_prev[0, :, 0].tolist() == [0, 0, 0, 0, 4, 4]
    assert x_next[0, :, 0].tolist() == [4, 4, 4, 4, 6, 6]
    assert t_rel[0, :, 0].tolist() == pytest.approx([0.25, 0.5, 0.75, 1.0, 0.5, 1.0])
    assert target_key[0].tolist() == [False, False, False, True, False, True]
    # past the last key (padding): last key both sides, t_rel 1
    assert x_prev[1, :, 0].tolist() == [0, 0, 2, 2, 2, 2]
    assert x_next[1, :, 0].tolist() == [2, 2, 2, 2, 2, 2]
    assert t_rel[1, :, 0].tolist() == pytest.approx([0.5, 1, 1, 1, 1, 1])


def test_make_batch_pads_sequences_of_any_length_and_spacing(sequences):
    s = sequences[0]
    short = LampSequence(s.values[10:50], np.array([0, 3, 30, 39]), "short")
    batch = make_batch([s, short], Normalizer.fit(sequences))
    assert batch.frames.shape == (2, 87, 6)
    assert batch.lengths.tolist() == [87, 40]
    assert batch.valid[1].sum() == 40 and not batch.valid[1, 40:].any()
    assert torch.nonzero(batch.is_key[1]).flatten().tolist() == [0, 3, 30, 39]


def test_delete_keys_keeps_ends_and_deletes_zero_to_two(sequences):
    batch = make_batch(sequences, Normalizer.fit(sequences))
    counts = []
    for seed in range(20):
        kept = delete_keys(batch.is_key, batch.valid, torch.Generator().manual_seed(seed))
        assert kept[:, 0].all() and kept[torch.arange(len(batch)), batch.lengths - 1].all()
        assert not (kept & ~batch.is_key).any()
        counts += (batch.is_key.sum(1) - kept.sum(1)).tolist()
    assert set(counts) == {0, 1, 2}
    again = delete_keys(batch.is_key, batch.valid, torch.Generator().manual_seed(7))
    assert torch.equal(again, delete_keys(batch.is_key, batch.valid, torch.Generator().manual_seed(7)))
    one_two = delete_keys(batch.is_key, batch.valid, torch.Generator().manual_seed(1), min_deleted=1)
    assert set((batch.is_key.sum(1) - one_two.sum(1)).tolist()) <= {1, 2}


def test_eval_deletions_are_one_or_two_interior_keys(sequences):
    for s, d in zip(sequences, deleted_keys(sequences, seed=0)):
        assert d.keys[0] == s.keys[0] and d.keys[-1] == s.keys[-1]
        assert len(s.keys) - len(d.keys) in (1, 2) and set(d.keys) <= set(s.keys)


# --- architectures ----------------------------------------------------------------------------------


@pytest.mark.parametrize("arch", arnn_network.ARCHITECTURES)
def test_forward_shapes_and_teacher_path_matches_free_path(arch, sequences):
    net = arnn_network.build(arch, torch.Generator().manual_seed(0)).eval()
    batch = make_batch(sequences[:3], Normalizer.fit(sequences))
    with torch.no_grad():
        free = arnn_network.run(net, batch.frames, batch.is_key)
        assert free.shape == (3, 86, 6) and torch.isfinite(free).all()
        # Feeding the free run's own predictions as "teacher" frames through the fused path gives the same frames.
        x_prev, x_next, t_rel, _ = conditioning(batch.frames, batch.is_key)
        own = torch.cat([batch.frames[:, :1], free[:, :-1]], dim=1)
        fused = net(batch.frames[:, 0], x_prev, x_next, t_rel, teacher=own)
    assert torch.allclose(fused, free, atol=1e-5)
    # about the same number of weights for a fair comparison (section 9)
    assert 100_000 < arnn_network.num_weights(net) < 115_000


def test_arnn_layers_are_those_of_section_6():
    net = arnn_network.build("arnn")
    assert (net.gru1.hidden_size, net.gru2.hidden_size) == (100, 100)
    assert (net.ff.first.out_features, net.ff.second.out_features, net.ff.out.out_features) == (10, 10, 6)
    assert net.gru1.input_size == 3 * net.pose.second.out_features + 1  # three pose features + t_rel
    assert arnn_network.DROPOUT == (0.1, 0.05, 0.2, 0.1)


def test_dropout_is_drawn_from_the_generator_only(sequences):
    net = arnn_network.build("arnn", torch.Generator().manual_seed(0)).train()
    batch = make_batch(sequences[:2], Normalizer.fit(sequences))
    a = arnn_network.run(net, batch.frames, batch.is_key, generator=torch.Generator().manual_seed(5))
    torch.manual_seed(123)  # the global generator must not matter
    b = arnn_network.run(net, batch.frames, batch.is_key, generator=torch.Generator().manual_seed(5))
    c = arnn_network.run(net, batch.frames, batch.is_key, generator=torch.Generator().manual_seed(6))
    assert torch.equal(a, b) and not torch.equal(a, c)


# --- loss and curriculum -----------------------------------------------------------------------------


def test_loss_terms_of_eq4():
    frames = torch.zeros(1, 5, 6)
    is_key = torch.tensor([[True, False, True, False, True]])
    valid = torch.ones(1, 5, dtype=torch.bool)
    pred = torch.zeros(1, 4, 6)
    pred[0, 1] = 1.0  # frame 2, a key: squared error 6
    pred[0, 0] = 0.5  # frame 1: squared error 1.5
    key_sum, frame_mse, key_mse = loss_terms(pred, frames, is_key, valid)
    assert float(key_sum) == pytest.approx(6.0)  # sum over keys and variables
    assert float(frame_mse) == pytest.approx(7.5 / 24)  # mean over 4 frames x 6 variables
    assert float(key_mse) == pytest.approx(6.0 / 12)  # mean over 2 keys x 6 variables


def test_curriculum_schedules_have_the_papers_shape():
    E = 1000
    s = Schedule(E)
    tf = np.array([s.teacher_forcing(e) for e in range(E)])
    om = np.array([s.omega(e) for e in range(E)])
    # teacher forcing: 1 -> 0 over the first half, monotone, inverse-sigmoid (fastest fall mid-phase)
    assert tf[0] == 1.0 and tf[E // 2:].max() == 0.0
    assert np.all(np.diff(tf) <= 0)
    assert tf[E // 4] == pytest.approx(0.5, abs=1e-9)
    drops = -np.diff(tf[: E // 2])
    assert abs(int(np.argmax(drops)) - E // 4) <= 1
    assert tf[E // 20] > 0.95 and tf[E // 2 - E // 20] < 0.05  # flat ends: sigmoid, not linear
    # omega: 0 through the first half, a sigmoid up to exactly 1, then held
    assert om[: E // 2 + 1].max() == 0.0 and om[-1] == 1.0 and np.all(np.diff(om) >= 0)
    mid = round((0.5 + 0.85) / 2 * E)
    assert om[mid] == pytest.approx(0.5, abs=0.01)
    assert om[int(0.88 * E)] == 1.0
    rises = np.diff(om)
    assert abs(int(np.argmax(rises)) - mid) <= 1
    # no curriculum: always free-running, full key weight
    n = Schedule(E, curriculum=False)
    assert {n.teacher_forcing(e) for e in range(0, E, 37)} == {0.0} and {n.omega(e) for e in range(0, E, 37)} == {1.0}
    assert sigmoid_ramp(0.0) == 0.0 and sigmoid_ramp(1.0) == 1.0 and sigmoid_ramp(0.5) == pytest.approx(0.5)
    # learning rate: the paper's until omega reaches 1, then down to a tenth
    lr = np.array([s.lr_scale(e) for e in range(E)])
    assert lr[: int(0.85 * E) + 1].min() == 1.0 and np.all(np.diff(lr) <= 0) and lr[-1] == pytest.approx(0.1, abs=0.002)
    assert n.lr_scale(E // 2) == 1.0 and n.lr_scale(E - 1) == pytest.approx(0.1, abs=0.002)


# --- training ----------------------------------------------------------------------------------------


def test_short_training_run_loss_falls(tmp_path, sequences):
    result = _train(tmp_path, sequences, curriculum=False, epochs=10)
    rows = [json.loads(line) for line in (tmp_path / "m.log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows] == list(range(1, 11))
    assert rows[-1]["train_objective"] < 0.5 * rows[0]["train_objective"]
    assert rows[-1]["val_total"] < 0.7 * rows[0]["val_total"]
    assert set(rows[0]) >= {"train_key", "train_frame", "train_total", "val_key", "val_frame", "val_total",
                            "val_deleted_total", "teacher_forcing", "omega"}
    config = json.loads((result.path / "config.json").read_text())
    assert config["kind"] == "arnn" and config["arch"] == "arnn" and config["skeleton"]["names"][0] == "base"


@pytest.mark.parametrize("key_weight", [0.0, 10.0, 100.0])
def test_the_objective_weighs_the_key_term_by_key_weight(tmp_path, sequences, key_weight):
    _train(tmp_path, sequences, curriculum=False, epochs=1, key_weight=key_weight)  # no curriculum: omega 1
    row = json.loads((tmp_path / "m.log.jsonl").read_text().splitlines()[0])
    assert row["omega"] == 1.0 and row["train_key"] > 0
    assert row["train_objective"] == pytest.approx(key_weight * row["train_key"] + row["train_frame"], rel=1e-6)


def test_training_is_deterministic(tmp_path, sequences):
    a = _train(tmp_path, sequences, name="a", epochs=2)
    b = _train(tmp_path, sequences, name="b", epochs=2)
    c = _train(tmp_path, sequences, name="c", epochs=2, seed=4)
    weights = [(r.path / "weights.safetensors").read_bytes() for r in (a, b, c)]
    assert weights[0] == weights[1] != weights[2]


def test_resume_gives_the_same_model_as_an_uninterrupted_run(tmp_path, sequences):
    full = _train(tmp_path, sequences, name="full", epochs=4, checkpoint_every=2)
    parts = split(sequences)
    settings = Settings(epochs=4, batch_size=4, checkpoint_every=2, seed=3)
    # interrupt a run in epoch 3 (after the checkpoint of epoch 2), then resume it
    class Stop(Exception):
        pass

    def stop_at_3(row):
        if row["epoch"] == 3:
            raise Stop

    with pytest.raises(Stop):
        train(parts["train"], parts["val"], settings, tmp_path / "resumed", checkpoint=tmp_path / "r.ckpt",
              log=tmp_path / "r.log.jsonl", on_epoch=stop_at_3)
    assert not (tmp_path / "resumed").exists()
    resumed = train(parts["train"], parts["val"], settings, tmp_path / "resumed", checkpoint=tmp_path / "r.ckpt",
                    log=tmp_path / "r.log.jsonl", resume=True)
    assert (resumed.path / "weights.safetensors").read_bytes() == (full.path / "weights.safetensors").read_bytes()
    rows = [json.loads(line) for line in (tmp_path / "r.log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows] == list(range(1, 5))


def test_resume_with_other_settings_is_refused(tmp_path, sequences):
    from keyfill.errors import UsageError

    _train(tmp_path, sequences, epochs=2, checkpoint_every=1)
    parts = split(sequences)
    with pytest.raises(UsageError, match="other settings"):
        train(parts["train"], parts["val"], Settings(epochs=2, batch_size=4, checkpoint_every=1, seed=4),
              tmp_path / "m", checkpoint=tmp_path / "m.ckpt", resume=True)


def test_diverging_training_stops_with_a_clear_message(tmp_path, sequences):
    parts = split(sequences)
    # lr 1e30: one Adam step throws the weights to ~1e30 and the next forward pass overflows
    settings = Settings(epochs=5, batch_size=3, lr=1e30, clip=0.0, checkpoint_every=1, curriculum=False)
    with pytest.raises(TrainingDiverged, match=r"training diverged at epoch 1: the loss is (nan|inf); no checkpoint"):
        train(parts["train"], parts["val"], settings, tmp_path / "m", checkpoint=tmp_path / "m.ckpt")
    assert not (tmp_path / "m").exists() and not (tmp_path / "m.ckpt").exists()


def test_nan_loss_keeps_the_last_good_checkpoint(tmp_path, sequences, monkeypatch):
    import keyfill.learn.arnn.task as T

    calls = {"n": 0}
    real = T.loss_terms

    def nan_in_epoch_3(pred, *args):  # per epoch: 3 training batches, then 2 held-out calls
        calls["n"] += 1
        out = real(pred, *args)
        return tuple(t * float("nan") for t in out) if calls["n"] > 2 * 5 else out

    monkeypatch.setattr(T, "loss_terms", nan_in_epoch_3)
    parts = split(sequences)
    settings = Settings(epochs=5, batch_size=3, checkpoint_every=1, curriculum=False)
    with pytest.raises(TrainingDiverged, match=r"training diverged at epoch 3: the loss is nan; the last good "
                                               r"checkpoint, .*m.ckpt \(epoch 2\), is kept: resume"):
        train(parts["train"], parts["val"], settings, tmp_path / "m", checkpoint=tmp_path / "m.ckpt")
    assert read_checkpoint(tmp_path / "m.ckpt")["epoch"] == 2 and not (tmp_path / "m").exists()


def test_split_is_the_papers_240_60(sequences):
    parts = split(list(range(300)))
    assert (len(parts["train"]), len(parts["val"]), len(parts["test"])) == (210, 30, 60)
    assert parts["test"] == list(range(240, 300))
    small = split(sequences)
    assert [len(small[k]) for k in ("train", "val", "test")] == [9, 1, 2]


# --- evaluation --------------------------------------------------------------------------------------


def test_evaluate_splines_hit_keys_and_fewer_keys_score_worse(sequences):
    for name in ("linear", "cubic", "cubic-variables"):
        rep = evaluate(name, sequences)
        for cond in ("all_keys", "deleted_keys"):
            assert rep.scores[cond].key < 1e-20 and rep.scores[cond].frame > 0.05
            assert rep.scores[cond].total == rep.scores[cond].frame
        assert rep.scores["all_keys"].frame < rep.scores["deleted_keys"].frame
    d = rep.as_dict()
    assert set(d["all_keys"]["rmse"]) == {"base_x", "base_y", "base_angle", "leg_angle", "neck_angle", "head_angle"}


def test_scores_compare_angles_modulo_a_turn(sequences):
    from keyfill.learn.protocols.keys import score

    s = sequences[0]
    norm = Normalizer.fit(sequences)
    spun = s.span + np.array([0, 0, 0, 0, 0, 2 * np.pi])  # the head one turn further: the same poses
    assert score([s], [spun], norm).frame < 1e-20
    off = s.span + np.array([0, 0.01, 0, 0, 0, 0])
    assert score([s], [off], norm).rmse["base_y"] == pytest.approx(0.01)


def test_keys_are_read_within_half_a_turn():
    from keyfill.learn.lamp_data import wrap_angles
    from keyfill.learn.protocols.keys import keys_as_read

    v = np.zeros((5, 6))
    v[:, 4] = [0.0, 1.5, 3.0, 2.0, -2.0]  # a neck swinging more than half a turn between keys 2.0 and -2.0 ...
    v[:, 5] = [0.0, 0.0, 7.0, 0.0, 0.0]  # ... and a head one turn around
    read = keys_as_read(LampSequence(v, np.array([0, 3, 4])))
    assert read.values[[3, 4], 4].tolist() == [2.0, -2.0]  # kept, not unwrapped the short way
    assert read.values[2, 5] == 7.0  # not a key: untouched
    assert wrap_angles(np.array([0, 0, np.pi, -np.pi, 7.0, 0]))[2:].tolist() == pytest.approx([-np.pi, -np.pi, 7.0 - 2 * np.pi, 0])
