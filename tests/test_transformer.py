"""The motion-completion transformer: layouts, embeddings, training, completion, model files."""

import json

import numpy as np
import pytest
import torch
from synthetic_corpus import walker_motion, walker_skeleton, write_corpus

from keyfill import io
from keyfill import rotations as R
from keyfill.cli.main import main
from keyfill.errors import ModelError, UsageError
from keyfill.learn.corpus import load_corpus
from keyfill.learn.transformer import config as TC
from keyfill.learn.transformer import features as TF
from keyfill.learn.transformer import model as T
from keyfill.learn.transformer import network as TN
from keyfill.learn.transformer.task import (
    TrainConfig,
    TransformerTask,
    learning_rate,
    make_batch,
    sample_layout,
    train,
)

TINY = TC.ModelConfig(layers=2, d_model=32, heads=4, ffn=64, dropout=0.0, max_frames=65)
TINY_TRAINING = TrainConfig(epochs=2, batch_size=16, lr=2e-3, warmup_epochs=0.2, decay_every=1, window=65,
                            window_offset=10, val_fraction=0.2, val_lengths=(5, 15))


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def corpus_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("walkers")
    write_corpus(folder, styles=("happy", "tired", "calm"), clips_per_style=4, frames=(90, 140), seed=3)
    return folder


@pytest.fixture(scope="module")
def corpus(corpus_dir):
    return load_corpus([corpus_dir], cache=False)


@pytest.fixture(scope="module")
def trained(corpus, tmp_path_factory):
    out = tmp_path_factory.mktemp("model") / "tiny"
    model = train(corpus, out, TINY, TINY_TRAINING, seed=0)
    return out, model


# --- layouts, masks and embeddings ------------------------------------------------


def test_frame_kinds_of_the_three_layouts():
    K, U, I = TF.KEY, TF.UNKNOWN, TF.IGNORED
    inbetween = TF.frame_kinds(18, np.append(np.arange(10), 15))
    assert inbetween.tolist() == [K] * 10 + [U] * 5 + [K] + [I] * 2
    infill = TF.frame_kinds(9, [0, 4, 8])
    assert infill.tolist() == [K, U, U, U, K, U, U, U, K]
    blend = TF.frame_kinds(8, [0, 1, 5, 6, 7])
    assert blend.tolist() == [K, K, U, U, U, K, K, K]
    assert TF.frame_kinds(6, [2, 4]).tolist() == [I, I, K, U, K, I]
    assert TF.anchor_frame(np.append(np.arange(10), 15)) == 9 and TF.anchor_frame([0, 4, 8]) == 0


def test_mixture_embedding_selects_position_and_kind_rows():
    torch.manual_seed(0)
    net = TN.build_network(10, TINY)
    kinds = torch.as_tensor(np.stack([TF.frame_kinds(12, [0, 1, 2, 9]), TF.frame_kinds(12, [0, 5, 10])]))
    emb = net.embed(kinds)
    for b in range(2):
        for t in range(12):
            want = net.position.weight[t] + net.keyframe.weight[kinds[b, t]]
            assert torch.equal(emb[b, t], want)
    assert not torch.equal(net.keyframe.weight[TF.KEY], net.keyframe.weight[TF.UNKNOWN])


def test_zero_filled_input_with_a_mask_and_velocities():
    """issue 46's input layout: the features on keys and zero elsewhere, then the velocity channels (0 unless a
    frame and its predecessor are keys), then the mask (1 on keys); by default the network reads the pre-fill."""
    rng = np.random.default_rng(0)
    x = torch.as_tensor(rng.standard_normal((2, 9, 5)), dtype=torch.float64)
    kinds = torch.as_tensor(np.stack([TF.frame_kinds(9, [0, 1, 2, 6, 7]), TF.frame_kinds(9, [1, 4, 8])]))
    known = (kinds == TF.KEY).numpy()
    assert torch.equal(TN.network_input(x, kinds, TINY), x)
    zero = TC.ModelConfig(**{**TINY.__dict__, "unknown_input": "zero", "velocity_input": True})
    got = TN.network_input(x, kinds, zero).numpy()
    assert got.shape == (2, 9, 11) == (2, 9, TN.input_size(5, zero))
    xn = x.numpy()
    np.testing.assert_array_equal(got[..., :5], np.where(known[..., None], xn, 0.0))
    np.testing.assert_array_equal(got[..., 10], known.astype(float))
    both = known[:, 1:] & known[:, :-1]
    np.testing.assert_allclose(got[:, 1:, 5:10], np.where(both[..., None], xn[:, 1:] - xn[:, :-1], 0.0))
    assert (got[:, 0, 5:10] == 0).all() and both.sum() == 3  # frames 1-2 and 7 of the first window
    speed = TC.ModelConfig(**{**TINY.__dict__, "velocity_input": True})
    got = TN.network_input(x, kinds, speed).numpy()  # the pre-fill's velocity everywhere
    np.testing.assert_allclose(got[:, 1:, 5:], xn[:, 1:] - xn[:, :-1])
    with pytest.raises(ModelError, match="unknown_input"):
        TC.ModelConfig(unknown_input="mean")


