"""Style augmentation of training windows: torso postures and slower tempos (issue 30)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from test_humanoid_roles import family
from test_mirror import walk, world

from keyfill import rotations as R
from keyfill.characters.humanoid import map_roles
from keyfill.errors import DataError, UsageError
from keyfill.learn import augment as A
from keyfill.learn.corpus import Corpus
from keyfill.learn.transformer import config as TC
from keyfill.learn.transformer.task import TrainConfig, TransformerTask

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def windows(skeleton, count: int = 6, frames: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """``count`` seeded walks of ``frames`` frames as windows ``(B, T, J, 4)``, ``(B, T, 3)``."""
    parts = [walk(skeleton, frames, seed) for seed in range(count)]
    return np.stack([q for q, _ in parts]), np.stack([r for _, r in parts])


def test_posture_joints_are_the_torso_above_the_hips():
    sk = family("lafan1")
    roles = map_roles(sk)
    names = [sk.names[j] for j in A.posture_joints(sk)]
    expected = [sk.names[j] for j in (*roles.spine, *roles.neck, roles.head, roles.limbs["clavicle_l"],
                                      roles.limbs["clavicle_r"])]
    assert names == expected and len(names) >= 5
    with pytest.raises(DataError, match="posture_angle needs a humanoid skeleton"):  # no arms: no humanoid
        from synthetic_corpus import walker_skeleton

        A.posture_joints(walker_skeleton())


def test_posture_is_one_constant_turn_per_window_and_joint_and_leaves_the_legs_alone():
    sk = family("lafan1")
    q, r = windows(sk)
    joints = A.posture_joints(sk)
    out = A.perturb_posture(np.random.default_rng(0), q, joints, 0.35)
    others = np.setdiff1d(np.arange(sk.num_joints), joints)
    np.testing.assert_array_equal(out[:, :, others], q[:, :, others])
    turn = R.quat_mul(R.quat_conjugate(q[:, :, joints]), out[:, :, joints])  # q^-1 q' per frame
    turn = np.where(turn[..., :1] < 0, -turn, turn)
    np.testing.assert_allclose(turn, np.broadcast_to(turn[:, :1], turn.shape), atol=1e-12)  # the same every frame
    angles = R.quat_angle(q[:, :, joints], out[:, :, joints])
    assert angles.max() <= 0.35 + 1e-9 and angles.max() > 0.2 and np.ptp(angles[:, 0]) > 0.05
    # the feet do not move: world positions of every leg joint are unchanged
    legs = [map_roles(sk).limbs[f"{r}_{s}"] for r in ("thigh", "shin", "foot", "toe") for s in "lr"]
    before = np.stack([world(sk, q[b], r[b]) for b in range(len(q))])
    after = np.stack([world(sk, out[b], r[b]) for b in range(len(q))])
    np.testing.assert_allclose(after[:, :, legs], before[:, :, legs], atol=1e-9)
    assert np.abs(after[:, :, map_roles(sk).head] - before[:, :, map_roles(sk).head]).max() > 1.0  # cm


def test_retime_slows_half_the_windows_along_the_original_path():
    sk = family("lafan1")
    q, r = windows(sk, count=40)
    r = np.zeros_like(r) + np.arange(r.shape[1])[None, :, None] * np.array([3.0, 0.0, -1.0])  # 3 cm per frame in X
    contacts = np.zeros(r.shape[:2] + (2,), dtype=bool)
    contacts[:, ::2, 0] = True  # even frames in contact
    out_q, out_r, out_c = A.retime(np.random.default_rng(1), q, r, 0.6, contacts)
    assert out_q.shape == q.shape and out_r.shape == r.shape and out_c.shape == contacts.shape
    speed = np.diff(out_r[..., 0], axis=1) / 3.0  # the new frames' speed, constant per window
    np.testing.assert_allclose(speed, np.broadcast_to(speed[:, :1], speed.shape), atol=1e-9)
    kept = np.isclose(speed[:, 0], 1.0)
    assert 10 < kept.sum() < 30 and speed.min() >= 0.6 - 1e-9
    np.testing.assert_array_equal(out_q[kept], q[kept])  # speed 1 starts at frame 0: unchanged
    assert out_r[..., 0].min() >= 0 and out_r[..., 0].max() <= 3.0 * (r.shape[1] - 1) + 1e-9  # inside the window
    # rotations lie between the original neighbouring frames: the slowed window's first frame at t = start
    slow = np.flatnonzero(~kept)[0]
    t0 = out_r[slow, 0, 0] / 3.0
    i = int(np.floor(t0))
    expected = R.quat_slerp(q[slow, i], q[slow, i + 1], np.full(sk.num_joints, t0 - i))
    np.testing.assert_allclose(out_q[slow, 0], expected, atol=1e-12)
    # contacts come from the nearest original frame
    t = out_r[..., 0] / 3.0
    np.testing.assert_array_equal(out_c[..., 0], np.rint(t).astype(int) % 2 == 0)


def humanoid_corpus() -> Corpus:
    sk = family("lafan1")
    parts = [walk(sk, 90, seed) for seed in range(8)]
    starts = np.concatenate([[0], np.cumsum([90] * len(parts))]).astype(np.int64)
    return Corpus(skeleton=sk, files=tuple(f"walk_{i}.bvh" for i in range(len(parts))),
                  quats=np.concatenate([q for q, _ in parts]), root=np.concatenate([r for _, r in parts]),
                  starts=starts, fps=30.0, folded=False)


TINY = TC.ModelConfig(layers=1, d_model=16, heads=2, ffn=32, dropout=0.0, max_frames=65)
PLAIN = TrainConfig(epochs=1, batch_size=4, window=65, window_offset=5, val_fraction=0.0)


def batches(cfg: TrainConfig, corpus: Corpus, count: int = 3):
    task = TransformerTask(corpus, TINY, cfg, seed=2)
    task.build(None)
    out = []
    for i, batch in enumerate(task.batches(0)):
        if i == count:
            break
        out.append([t.numpy() for t in batch])
    return task, out


def test_training_windows_are_augmented_only_when_asked_and_deterministically():
    corpus = humanoid_corpus()
    task, plain = batches(PLAIN, corpus)
    assert task.posture is None and "posture_angle" not in PLAIN.recorded()  # off: older runs keep their bytes
    aug = dataclasses.replace(PLAIN, posture_angle=0.35, slowest_tempo=0.6)
    assert aug.recorded()["posture_angle"] == 0.35 and aug.recorded()["slowest_tempo"] == 0.6
    _, first = batches(aug, corpus)
    _, again = batches(aug, corpus)
    for a, b in zip(first, again):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
    # the first batch draws its layout before any augmentation: same shapes, other true rotations
    assert [x.shape for x in first[0]] == [x.shape for x in plain[0]]
    assert np.abs(first[0][2] - plain[0][2]).max() > 1e-3


def test_augmentation_settings_are_checked():
    with pytest.raises(UsageError, match="posture_angle"):
        TrainConfig(posture_angle=-0.1)
    with pytest.raises(UsageError, match="slowest_tempo"):
        TrainConfig(slowest_tempo=0.0)
    with pytest.raises(UsageError, match="slowest_tempo"):
        TrainConfig(slowest_tempo=1.5)
