"""The gan's second recipe (issue 31, docs/gan.md): each new setting against a hand-computed value, a fresh
generator that is not saturated, in-clip windows, the schedule and moving average, and old model folders."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import built, fit, synthetic_corpus, tiny_config

from keyfill.learn.gan import losses as L
from keyfill.learn.gan.config import GanConfig
from keyfill.learn.gan.features import dense_input
from keyfill.learn.gan.layers import ResidualConv
from keyfill.learn.gan.model import build_networks, generate, load_model
from keyfill.learn.gan.poses import clip_pool
from keyfill.learn.gan.sampling import LAFAN_CONTEXT, clip_window, training_sequence
from keyfill.learn.gan.task import GanTask

#: the settings of benchmarks/gan_recipe2.json that shape the networks and the data
RECIPE2 = {"noise_dim": 0, "residual_form": "variance", "output_init": "small", "upsampling": "linear",
           "root_input": "key-relative", "in_clip_fraction": 0.5, "window_frames": 128, "real_frames": 64,
           "optimizer": "adam", "lr_schedule": "cosine", "ema_decay": 0.9, "root_weight_schedule": "run",
           "recon_weight": 300.0, "foot_weight": 20.0, "max_key_every": 40, "output_smoothing": 0}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return synthetic_corpus(tmp_path_factory.mktemp("recipe2"), clips_per_style=2)


def test_the_shipped_recipe_file_names_only_real_settings():
    from pathlib import Path

    data = json.loads((Path(__file__).parents[1] / "benchmarks" / "gan_recipe2.json").read_text())
    cfg = GanConfig(**data)
    assert cfg.residual_form == "variance" and cfg.in_clip_fraction > 0 and cfg.noise_dim == 0


# --- layers -------------------------------------------------------------------------------------------------


def test_variance_form_of_eq6_has_unit_skip_gain():
    torch.manual_seed(0)
    x = torch.randn(2, 5, 16)
    layer = ResidualConv(5, 5, 3, 1, 1, ratio=0.25, form="variance")
    with torch.no_grad():
        h = layer.act(layer.conv(x) * layer.scale[:, None] + layer.bias[:, None])
        assert torch.allclose(layer(x), 0.5 * h + math.sqrt(0.75) * x, atol=1e-6)
    printed = ResidualConv(5, 5, 3, 1, 1, ratio=0.25)
    with torch.no_grad():  # the printed form's skip gain: sqrt(s) sqrt(1 - s) + sqrt(1 - s) = 1.30 at s = 1/4
        printed.conv.weight.zero_()
        printed.bias.zero_()
        assert torch.allclose(printed(x), (0.5 * math.sqrt(0.75) + math.sqrt(0.75)) * x, atol=1e-6)


def test_linear_up_sampling_has_no_checkerboard():
    torch.manual_seed(0)
    x = torch.ones(1, 4, 16)
    linear = ResidualConv(4, 4, 4, 2, 1, ratio=1.0, transpose=True, upsampling="linear")
    transposed = ResidualConv(4, 4, 4, 2, 1, ratio=1.0, transpose=True)
    with torch.no_grad():
        a, b = linear(x)[..., 2:-2], transposed(x)[..., 2:-2]
    assert a.shape[-1] == b.shape[-1] == 28
    assert float((a[..., 1:] - a[..., :-1]).abs().max()) < 1e-6  # a constant stays constant
    assert float((b[..., 1:] - b[..., :-1]).abs().max()) > 1e-3  # a period-2 pattern


def test_a_fresh_second_recipe_generator_is_not_saturated(corpus):
    from keyfill.learn.gan.ranges import estimate_ranges

    ranges = estimate_ranges(corpus.skeleton, corpus.quats)
    pool = clip_pool(corpus)
    shares = {}
    for name, cfg in (("first", GanConfig(sequence_frames=256, max_gap=120)),
                      ("second", GanConfig(sequence_frames=256, max_gap=120, **{**RECIPE2, "window_frames": 256}))):
        torch.manual_seed(0)
        G = build_networks(corpus.skeleton, ranges, cfg)["generator"]
        rng = np.random.default_rng(0)
        x = torch.as_tensor(np.stack([training_sequence(pool, rng, cfg)["dense"] for _ in range(2)]))
        noise = torch.randn(2, cfg.noise_dim, 4) if cfg.noise_dim else None
        with torch.no_grad():
            z = G.decoder(torch.cat([G.encoder(x)] + ([noise] if noise is not None else []), 1))
            raw = G(x, noise)[:, 6:]
        shares[name] = float((raw.abs() < 1).float().mean())
        if name == "second":  # activations neither fade nor explode through 19 layers
            assert 0.1 < float(z.std()) < 10  # PyTorch's default init with this form: 0.00 (docs/gan.md)
    assert shares["second"] > 0.95
    assert shares["second"] >= shares["first"]


# --- inputs and windows ---------------------------------------------------------------------------------------


def test_key_relative_root_input_is_zero_at_keys_and_keeps_the_height():
    frames = np.array([0, 10, 30])
    poses = np.zeros((3, 2, 3))
    poses[:, 0] = [[0.0, 0.9, 0.0], [1.0, 0.8, 0.0], [3.0, 0.9, 2.0]]
    x = dense_input(40, frames, poses, root="key-relative")
    root = x[:3]  # (3, T): the root's x, y, z
    assert np.allclose(root[[0, 2]][:, frames], 0)
    assert np.allclose(root[1], dense_input(40, frames, poses)[1])  # the height as it was
    # frame 4 takes key 0's root; the line between keys 0 and 1 is at 0.4 there
    assert np.isclose(root[0, 4], -0.4)
    assert np.isclose(root[0, 16], 1.0 - (1.0 + 2.0 * 6 / 20))  # nearest key 1, the line at 1.6
    assert np.allclose(root[[0, 2], 31:], 0)  # past the last key: on it


def test_in_clip_windows_hold_the_truth_their_keys_and_contacts(corpus):
    from keyfill.learn.gan.labels import content_of

    cfg = tiny_config(**RECIPE2)
    pool = clip_pool(corpus, labels=True)
    assert list(pool.groups) == [0, 0, 1, 1, 2, 2]  # synthetic_walk_{style}_{id}: one content per style
    assert len(pool.foot_joints) == 0  # the synthetic skeleton has no thighs and knees to find legs by
    pool = dataclasses.replace(pool, foot_joints=np.array([5, 7]),
                               contacts=tuple(np.ones((len(r), 2), bool) for r in pool.root))
    assert content_of("dataset-2_walk-turn-left_feminine_001.bvh") == "walk-turn-left"
    assert content_of("run_03.bvh") == "run"
    rng = np.random.default_rng(3)
    lafan = 0
    for _ in range(40):
        w = clip_window(pool, rng, cfg)
        k = np.flatnonzero(w["key_mask"])
        L_ = int(w["valid"].sum())
        assert w["valid"][:L_].all() and k[0] == 0 and k[-1] == L_ - 1
        assert w["dense"].shape == (6 * corpus.skeleton.num_joints, cfg.window_frames)
        joints = w["dense"][: 3 * corpus.skeleton.num_joints].T.reshape(cfg.window_frames, -1, 3)[:, 1:]
        assert np.allclose(joints[k], w["truth"][k, 1:], atol=1e-6)  # the keys are the truth's poses
        assert not w["contact"][L_:].any()
        gaps = np.diff(k)
        lafan += bool(len(k) == LAFAN_CONTEXT + 1 and (gaps[:-1] == 1).all())
        if len(k) != LAFAN_CONTEXT + 1:
            assert gaps.max() <= max(cfg.max_key_every, 60)
    assert 0 < lafan < 40
    # the same draws, the same window
    a, b = (clip_window(pool, np.random.default_rng(9), cfg) for _ in range(2))
    assert all(np.array_equal(a[n], b[n]) for n in a)


# --- the two new loss terms ---------------------------------------------------------------------------------


def test_reconstruction_loss_matches_a_hand_computed_value():
    pos = torch.zeros(2, 4, 3, 3)
    truth = torch.zeros(2, 4, 3, 3)
    truth[0, 1, 1] = torch.tensor([0.3, 0.0, 0.4])  # 0.25 m^2 on joint 1 at frame 1
    truth[0, 2, 2, 1] = 0.2  # 0.04 m^2 on joint 2 at frame 2
    truth[0, 3, 1, 0] = 5.0  # a key frame: not counted
    truth[1, 1, 0] = 9.0  # the root: not counted
    key = torch.tensor([[True, False, False, True], [True, False, False, True]])
    valid = torch.tensor([[True, True, True, True], [True, True, False, False]])
    # row 0: frames 1, 2 between keys, joints 1-2: (0.25 / 2 + 0.04 / 2) / 2 = 0.0725; row 1: frame 1, 0
    assert math.isclose(float(L.reconstruction_loss(pos, truth, key, valid)), (0.0725 + 0.0) / 2, rel_tol=1e-6)
    # loss_form "distance": the distances 0.5 and 0.2 m in place of their squares: (0.5 / 2 + 0.2 / 2) / 2 / 2
    got = float(L.reconstruction_loss(pos, truth, key, valid, "distance"))
    assert math.isclose(got, (0.175 + 0.0) / 2, abs_tol=2e-4)  # sqrt(d^2 + 1e-8): 1e-4 m at d = 0
    none = torch.ones(2, 4, dtype=torch.bool)
    assert float(L.reconstruction_loss(pos, truth, none, valid)) == 0.0


def test_foot_sliding_loss_matches_a_hand_computed_value():
    T = 4
    root = torch.zeros(1, T, 3)
    root[0, :, 0] = torch.tensor([0.0, 0.1, 0.2, 0.3])  # the body moves 0.1 m a frame along x
    rel = torch.zeros(1, T, 3, 3)
    rel[0, :, 1, 0] = torch.tensor([0.0, -0.1, -0.2, -0.2])  # joint 1 holds still on frames 0-2
    rel[0, :, 1, 1] = torch.tensor([0.0, 0.5, 0.0, 0.0])  # height changes do not count
    rel[0, :, 2, 2] = torch.tensor([0.0, 0.0, 0.0, 0.05])
    contact = torch.tensor([[[True, True], [True, True], [True, True], [False, True]]])
    # pairs in contact: joint 1 at (0,1), (1,2): speeds 0, 0; joint 2 at (0,1), (1,2), (2,3): 3 m/s along x each
    # pair, and 1.5 m/s along z in the last: (9 + 9 + 9 + 2.25) / 5 at 30 fps
    got = float(L.foot_sliding_loss(root, rel, torch.tensor([1, 2]), contact, 30.0, up=1))
    assert math.isclose(got, (0 + 0 + 9 + 9 + 9 + 2.25) / 5, rel_tol=1e-5)
    got = float(L.foot_sliding_loss(root, rel, torch.tensor([1, 2]), contact, 30.0, 1, "distance"))  # speeds, m/s
    assert math.isclose(got, (0 + 0 + 3 + 3 + 45**0.5 / 2) / 5, abs_tol=2e-4)
    assert float(L.foot_sliding_loss(root, rel, torch.tensor([1, 2]), contact & False, 30.0, 1)) == 0.0


# --- schedule, moving average, root weight ------------------------------------------------------------------


def test_cosine_schedule_root_weight_and_moving_average(corpus, tmp_path):
    cfg = tiny_config(**RECIPE2, steps_per_epoch=10, lr_generator=1e-3, warmup_fraction=0.1)
    task = GanTask(corpus, cfg, stage="path", epochs=2)
    built(task)
    rates = [task.learning_rates(e, s, 10)["path"] for e in range(2) for s in range(10)]
    assert math.isclose(rates[0], cfg.lr_path / 2) and math.isclose(rates[1], cfg.lr_path)  # two warm-up steps
    assert all(a >= b for a, b in itertools.pairwise(rates[1:]))
    assert math.isclose(rates[-1], cfg.lr_path * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * 17 / 18))))
    assert cfg.root_weight(0, 100) == cfg.root_weight_start and cfg.root_weight(99, 100) == cfg.root_weight_end
    path = fit(task, tmp_path / "path").output
    gen = GanTask(corpus, cfg, stage="generator", path_model=path, epochs=1)
    G = built(gen)["generator"]
    before = {k: v.clone() for k, v in gen.ema.items()}
    with torch.no_grad():
        for p in G.parameters():
            p.add_(1.0)
    gen._update_ema(G)
    k = next(k for k, v in G.state_dict().items() if v.dtype.is_floating_point)
    assert torch.allclose(gen.ema[k], 0.9 * before[k] + 0.1 * G.state_dict()[k])


def test_second_recipe_trains_and_a_first_recipe_folder_loads_as_before(corpus, tmp_path):
    cfg = tiny_config(**RECIPE2)
    path = fit(GanTask(corpus, cfg, stage="path", epochs=1), tmp_path / "path").output
    task = GanTask(corpus, cfg, stage="generator", path_model=path, epochs=2)
    out = fit(task, tmp_path / "gen")
    row = out.history[-1]
    assert {"loss_recon", "window_error"} <= set(row)  # (no foot term: the synthetic skeleton has no legs)
    assert np.isfinite([v for v in row.values() if isinstance(v, float)]).all()
    model = load_model(out.output)
    assert model.config.residual_form == "variance"
    # the moving average is what the model keeps
    saved = model.generator.state_dict()
    assert all(torch.allclose(saved[k].float(), v.float()) for k, v in task.ema.items())

    # a folder written before the second recipe's settings existed: they take the first recipe's values
    first = GanTask(corpus, tiny_config(), stage="generator", path_model=path, epochs=1)
    old = fit(first, tmp_path / "old").output
    frames = np.array([0, 40, 90])
    poses = np.zeros((3, corpus.skeleton.num_joints, 3))
    poses[:, 0, 1] = 0.9
    expected = generate(load_model(old), frames, poses, seed=3)
    config = json.loads((old / "config.json").read_text())
    for name in RECIPE2:
        if name not in ("noise_dim", "real_frames", "max_key_every", "output_smoothing"):
            config["gan"].pop(name)
    (old / "config.json").write_text(json.dumps(config))
    again = generate(load_model(old), frames, poses, seed=3)
    assert all(np.array_equal(a, b) for a, b in zip(expected, again))


def test_clip_contacts_label_a_real_walk():
    from conftest import SHARED

    from keyfill.learn.corpus import load_corpus
    from keyfill.learn.gan.labels import clip_contacts

    walk = SHARED / "bvh_fixtures" / "dataset-1_walk_normal_002.bvh"
    if not walk.is_file():
        pytest.skip(f"needs {walk} (../shared/data)")
    corpus = load_corpus([walk], cache=False)
    labels, joints = clip_contacts(corpus, [0])
    names = [corpus.skeleton.names[j] for j in joints]
    assert names == ["Foot_L", "Toes_L", "Foot_R", "Toes_R"]
    share = labels[0].mean(0)
    assert labels[0].shape == (corpus.starts[1], 4) and (share > 0.1).all() and (share < 0.95).all()


def test_root_targets_are_the_key_roots_whatever_the_root_input(corpus, tmp_path):
    """Eq. 10's targets come from the batch's key roots: with root_input key-relative the dense input's root
    channels are offsets from the keys' line (0 at keys), which a root loss must not take as positions."""
    cfg = tiny_config(**RECIPE2)
    path = fit(GanTask(corpus, cfg, stage="path", epochs=1), tmp_path / "path").output
    tasks = [GanTask(corpus, dataclasses.replace(cfg, root_input=r), stage="generator", path_model=path, epochs=1)
             for r in ("key-relative", "centred")]
    rngs = [np.random.default_rng(4), np.random.default_rng(4)]  # the root input draws nothing: the same batches
    kinds = set()
    for _ in range(8):
        rel, cen = (t.generator_batch(r, t.train_pool).arrays for t, r in zip(tasks, rngs))
        kinds.add("truth" in rel)
        got, want = (t.key_targets(torch.as_tensor(a["dense"]), torch.as_tensor(a["key_mask"]),
                                    torch.as_tensor(a["key_root"]))[0][:, :, 0].numpy() for t, a in zip(tasks, (rel, cen)))
        m = rel["key_mask"]
        first_recipe = tasks[1].key_targets(torch.as_tensor(cen["dense"]), torch.as_tensor(cen["key_mask"]))[0]
        assert np.allclose(got[m], want[m], atol=1e-6)  # the same targets either way
        assert np.allclose(first_recipe[:, :, 0].numpy()[m], want[m], atol=1e-6)  # = the centred input's keys
        assert np.abs(rel["dense"][:, [0, 2]].transpose(0, 2, 1)[m]).max() < 1e-6  # the input is 0 there
        assert np.abs(got[m][:, [0, 2]]).max() > 0.05  # while the keys are spread over the ground
        if "truth" in rel:
            assert np.allclose(got[m], rel["truth"][:, :, 0][m], atol=1e-6)
    assert kinds == {True, False}  # windows and long sequences both checked