def test_only_key_and_unknown_frames_carry_loss(corpus):
    torch.manual_seed(0)
    model = T.new_model(corpus.skeleton, TINY, np.zeros(24), np.full(24, 30.0), corpus.folded)
    q, r, _, _ = corpus.windows(65, 20)
    x, y, gq, gr, kinds = make_batch(model, q[:4], r[:4], np.append(np.arange(10), 30), 36)
    assert (kinds[:, :10] == TF.KEY).all() and (kinds[:, 10:30] == TF.UNKNOWN).all() and (kinds[:, 30] == TF.KEY).all()
    assert (kinds[:, 31:] == TF.IGNORED).all()
    with torch.no_grad():
        pred = model.network(x, kinds)
        base = TN.losses(model.features, pred, y, gq, gr, kinds, TINY)["total"]
        moved = pred.clone()
        moved[:, 31:] += 3.0  # ignored frames: no effect
        assert torch.equal(TN.losses(model.features, moved, y, gq, gr, kinds, TINY)["total"], base)
        for frame in (5, 20, 30):  # key and unknown frames count
            moved = pred.clone()
            moved[:, frame] += 3.0
            assert TN.losses(model.features, moved, y, gq, gr, kinds, TINY)["total"] > base + 1e-3


def test_sampled_layouts_fit_the_window():
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(300):
        name, frames, keys = sample_layout(rng, {"inbetween": 1, "infill": 1, "blend": 1}, 65)
        seen.add(name)
        assert frames <= 65 and keys[0] == 0 and keys[-1] < frames and np.all(np.diff(keys) > 0)
        if name == "inbetween":
            assert keys[:10].tolist() == list(range(10)) and 5 <= keys[-1] - 10 <= 54
    assert seen == {"inbetween", "infill", "blend"}


def test_log_uniform_gap_sampling_trains_short_transitions_more_often():
    def gaps(sampling):
        rng = np.random.default_rng(1)
        return np.array([sample_layout(rng, {"inbetween": 1}, 65, sampling)[2][-1] - 10 for _ in range(4000)])

    uniform, log_uniform = gaps("uniform"), gaps("log-uniform")
    for n in (uniform, log_uniform):
        assert n.min() == 5 and n.max() == 54  # the same range
    # P(n <= 15) is 11/50 = 0.22 uniform and sum(1/n, 5..15) / sum(1/n, 5..54) = 0.496 log-uniform
    assert abs(np.mean(uniform <= 15) - 0.22) < 0.03 and abs(np.mean(log_uniform <= 15) - 0.496) < 0.03
    # the default draws exactly as before the option existed (so older runs retrain to the same bytes)
    rng, old = np.random.default_rng(2), np.random.default_rng(2)
    for _ in range(50):
        _, frames, keys = sample_layout(rng, {"inbetween": 1}, 65)
        old.choice(1, p=[1.0])
        n = int(old.integers(5, 55))
        assert keys[-1] == 10 + n and frames == 11 + n + int(old.integers(0, min(5, 54 - n) + 1))
    with pytest.raises(UsageError, match="gap_sampling 'short'; it is one of uniform, log-uniform"):
        TrainConfig(gap_sampling="short")


def test_key_distances_count_frames_to_the_keys_on_each_side():
    kinds = torch.as_tensor(np.stack([TF.frame_kinds(12, [0, 1, 2, 7, 10]), TF.frame_kinds(12, [3, 4])]))
    since, until = TN.key_distances(kinds, 9)
    assert since.tolist() == [[0, 0, 0, 1, 2, 3, 4, 0, 1, 2, 0, 1], [9, 9, 9, 0, 0, 1, 2, 3, 4, 5, 6, 7]]
    assert until.tolist() == [[0, 0, 0, 4, 3, 2, 1, 0, 2, 1, 0, 9], [3, 2, 1, 0, 0, 9, 9, 9, 9, 9, 9, 9]]


def test_canonical_frame_round_trip():
    rng = np.random.default_rng(3)
    q = R.quat_normalize(rng.normal(size=(3, 20, 4, 4)))
    r = rng.normal(size=(3, 20, 3)) * 100
    keys = np.array([0, 1, 2, 12, 19])
    turn, shift = TF.canonical_transform(q, r, keys, "+Y")
    cq, cr = TF.apply_transform(q, r, turn, shift)
    np.testing.assert_allclose(cr[:, keys][..., [0, 2]].mean(1), 0, atol=1e-9)
    bq, br = TF.apply_transform(cq, cr, turn, shift, inverse=True)
    np.testing.assert_allclose(br, r, atol=1e-9)
    np.testing.assert_allclose(bq, q, atol=1e-12)


def test_learning_rate_warms_up_then_steps_down():
    cfg = TrainConfig(lr=1e-3, warmup_epochs=2, decay_every=4, decay=0.5)
    assert learning_rate(cfg, 0.0) == 0.0 and learning_rate(cfg, 1.0) == pytest.approx(5e-4)
    assert learning_rate(cfg, 3.0) == 1e-3 and learning_rate(cfg, 4.5) == 5e-4 and learning_rate(cfg, 8.0) == 2.5e-4


# --- training -------------------------------------------------------------------------


@pytest.mark.parametrize("coordinates,residual,steps,factor", [
    ("global", False, 30, 0.3), ("local", False, 30, 0.3), ("global", True, 60, 0.9)])
