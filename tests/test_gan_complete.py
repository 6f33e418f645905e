"""Inference: exact keys, seeds that choose the noise, and the errors of ``complete``."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import fit, synthetic_corpus, tiny_config
from synthetic_corpus import walker_motion, walker_skeleton

from keyfill import io
from keyfill.errors import ModelError, UsageError
from keyfill.interpolate import linear
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.gan.model import complete, complete_motion, load_model
from keyfill.learn.gan.task import GanTask
from keyfill.learn.modelfile import save_model
from keyfill.motion import Keys

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """``(path-stage model, full model)`` folders, each trained for a handful of steps."""
    root = tmp_path_factory.mktemp("gan_models")
    corpus = synthetic_corpus(root / "clips", clips_per_style=2)
    cfg = tiny_config(max_frames=256, steps_per_epoch=3)
    path_dir = fit(GanTask(corpus, cfg, "path", epochs=1), root / "path").model
    full = fit(GanTask(corpus, cfg, "generator", path_model=path_dir, epochs=1), root / "full").model
    return path_dir, full


@pytest.fixture(scope="module")
def motion():
    """A 240-frame walk of the training skeleton (joint_Root on top, as in the corpus files)."""
    return walker_motion(walker_skeleton(), 240, np.random.default_rng(42))


KEYS = Keys(np.array([0, 50, 130, 200]))


def test_inference_hits_keys_exactly(models, motion):
    out = complete(motion, KEYS, CompleteOptions(model=str(models[1]), seed=3))
    m = out.motion
    assert m.num_frames == motion.num_frames and m.keys.to_list() == KEYS.to_list()
    k = KEYS.frames
    assert np.array_equal(m.rotations[k], motion.rotations[k])
    assert np.array_equal(m.positions[k], motion.positions[k])
    assert np.all(np.isfinite(m.rotations)) and np.allclose(np.linalg.norm(m.rotations, axis=-1), 1)
    assert out.info["exact_keys"] and out.info["seed"] == 3
    # outside the key range every frame holds the nearest key
    assert np.allclose(m.rotations[201:], motion.rotations[200])
    # only the hips move: the static joint_Root and every bone below the hips keep their offsets
    assert np.allclose(m.positions[:, 0], motion.positions[:, 0])
    assert np.allclose(m.positions[:, 2:], motion.positions[:, 2:])


def test_two_seeds_give_different_inbetweens_through_the_same_keys(models, motion):
    a = complete(motion, KEYS, CompleteOptions(model=str(models[1]), seed=1)).motion
    b = complete(motion, KEYS, CompleteOptions(model=str(models[1]), seed=2)).motion
    again = complete(motion, KEYS, CompleteOptions(model=str(models[1]), seed=1)).motion
    k = KEYS.frames
    assert np.array_equal(a.rotations[k], b.rotations[k]) and np.array_equal(a.positions[k], b.positions[k])
    between = np.setdiff1d(np.arange(k[0], k[-1]), k)
    assert np.abs(a.rotations[between] - b.rotations[between]).max() > 1e-3
    assert np.array_equal(a.rotations, again.rotations) and np.array_equal(a.positions, again.positions)


def test_joints_the_network_does_not_drive_are_interpolated(models, motion):
    model = load_model(models[1])
    out, info = complete_motion(model, motion, KEYS, seed=0)
    lin = linear(motion, KEYS)
    leaves = [motion.skeleton.index(n) for n in ("Head", "Foot_L", "Foot_R")]
    assert np.allclose(out.rotations[:, leaves], lin.rotations[:, leaves])
    assert info["frames_generated"] == 201


def test_keys_too_far_apart(models, motion):
    with pytest.raises(UsageError, match=r"keys 10 and 131 are 121 frames apart.*at most 120"):
        complete(motion, Keys(np.array([0, 10, 131])), CompleteOptions(model=str(models[1])))


def test_a_key_range_longer_than_max_frames_is_filled_by_windows(models):
    """301 frames of keys with a 256-frame model: two windows (tests/test_gan_long.py has the long takes)."""
    long = walker_motion(walker_skeleton(), 400, np.random.default_rng(1))
    keys = Keys(np.array([0, 100, 200, 300]))
    out = complete(long, keys, CompleteOptions(model=str(models[1])))
    assert out.info["windows"] == 2 and out.info["frames_generated"] == 301
    assert np.array_equal(out.motion.rotations[keys.frames], long.rotations[keys.frames])
    assert np.array_equal(out.motion.positions[keys.frames], long.positions[keys.frames])


def test_another_skeleton(models):
    other = walker_motion(walker_skeleton(leg_length=55.0), 100, np.random.default_rng(1))
    with pytest.raises(ModelError, match=r"another skeleton than the model \(\d+ joints, top joint '\w+'\): "
                                         r"the model's vs the motion's: joint '\w+' has a different rest offset; "
                                         r"train a gan model on your own clips with "
                                         r"'keyfill train gan CLIPS -o MODEL-path --stage path'"):
        complete(other, Keys(np.array([0, 60, 99])), CompleteOptions(model=str(models[1])))


def test_model_folder_of_another_kind_or_stage(models, motion, tmp_path):
    save_model(tmp_path / "tf", "transformer", {"w": torch.zeros(1)}, {"skeleton": motion.skeleton.to_json(hierarchy_only=True)})
    with pytest.raises(ModelError, match="'transformer' model, not a 'gan' model"):
        complete(motion, KEYS, CompleteOptions(model=str(tmp_path / "tf")))
    with pytest.raises(ModelError, match="stage 'path'"):
        complete(motion, KEYS, CompleteOptions(model=str(models[0])))
    with pytest.raises(ModelError, match=r"another skeleton than the model \(22 joints, top joint 'joint_Root'\)"):
        complete(motion, KEYS, CompleteOptions())  # the shipped model serves the Bandai-Namco skeleton


def test_written_file_round_trips(models, motion, tmp_path):
    out = complete(motion, KEYS, CompleteOptions(model=str(models[1]), seed=5)).motion
    io.save(out, tmp_path / "filled.bvh")
    back = io.load(tmp_path / "filled.bvh")
    assert back.num_frames == motion.num_frames
    assert np.allclose(back.world_positions()[KEYS.frames], motion.world_positions()[KEYS.frames], atol=1e-4)


def test_reads_only_the_key_frames(models, motion):
    rng = np.random.default_rng(0)
    noisy = motion.rotations.copy()
    others = np.setdiff1d(np.arange(motion.num_frames), KEYS.frames)
    noisy[others] = rng.normal(size=noisy[others].shape)
    noisy[others] /= np.linalg.norm(noisy[others], axis=-1, keepdims=True)
    pos = motion.positions.copy()
    pos[others] += rng.normal(size=pos[others].shape)
    scrambled = motion.replace(rotations=noisy, positions=pos)
    a = complete(motion, KEYS, CompleteOptions(model=str(models[1]), seed=4)).motion
    b = complete(scrambled, KEYS, CompleteOptions(model=str(models[1]), seed=4)).motion
    assert np.array_equal(a.rotations, b.rotations) and np.array_equal(a.positions, b.positions)


def test_benchmark_windows(models, motion):
    """The LaFAN1 protocol's hook: windows sharing keys, exact at the keys."""
    from keyfill.learn.corpus import fold_root

    model = load_model(models[1])
    q, p = fold_root(motion.rotations, motion.positions, motion.skeleton.parents)
    skel = model.skeleton
    quats = np.stack([q[0:65], q[40:105]])
    root = np.stack([p[0:65, 0], p[40:105, 0]])
    keys = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 40])
    method = model.benchmark_method()
    assert method.folded
    hidden_q, hidden_r = quats.copy(), root.copy()
    between = np.setdiff1d(np.arange(65), keys)
    hidden_q[:, between], hidden_r[:, between] = np.nan, np.nan  # as the protocol hands them over
    out_q, out_r = method(skel, hidden_q, hidden_r, keys)
    assert np.all(np.isfinite(out_q)) and np.all(np.isfinite(out_r))
    assert out_q.shape == quats.shape and out_r.shape == root.shape
    assert np.allclose(out_q[:, keys], quats[:, keys]) and np.allclose(out_r[:, keys], root[:, keys])


def test_generate_takes_an_optional_style_vector():
    """The Motion DNA hook: no style is a zero style; another style gives another motion."""
    from keyfill.learn.gan.model import GanModel, build_networks, generate
    from keyfill.learn.gan.ranges import estimate_ranges

    skel = walker_skeleton(static_root=False)
    walk = walker_motion(skel, 120, np.random.default_rng(0))
    ranges = estimate_ranges(skel, walk.rotations)
    cfg = tiny_config(style_dim=2)
    torch.manual_seed(0)
    nets = build_networks(skel, ranges, cfg)
    model = GanModel(cfg, skel, ranges, nets["generator"].eval(), nets["path"].eval())
    poses = np.random.default_rng(1).normal(size=(3, skel.num_joints, 3)) * 0.3
    frames = np.array([0, 50, 100])
    q0, r0 = generate(model, frames, poses, seed=0)
    qz, rz = generate(model, frames, poses, seed=0, style=np.zeros(2))
    q1, _ = generate(model, frames, poses, seed=0, style=np.ones(2))
    assert q0.shape == (101, skel.num_joints, 4) and r0.shape == (101, 3)
    assert np.array_equal(q0, qz) and np.array_equal(r0, rz)
    assert np.abs(q1 - q0).max() > 1e-4
