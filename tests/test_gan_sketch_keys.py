"""2-D keys drawn as casual stick figures (issue 31, step 8; section 5.3; docs/gan.md "Partial keys"): the stretched
sketch, training data whose key losses keep the true poses, and the refusals."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import built, synthetic_corpus, tiny_config

from keyfill.errors import UsageError
from keyfill.learn.gan.config import GanConfig
from keyfill.learn.gan.poses import clip_pool, relative_positions
from keyfill.learn.gan.sampling import SKETCH_SHARE, clip_window, sketch_poses, training_sequence
from keyfill.learn.gan.task import GanTask

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return synthetic_corpus(tmp_path_factory.mktemp("sketch"), clips_per_style=2)


def _bones(poses, parents):
    rel = poses.copy()
    rel[:, 0] = 0.0
    return np.stack([rel[:, j] - rel[:, parents[j]] for j in range(1, len(parents))], axis=1)


def test_a_sketch_stretches_each_bone_along_itself_and_keeps_the_root(corpus):
    s = corpus.skeleton
    poses = relative_positions(corpus.quats[:6], s.offsets * s.meters_per_unit, s.parents)
    poses[:, 0] = corpus.root[:6] * s.meters_per_unit
    drawn = sketch_poses(np.random.default_rng(0), poses, s.parents, 0.3)
    assert np.array_equal(drawn[:, 0], poses[:, 0])
    a, b = _bones(poses, s.parents), _bones(drawn, s.parents)
    long = np.linalg.norm(a, axis=-1) > 1e-6
    ratio = np.linalg.norm(b, axis=-1)[long] / np.linalg.norm(a, axis=-1)[long]
    assert ratio.min() >= np.exp(-0.3) - 1e-9 and ratio.max() <= np.exp(0.3) + 1e-9
    assert ratio.std() > 0.05  # uneven: bones and keys each get their own stretch
    cos = (a * b).sum(-1)[long] / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))[long]
    assert np.allclose(cos, 1.0)  # each bone keeps its direction
    assert np.allclose(sketch_poses(np.random.default_rng(0), poses, s.parents, 0.0), poses)


@pytest.mark.parametrize("make", [training_sequence, clip_window])
def test_sketched_training_keys_keep_their_true_poses_for_the_losses(corpus, make):
    cfg = tiny_config(partial_keys=True, partial_fraction=1.0, sketch_stretch=0.3, in_clip_fraction=0.5,
                      window_frames=256, max_key_every=60)
    pool = clip_pool(corpus)
    J = corpus.skeleton.num_joints
    counts = {"plane": 0, "sketched": 0, "other": 0}
    rng = np.random.default_rng(5)
    for _ in range(60):
        a = make(pool, rng, cfg)
        shown, truth, mask = a["dense"][: 3 * J], a["key_truth"], a["dense"][3 * J :]
        given = mask.T.reshape(-1, J, 3)[a["key_mask"]] > 0.5
        plane = (~given).all(axis=(0, 1)).any()
        if not plane:
            counts["other"] += 1
            assert np.array_equal(shown, truth)  # only 2-D keys are ever sketched
            continue
        counts["plane"] += 1
        if np.array_equal(shown, truth):
            continue
        counts["sketched"] += 1
        k = np.flatnonzero(a["key_mask"])
        s_pos, t_pos = shown.T.reshape(-1, J, 3)[k], truth.T.reshape(-1, J, 3)[k]
        assert np.array_equal(s_pos[:, 0], t_pos[:, 0])  # the root stays where it is
        assert np.all(s_pos[~given] == 0) and np.all(t_pos[~given] == 0)  # the hidden axis is hidden in both
    assert counts["plane"] >= 10 and counts["other"] >= 10
    assert 0.25 < counts["sketched"] / counts["plane"] < 0.75  # about SKETCH_SHARE of them
    assert SKETCH_SHARE == 0.5


def test_the_key_targets_are_the_true_poses_of_a_sketch(corpus):
    cfg = tiny_config(partial_keys=True, partial_fraction=1.0, sketch_stretch=0.3, max_frames=256)
    task = GanTask(corpus, cfg, "path", epochs=1)
    J = corpus.skeleton.num_joints
    rng = np.random.default_rng(0)
    seq = task.sequences(rng, task.train_pool, 3)
    assert seq["key_truth"].shape == (3, 3 * J, cfg.sequence_frames)
    t = task.inputs(seq, "cpu")
    pose, _, coords = task.key_targets(t["dense"], t["key_mask"], t["key_root"], t["key_truth"])
    want = t["key_truth"].transpose(1, 2).reshape(3, -1, J, 3)
    assert torch.equal(pose, want)
    assert torch.equal(coords, t["dense"][:, 3 * J :].transpose(1, 2).reshape(3, -1, J, 3) > 0.5)
    built(task)  # a config with sketches builds its networks as any partial-key config


def test_sketches_need_partial_keys_and_stay_out_of_old_configs():
    with pytest.raises(UsageError, match="sketch_stretch .* needs partial_keys"):
        GanConfig(sketch_stretch=0.3)
    with pytest.raises(UsageError, match="sketch_stretch"):
        GanConfig(partial_keys=True, max_gap=300, sketch_stretch=2.0)
    assert "sketch_stretch" not in GanConfig(partial_keys=True, max_gap=300).to_json()