def test_a_few_training_steps_reduce_the_loss(corpus, coordinates, residual, steps, factor):
    cfg = TC.ModelConfig(**{**TINY.__dict__, "coordinates": coordinates, "residual": residual})
    q, r, _, _ = corpus.windows(65, 20)
    torch.manual_seed(0)
    model = T.new_model(corpus.skeleton, cfg, np.zeros(24), np.full(24, 30.0), corpus.folded)
    x, y, gq, gr, kinds = make_batch(model, q[:16], r[:16], np.append(np.arange(10), 40), 45)
    opt = torch.optim.Adam(model.network.parameters(), lr=3e-3)
    model.network.train()
    history = []
    for _ in range(steps + 1):
        loss = TN.losses(model.features, model.network(x, kinds), y, gq, gr, kinds, cfg)["total"]
        history.append(float(loss.detach()))
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert history[-1] < factor * history[0]


def test_training_is_deterministic_and_resumable(corpus, tmp_path):
    cfg = TrainConfig(**{**TINY_TRAINING.__dict__, "epochs": 2, "val_fraction": 0.0})
    a = train(corpus, tmp_path / "a", TINY, cfg, seed=5)
    b = train(corpus, tmp_path / "b", TINY, TrainConfig(**{**cfg.__dict__, "epochs": 1}), seed=5)
    b = train(corpus, tmp_path / "b", TINY, cfg, seed=5, resume=True)
    for (k, va), vb in zip(a.network.state_dict().items(), b.network.state_dict().values()):
        assert torch.equal(va, vb), k
    for name in ("config.json", "weights.safetensors"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    log = [json.loads(line) for line in (tmp_path / "b.log.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in log] == [1, 2]
    with pytest.raises(UsageError, match=r"\(seed 5, now 6\)"):
        train(corpus, tmp_path / "b", TINY, cfg, seed=6, resume=True)


def test_fine_tuning_starts_from_a_model_and_may_change_its_prefill(trained, corpus, tmp_path, capsys):
    folder, model = trained
    cubic = TC.ModelConfig(**{**TINY.__dict__, "prefill": "cubic"})
    cfg = TrainConfig(**{**TINY_TRAINING.__dict__, "epochs": 1, "lr": 0.0})
    # at learning rate 0 the tuned network is the one it started from; only the pre-fill differs
    tuned = train(corpus, tmp_path / "tuned", cubic, cfg, seed=1, init=folder)
    for (k, a), b in zip(model.network.state_dict().items(), tuned.network.state_dict().values()):
        assert torch.equal(a, b), k
    np.testing.assert_array_equal(tuned.features.pos_std, model.features.pos_std)
    assert tuned.info["init"]["model"] == folder.name and len(tuned.info["init"]["weights_sha256"]) == 64
    q, r, _, _ = corpus.windows(41, 20)
    keys = np.append(np.arange(10), 40)
    _, cr = tuned.complete_windows(q[:2], r[:2], keys)
    _, ir = model.complete_windows(q[:2], r[:2], keys)
    assert np.abs(cr - ir).max() > 1e-3  # the pre-fill reaches the output
    assert T.load(tmp_path / "tuned").config.prefill == "cubic"
    # key-distance embeddings start at zero: a model tuned with them starts as the one without
    with_distances = TC.ModelConfig(**{**TINY.__dict__, "key_distances": True})
    distances = train(corpus, tmp_path / "distances", with_distances, cfg, seed=1, init=folder)
    _, dr = distances.complete_windows(q[:2], r[:2], keys)
    _, mr = model.complete_windows(q[:2], r[:2], keys)
    np.testing.assert_allclose(dr, mr, atol=1e-4)
    assert T.load(tmp_path / "distances").config.key_distances
    assert "since_key.weight" in distances.network.state_dict()
    # so do velocity inputs (their input weights); a zero-filled input keeps the features' weights and the mask's
    # start at zero, so its network is the old one reading other inputs
    with_velocity = TC.ModelConfig(**{**TINY.__dict__, "velocity_input": True})
    velocity = train(corpus, tmp_path / "velocity", with_velocity, cfg, seed=1, init=folder)
    _, vr = velocity.complete_windows(q[:2], r[:2], keys)
    np.testing.assert_allclose(vr, mr, atol=1e-4)
    zero = train(corpus, tmp_path / "zero", TC.ModelConfig(**{**TINY.__dict__, "unknown_input": "zero"}), cfg,
                 seed=1, init=folder)
    w, old = zero.network.input.weight, model.network.input.weight
    assert torch.equal(w[:, :-1], old) and not w[:, -1].any()
    with pytest.raises(ModelError, match="prefill must be one of interpolation, cubic, velocity"):
        TC.ModelConfig(prefill="spline")
    with pytest.raises(ModelError, match="rotation_weight must be a number from 0 to 1e"):
        TC.ModelConfig(rotation_weight=-1.0)
    # a model of another skeleton is refused before any training, naming the difference
    long_legs = tmp_path / "long_legs"
    write_corpus(long_legs, styles=("a",), clips_per_style=2, frames=(90, 100), skeleton=walker_skeleton(leg_length=60.0))
    with pytest.raises(UsageError, match="^init .*another skeleton than the training clips: .*Foot_L"):
        train(load_corpus([long_legs], cache=False), tmp_path / "x", cubic, cfg, init=folder)
    assert not (tmp_path / "x").exists()
    # a resumed run must start from the same model
    other = tmp_path / "other"
    train(corpus, other, TINY, cfg, seed=2)
    with pytest.raises(UsageError, match="init"):
        train(corpus, tmp_path / "tuned", cubic, TrainConfig(**{**cfg.__dict__, "epochs": 2}), seed=1, init=other,
              resume=True)


def test_settings_added_later_keep_older_checkpoints_resumable(corpus, tmp_path):
    cfg = TrainConfig(**{**TINY_TRAINING.__dict__, "epochs": 1, "val_fraction": 0.0})
    train(corpus, tmp_path / "m", TINY, cfg, seed=0)
    saved = json.loads(torch.load(tmp_path / "m.checkpoint.pt", weights_only=True)["config"])
    assert "model.prefill" not in saved and "model.rotation_weight" not in saved  # as checkpoints were before
    assert "training.gap_sampling" not in saved and "training.relative_loss" not in saved
    written = json.loads((tmp_path / "m" / "config.json").read_text())
    assert "gap_sampling" not in written["training"]["training"]
    assert {"prefill", "rotation_weight", "key_distances"}.isdisjoint(written["architecture"])
    more = TrainConfig(**{**cfg.__dict__, "epochs": 2})
    train(corpus, tmp_path / "m", TINY, more, seed=0, resume=True)
    velocity = TC.ModelConfig(**{**TINY.__dict__, "prefill": "velocity"})
    with pytest.raises(UsageError, match="prefill"):
        train(corpus, tmp_path / "m", velocity, TrainConfig(**{**cfg.__dict__, "epochs": 3}), seed=0, resume=True)
    log_gaps = TrainConfig(**{**cfg.__dict__, "epochs": 3, "gap_sampling": "log-uniform"})
    with pytest.raises(UsageError, match="gap_sampling"):
        train(corpus, tmp_path / "m", TINY, log_gaps, seed=0, resume=True)


def test_relative_loss_divides_each_batch_by_the_prefill_loss(corpus):
    def first_step(relative):
        cfg = TrainConfig(**{**TINY_TRAINING.__dict__, "val_fraction": 0.0, "relative_loss": relative})
        task = TransformerTask(corpus, TINY, cfg, seed=0)
        torch.manual_seed(0)
        task.build(None)
        batch = next(task.batches(0))
        minimised = []
        logged, _ = task.step(batch, lambda name, loss: minimised.append(float(loss.detach())))
        return task, batch, logged, minimised[0]

    _, _, logged_abs, absolute = first_step(False)
    task, (x, y, gq, gr, kinds), logged_rel, relative = first_step(True)
    prefill = float(TN.losses(task.model.features, x, y, gq, gr, kinds, TINY)["total"])
    assert 0 < prefill and absolute == pytest.approx(logged_abs["total"])
    assert relative == pytest.approx(absolute / prefill, rel=1e-5)
    assert logged_rel == pytest.approx(logged_abs)  # the log stays absolute


def test_rotation_weight_scales_the_quaternion_loss(corpus):
    q, r, _, _ = corpus.windows(45, 20)
    torch.manual_seed(0)
    model = T.new_model(corpus.skeleton, TINY, np.zeros(24), np.full(24, 30.0), corpus.folded)
    x, y, gq, gr, kinds = make_batch(model, q[:4], r[:4], np.append(np.arange(10), 40), 45)
    with torch.no_grad():
        pred = model.network(x, kinds) + 0.01
        one = TN.losses(model.features, pred, y, gq, gr, kinds, TINY)
        four = TN.losses(model.features, pred, y, gq, gr, kinds, TC.ModelConfig(**{**TINY.__dict__, "rotation_weight": 4.0}))
    assert float(one["rotation"]) > 0
    assert float(four["total"] - one["total"]) == pytest.approx(3 * float(one["rotation"]), rel=1e-5)


def test_training_logs_validation_scores(trained):
    out, model = trained
    log = [json.loads(line) for line in out.with_name("tiny.log.jsonl").read_text().splitlines()]
    assert len(log) == 2 and {"val_L2P_5", "val_L2Q_15", "val_NPSS_15", "val_L2P_15_vs_interp"} <= set(log[-1])
    assert model.info["validation_clips"] == 2
    assert out.with_name("tiny.checkpoint.pt").is_file()


# --- using a model -------------------------------------------------------------------


def test_one_model_serves_inbetweening_infilling_and_blending(trained, corpus):
    _, model = trained
    q, r = corpus.clip(0)
    q, r = q[None, :60], r[None, :60]
    for keys in (np.append(np.arange(10), 40), np.arange(0, 60, 6), np.r_[0:10, 45:60]):
        pq, pr = model.complete_windows(q, r, keys)
        assert pq.shape == q.shape and np.isfinite(pq).all() and np.isfinite(pr).all()
        # keys come back close (not yet exact) and frames outside the keys hold the last key
        assert np.abs(pr[0, keys] - r[0, keys]).max() < 5.0
        np.testing.assert_allclose(pr[0, keys[-1] + 1:], np.broadcast_to(r[0, keys[-1]], pr[0, keys[-1] + 1:].shape),
                                   atol=1e-9)


def test_hidden_frames_do_not_change_the_prediction(trained, corpus):
    _, model = trained
    q, r = corpus.clip(1)
    q, r = q[None, :40].copy(), r[None, :40].copy()
    keys = np.append(np.arange(10), 30)
    a = model.complete_windows(q, r, keys)
    q[:, 10:30], r[:, 10:30] = np.nan, np.nan
    b = model.complete_windows(q, r, keys)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_a_joint_s_quaternion_sign_does_not_change_the_prediction(trained, corpus):
    """q and -q are one rotation: flipping the signs of some joints over a window (as another Euler channel order
    gives them: issue 47's Blender operator against the CLI, 0.032 of the height) gives the same rotations,
    each in the sign it was given."""
    _, model = trained
    q, r = corpus.clip(1)
    q, r = q[None, :40].copy(), r[None, :40].copy()
    keys = np.append(np.arange(10), 30)
    a = model.complete_windows(q, r, keys)
    flip = np.where(np.random.default_rng(4).random(q.shape[2]) < 0.5, -1.0, 1.0)[None, None, :, None]
    flip[..., 0, :] = -1.0  # the root too
    b = model.complete_windows(q * flip, r, keys)
    np.testing.assert_allclose(b[0], a[0] * flip, atol=1e-12)
    np.testing.assert_array_equal(a[1], b[1])


def test_save_and_load_give_the_same_completion(trained, corpus):
    out, model = trained
    again = T.load(out)
    q, r = corpus.clip(2)
    keys = [0, 7, 19, 30]
    np.testing.assert_array_equal(model.complete_windows(q[None, :31], r[None, :31], keys)[0],
                                  again.complete_windows(q[None, :31], r[None, :31], keys)[0])
    assert again.skeleton.names == corpus.skeleton.names and again.folded


@pytest.mark.parametrize("keys", [list(range(10)) + [40], list(range(0, 60, 6)), list(range(10)) + list(range(45, 60))],
                         ids=["inbetween", "infill", "blend"])
def test_keys_are_exact_in_every_layout(trained, keys):
    from keyfill.learn.completion import CompleteOptions
    from keyfill.learn.registry import complete
    from keyfill.motion import Keys

    out, _ = trained
    motion = walker_motion(walker_skeleton(), 60, np.random.default_rng(4))
    result = complete(motion, Keys(np.array(keys)), "transformer", CompleteOptions(model=str(out)))
    got = result.motion
    np.testing.assert_allclose(got.positions[keys], motion.positions[keys], atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(got.rotations[keys] * motion.rotations[keys], -1)), 1.0, atol=1e-12)
    between = np.setdiff1d(np.arange(keys[0], keys[-1] + 1), keys)
    assert not np.allclose(got.positions[between, 1], motion.positions[between, 1], atol=1e-3)  # generated


def test_spans_cut_long_key_ranges():
    assert T.spans([0, 10, 30, 60, 90], 65) == [(0, 60), (60, 90)]
    assert T.spans([0, 64], 65) == [(0, 64)]
    with pytest.raises(UsageError, match="keys 0 and 70 are 70 frames apart; this model fills gaps of at most 63"):
        T.spans([0, 70], 65)


def test_cli_complete_makes_keys_exact(trained, tmp_path, capsys):
    out, _ = trained
    src = tmp_path / "walk.bvh"
    io.save(walker_motion(walker_skeleton(), 100, np.random.default_rng(11)), src)
    dst = tmp_path / "filled.bvh"
    code = main(["complete", str(src), "-o", str(dst), "--method", "transformer", "--model", str(out),
                 "--keys", "0,1,2,3,4,5,6,7,8,9,30,50,56,99", "--json"])
    assert code == 0, capsys.readouterr().err
    info = json.loads(capsys.readouterr().out)
    assert info["method"] == "transformer" and info["spans"] == 2 and info["exact_keys"]
    a, b = io.load(src), io.load(dst)
    keys = info["keys"]
    np.testing.assert_allclose(b.positions[keys], a.positions[keys], atol=1e-6)
    np.testing.assert_allclose(np.abs(np.sum(b.rotations[keys] * a.rotations[keys], -1)), 1.0, atol=1e-9)
    assert not np.allclose(b.positions[10:30], a.positions[10:30], atol=1e-3)  # really generated
    np.testing.assert_array_equal(b.positions[:, 0], a.positions[:, 0])  # the static joint_Root stays


def test_model_for_another_skeleton_is_refused(trained, tmp_path, capsys):
    out, _ = trained
    src = tmp_path / "other.bvh"
    io.save(walker_motion(walker_skeleton(leg_length=60.0), 40, np.random.default_rng(1)), src)
    code = main(["complete", str(src), "-o", str(tmp_path / "o.bvh"), "--method", "transformer",
                 "--model", str(out), "--keys", "0,20,39"])
    assert code == 1
    err = capsys.readouterr().err
    assert "keyfill: error: the motion has another skeleton than the model (" in err
    assert ": joint 'Foot_L' has a different rest offset; train a transformer on your own clips with " \
           "'keyfill train transformer CLIPS -o MODEL'" in err
    assert not (tmp_path / "o.bvh").exists()


def test_the_model_is_a_keyfill_model_folder(trained, corpus):
    out, model = trained
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "weights.safetensors"]
    config = json.loads((out / "config.json").read_text())
    assert config["format"] == "keyfill-model" and config["kind"] == "transformer"
    assert config["skeleton"]["names"] == list(corpus.skeleton.names) and config["folded_root"]
    assert config["architecture"]["layers"] == TINY.layers and config["training"]["epochs"] == 2
    from keyfill.learn.modelfile import check_skeleton

    check_skeleton(config, corpus.skeleton, out)  # the check every learned method shares
    model.save(out)  # saving again replaces the model with the same bytes
    assert json.loads((out / "config.json").read_text()) == config


def test_loading_a_model_leaves_the_global_random_stream_alone(trained):
    from keyfill.learn.arnn import model as arnn

    torch.manual_seed(7)
    expected = torch.rand(3)
    torch.manual_seed(7)
    T.load(trained[0])
    arnn.load(arnn.DEFAULT_MODEL)
    assert torch.equal(torch.rand(3), expected)


def test_damaged_or_foreign_models_are_refused(trained, tmp_path):
    import shutil

    out, _ = trained
    with pytest.raises(ModelError, match="no such model"):
        T.load(tmp_path / "missing")
    junk = tmp_path / "junk.safetensors"  # a model file of the old one-file format, or any file
    junk.write_bytes(b"\x00" * 100)
    with pytest.raises(ModelError, match="not a keyfill model \\(expected a folder with config.json"):
        T.load(junk)
    cut = tmp_path / "cut"
    shutil.copytree(out, cut)
    weights = (cut / "weights.safetensors").read_bytes()
    (cut / "weights.safetensors").write_bytes(weights[: len(weights) // 2])
    with pytest.raises(ModelError, match="damaged or truncated weights"):
        T.load(cut)
    bad = tmp_path / "bad"
    shutil.copytree(out, bad)
    config = json.loads((bad / "config.json").read_text())
    del config["statistics"]
    (bad / "config.json").write_text(json.dumps(config))
    with pytest.raises(ModelError, match="bad.config.json: statistics is missing"):
        T.load(bad)
    config = json.loads((out / "config.json").read_text())
    (bad / "config.json").write_text(json.dumps({**config, "kind": "arnn"}))
    with pytest.raises(ModelError, match="a 'arnn' model, not a 'transformer' model"):
        T.load(bad)
    config["architecture"]["layers"] = 3
    (bad / "config.json").write_text(json.dumps(config))
    with pytest.raises(ModelError, match="the weights do not fit the model's configuration"):
        T.load(bad)


def test_a_model_of_another_kind_is_one_clear_error(trained, tmp_path, capsys):
    from keyfill.learn.arnn.model import DEFAULT_MODEL

    out, _ = trained
    src = tmp_path / "walk.bvh"
    io.save(walker_motion(walker_skeleton(), 40, np.random.default_rng(2)), src)
    args = ["complete", str(src), "-o", str(tmp_path / "o.bvh"), "--keys", "0,20,39"]
    assert main([*args, "--method", "transformer", "--model", str(DEFAULT_MODEL)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"keyfill: error: {DEFAULT_MODEL}: a model of kind 'arnn', not 'transformer'; complete with --method arnn"
    assert main([*args, "--method", "arnn", "--model", str(out)]) == 2
    assert capsys.readouterr().err.strip().endswith("a model of kind 'transformer', not 'arnn'; complete with --method transformer")
    assert main(["evaluate", str(out), str(tmp_path), "--protocol", "keys"]) == 2
    assert capsys.readouterr().err.strip() == (f"keyfill: error: {out}: a model of kind 'transformer' is scored "
                                               "with --protocol lafan1, not keys")
    assert main(["evaluate", str(DEFAULT_MODEL), str(tmp_path), "--protocol", "lafan1"]) == 2
    assert "a model of kind 'arnn' is scored with --protocol keys, not lafan1" in capsys.readouterr().err
    assert not (tmp_path / "o.bvh").exists()


def test_cli_train_transformer(corpus_dir, tmp_path, capsys):
    config = tmp_path / "tiny.json"
    config.write_text(json.dumps({"model": {k: v for k, v in TINY.__dict__.items()},
                                  "training": {**TINY_TRAINING.__dict__, "epochs": 1}}))
    out = tmp_path / "m"
    code = main(["-q", "train", "transformer", str(corpus_dir), "-o", str(out) + "/", "--config", str(config),
                 "--exclude", "*_calm_*", "--json"])
    assert code == 0, capsys.readouterr().err
    info = json.loads(capsys.readouterr().out)
    assert info["corpus_clips"] == 8 and info["epochs"] == 1 and (out / "config.json").is_file()
    assert info["checkpoint"] == str(tmp_path / "m.checkpoint.pt") and info["log"] == str(tmp_path / "m.log.jsonl")
    assert (tmp_path / "m.checkpoint.pt").is_file() and (tmp_path / "m.log.jsonl").is_file()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["train", "transformer", str(empty), "-o", str(tmp_path / "x")]) == 1
    assert "keyfill: error: no BVH files in" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text('{"model": {"layers": 2, "colour": 3}}')
    assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "x"), "--config", str(bad)]) == 2
    assert "colour" in capsys.readouterr().err
    bad.write_text('{"model": {"prefill": "spline"}}')  # a value the model refuses: the same kind of line
    assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "x"), "--config", str(bad)]) == 2
    assert capsys.readouterr().err == f"keyfill: error: {bad}: prefill must be one of interpolation, cubic, velocity, not 'spline'\n"
    for text, message in (('{"training": {"gap_sampling": "short"}}', "unknown gap_sampling 'short'"),
                          ('{"training": {"relative_loss": 3}}', "relative_loss must be true or false, not 3"),
                          ('{"model": {"key_distances": "yes"}}', "key_distances must be true or false, not 'yes'")):
        bad.write_text(text)
        assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "x"), "--config", str(bad)]) == 2
        assert capsys.readouterr().err.startswith(f"keyfill: error: {bad}: {message}")
    # an output that is not a model is refused before any training, and left alone
    (empty / "notes.txt").write_text("mine")
    assert main(["train", "transformer", str(corpus_dir), "-o", str(empty), "--config", str(config)]) == 2
    assert capsys.readouterr().err.strip() == (f"keyfill: error: {empty}: exists and is not a keyfill model; "
                                               "refusing to replace it")
    assert [p.name for p in empty.iterdir()] == ["notes.txt"] and not (tmp_path / "empty.log.jsonl").exists()
    assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "nowhere" / "m")]) == 2
    assert "the output folder" in capsys.readouterr().err
    # --init: a model folder to start from; anything else is one clear line
    assert main(["-q", "train", "transformer", str(corpus_dir), "-o", str(tmp_path / "t"), "--config", str(config),
                 "--exclude", "*_calm_*", "--init", str(out), "--json"]) == 0, capsys.readouterr().err
    assert json.loads(capsys.readouterr().out)["init"]["model"] == "m"
    assert main(["train", "transformer", str(corpus_dir), "-o", str(tmp_path / "u"), "--config", str(config),
                 "--init", str(empty)]) != 0
    err = capsys.readouterr().err
    assert err.startswith("keyfill: error:") and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_cli_evaluate_a_model(trained, corpus_dir, capsys):
    out, model = trained
    code = main(["evaluate", str(out), str(corpus_dir), "--test-pattern", "*_calm_*", "--lengths", "5,15", "--json"])
    assert code == 0, capsys.readouterr().err
    res = json.loads(capsys.readouterr().out)["results"]
    assert set(res) == {out.name, "zero-velocity", "interpolation"}
    from keyfill.learn.protocols import lafan1 as B

    proto = B.lafan1([corpus_dir], ["*_calm_*"], fold=True, cache=False)
    lib = B.evaluate({"m": model.benchmark_method()}, proto.test, proto.stats, (5, 15))
    assert res[out.name]["15"]["L2Q"] == pytest.approx(lib["m"][15]["L2Q"], rel=1e-9)


def test_output_fk_loss_is_zero_for_the_truth_and_positive_otherwise(corpus):
    cfg = TC.ModelConfig(**{**TINY.__dict__, "fk_weight": 1.0})
    torch.manual_seed(0)
    model = T.new_model(corpus.skeleton, cfg, np.zeros(24), np.full(24, 30.0), corpus.folded)
    q, r, _, _ = corpus.windows(65, 20)
    x, y, gq, gr, kinds = make_batch(model, q[:4], r[:4], np.append(np.arange(10), 30), 31)
    exact = TN.losses(model.features, y, y, gq, gr, kinds, cfg)
    assert float(exact["output_fk"]) < 1e-5 and float(exact["total"]) < 1e-4
    off = TN.losses(model.features, x, y, gq, gr, kinds, cfg)  # the interpolation
    assert float(off["output_fk"]) > 1e-3
    assert float(off["total"]) == pytest.approx(float(off["position"] + off["rotation"] + 0.01 * off["kinematics"]
                                                      + off["output_fk"]), rel=1e-6)


def test_a_missing_gpu_is_a_usage_error(trained):
    out, _ = trained
    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    with pytest.raises(UsageError, match="no CUDA GPU"):
        T.load(out, device="cuda")
    with pytest.raises(UsageError, match="unknown torch device"):
        T.load(out, device="gpu0")


# --- a matched start (issue 46) ------------------------------------------------------


def _same_rotations(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    return bool(np.all(np.abs(np.abs((a * b).sum(-1)) - 1.0) <= atol))


def test_a_zero_residual_gives_the_matched_start_and_without_one_the_prefill(corpus, corpus_dir):
    """A new residual model's correction is zero: started from a matched in-between it gives that in-between,
    and without one its pre-fill (here the cubic spline, not the take's linear interpolation it starts from),
    as when it completes that job alone: both kinds of job in one batch stay apart."""
    import dataclasses

    from keyfill import interpolate
    from keyfill.motion import Keys

    torch.manual_seed(0)
    cfg = dataclasses.replace(TINY, prefill="cubic")
    model = T.new_model(corpus.skeleton, cfg, np.zeros(24), np.full(24, 30.0), corpus.folded)
    motion = io.load(min(corpus_dir.rglob("*.bvh"))).frames(slice(0, 81)).replace(keys=None)
    keys = Keys([0, 20, 50, 80])
    rng = np.random.default_rng(0)  # a start that is neither the truth nor the interpolation
    between = np.setdiff1d(np.arange(81), keys.frames)
    rot, pos = motion.rotations.copy(), motion.positions.copy()
    rot[between] = R.quat_normalize(rot[between] + 0.05 * rng.standard_normal((len(between),) + rot.shape[1:]))
    pos[between, 0] += 0.02 * rng.standard_normal((len(between), 3))
    start = motion.replace(rotations=rot, positions=pos)
    (matched, _), (plain, _) = T.complete_motions(model, [(motion, keys), (motion, keys)], starts=[start, None])
    assert _same_rotations(matched.rotations, start.rotations, 1e-5)
    np.testing.assert_allclose(matched.positions[:, 0], start.positions[:, 0], atol=1e-4)
    (alone, _), = T.complete_motions(model, [(motion, keys)], batch=False)
    np.testing.assert_array_equal(plain.rotations, alone.rotations)
    np.testing.assert_array_equal(plain.positions, alone.positions)
    linear = interpolate.linear(motion, keys)
    assert not _same_rotations(plain.rotations, linear.rotations, 1e-3)
    assert not _same_rotations(plain.rotations, matched.rotations, 1e-3)


def test_a_start_of_other_frames_or_other_keys_is_refused(corpus, corpus_dir):
    from keyfill.errors import DataError
    from keyfill.motion import Keys

    model = T.new_model(corpus.skeleton, TINY, np.zeros(24), np.full(24, 30.0), corpus.folded)
    motion = io.load(min(corpus_dir.rglob("*.bvh"))).frames(slice(0, 81)).replace(keys=None)
    keys = Keys([0, 40, 80])
    short = motion.frames(slice(0, 80))
    moved = motion.replace(positions=motion.positions + 1.0)
    for start, words in ((short, "80 frames"), (moved, "positions at the keys")):
        (result,) = T.complete_motions(model, [(motion, keys)], starts=[start])
        assert isinstance(result, DataError) and words in str(result)


def _start_set(corpus, path, spacing=30):
    """A start set of the corpus's windows whose starts are the truth disturbed between the keys."""
    from keyfill.learn.transformer import starts

    keys = starts.layout(spacing, 65)
    T = int(keys[-1]) + 1
    q, r, _, _ = corpus.windows(T, 10)
    rng = np.random.default_rng(1)
    sq, sr = q.copy(), r.copy()
    between = np.setdiff1d(np.arange(T), keys)
    sq[:, between] = R.quat_normalize(sq[:, between] + 0.1 * rng.standard_normal(sq[:, between].shape))
    sr[:, between] += 0.05 * rng.standard_normal(sr[:, between].shape)
    starts.save({f"truth_q_{spacing}": q.astype(np.float32), f"truth_r_{spacing}": r.astype(np.float32),
                 f"start_q_{spacing}": sq.astype(np.float32), f"start_r_{spacing}": sr.astype(np.float32)}, path)
    return q, r, sq, sr, keys


def test_a_start_batch_reads_the_start_and_aims_at_the_truth(corpus, tmp_path):
    from keyfill.learn.transformer.starts import make_batch as make_start_batch

    q, r, sq, sr, keys = _start_set(corpus, tmp_path / "starts.npz")
    model = T.new_model(corpus.skeleton, TINY, np.zeros(24), np.full(24, 30.0), corpus.folded)
    x, y, _, _, kinds = make_start_batch(model, q[:4], r[:4], sq[:4], sr[:4], keys)
    dq, _ = model.features.decode(x.double())
    tq, _ = model.features.decode(y.double())
    sign = np.where(q[:4, :1, :, :1] < 0, -1.0, 1.0)  # (the canonical turn is one rotation of the root)

    def dots(a, b):  # per joint below the root: |<a, b>| is 1 for one rotation
        return np.abs((np.asarray(a)[..., 1:, :] * np.asarray(b)[..., 1:, :]).sum(-1))

    assert np.all(np.abs(dots(dq, sq[:4] * sign) - 1) < 1e-4)  # the input: the start (joints below the root)
    assert np.all(np.abs(dots(tq, q[:4] * sign) - 1) < 1e-4)  # the target: the truth
    assert not np.all(np.abs(dots(dq, q[:4]) - 1) < 1e-4)
    assert (kinds[:, keys] == TF.KEY).all() and (kinds[:, 1:30] == TF.UNKNOWN).all()


def test_training_draws_matched_start_batches_only_when_asked(corpus, tmp_path):
    import dataclasses

    from keyfill.learn.transformer import starts

    _start_set(corpus, tmp_path / "starts.npz")
    cfg = dataclasses.replace(TINY_TRAINING, epochs=1, matched_starts=str(tmp_path / "starts.npz"),
                              matched_share=0.5)
    task = TransformerTask(corpus, TINY, cfg, seed=0)
    task.build(None)
    lengths = [b[0].shape[1] for e in range(5) for b in task.batches(e)]
    assert 61 in lengths and len(set(lengths)) > 1  # start batches (61 frames, keys every 30) among the others
    every = TransformerTask(corpus, TINY, dataclasses.replace(cfg, matched_share=1.0), seed=0)
    every.build(None)
    assert {b[0].shape[1] for b in every.batches(0)} == {61}
    off = TransformerTask(corpus, TINY, TINY_TRAINING, seed=0)
    assert off.starts is None and "matched_share" not in TINY_TRAINING.recorded()
    with pytest.raises(UsageError, match="spacing 30 is not 5 joints"):
        starts.load(tmp_path / "starts.npz", 5)
    with pytest.raises(UsageError, match="name a start set"):
        TrainConfig(matched_share=0.5)


@pytest.mark.parametrize("layout", [{}, {"unknown_input": "zero", "velocity_input": True}])
def test_a_zero_residual_gives_the_interpolation_it_corrects(corpus, corpus_dir, layout):
    """The output is a correction of the pre-fill: a new residual model (its output layer zero) gives the linear
    interpolation of the keys back, to the float32 precision of the features, also when the network reads
    zeros and a mask in place of it (issue 46's delta from interpolation)."""
    from keyfill import interpolate
    from keyfill.motion import Keys

    cfg = TC.ModelConfig(**{**TINY.__dict__, **layout})
    model = T.new_model(corpus.skeleton, cfg, np.zeros(24), np.full(24, 30.0), corpus.folded)
    motion = io.load(min(corpus_dir.rglob("*.bvh"))).frames(slice(0, 81)).replace(keys=None)
    keys = Keys([0, 20, 50, 80])
    ((done, _),) = T.complete_motions(model, [(motion, keys)], batch=False)
    linear = interpolate.linear(motion, keys)
    assert _same_rotations(done.rotations, linear.rotations, 1e-5)
    np.testing.assert_allclose(done.positions[:, 0], linear.positions[:, 0], atol=1e-4)
    assert not _same_rotations(done.rotations, motion.rotations, 1e-3)
