"""Motion DNA that steers (issue 31, step 6; docs/gan.md): the normalised style vector, in-clip windows that take
their own clip's DNA, the settings' checks, and a DNA change that moves the output where a seed change does not."""

from __future__ import annotations

import json

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import fit, synthetic_corpus, tiny_config
from synthetic_corpus import walker_motion, walker_skeleton
from test_gan_spline_base import SPLINE

from keyfill import io
from keyfill.errors import UsageError
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.gan.config import GanConfig
from keyfill.learn.gan.dna import build_bank, draw_dna
from keyfill.learn.gan.network import DnaEncoder
from keyfill.learn.gan.poses import clip_pool
from keyfill.learn.gan.sampling import clip_window
from keyfill.learn.gan.task import GanTask
from keyfill.learn.gan.train_command import read_config
from keyfill.learn.registry import complete
from keyfill.motion import Keys

pytestmark = pytest.mark.usefixtures("one_torch_thread")

STEERING = {"dna_norm": True, "dna_source": "own", "style_dim": 4, "dna_width": 8}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return synthetic_corpus(tmp_path_factory.mktemp("steering"), clips_per_style=2)


def test_the_normalised_style_vector_has_zero_mean_and_unit_variance():
    torch.manual_seed(0)
    poses = torch.randn(5, 12, 3) * 0.02  # metres: representative poses are small numbers
    plain, normed = DnaEncoder(12, 16, 8), DnaEncoder(12, 16, 8, normalise=True)
    normed.load_state_dict(plain.state_dict())
    w, n = plain(poses), normed(poses)
    assert torch.allclose(n.mean(-1), torch.zeros(5), atol=1e-5)
    assert torch.allclose(n.var(-1, unbiased=False), torch.ones(5), atol=1e-3)
    assert torch.allclose(n, (w - w.mean(-1, keepdim=True)) / w.std(-1, unbiased=False, keepdim=True), atol=1e-3)
    assert w.std().item() < 0.5 * n.std().item()  # unnormalised, the vector is far smaller


def test_windows_with_their_own_dna_draw_the_poses_of_their_clip(corpus):
    _, first = np.unique(clip_pool(corpus).lengths, return_index=True)
    clips = np.sort(first)  # clips of different lengths: a whole-clip window's length tells its clip
    pool, bank = clip_pool(corpus, clips), build_bank(corpus, clips)
    lengths = pool.lengths
    assert len(clips) >= 4
    seen = {"own": [], "any": []}
    for source, found in seen.items():
        cfg = tiny_config(dna_width=8, style_dim=4, dna_source=source, window_frames=256, max_key_every=60)
        rng = np.random.default_rng(3)
        for _ in range(40):
            w = clip_window(pool, rng, cfg, bank=bank)
            n = int(w["valid"].sum())
            if n not in lengths:  # a LaFAN1-layout window: a part of its clip
                continue
            own = bank.poses[bank.clips == int(np.flatnonzero(lengths == n)[0])]
            found.append(all(np.any(np.all(own == p, axis=(1, 2))) for p in w["dna"]))
    assert len(seen["own"]) >= 10 and all(seen["own"])
    assert not all(seen["any"])  # the old draw takes any clip's poses


def test_the_key_dna_is_the_most_representative_key_poses():
    from keyfill.learn.gan.dna import key_dna
    from keyfill.learn.representative import pick_frames, root_free_poses, rotation_change

    s = walker_skeleton()
    q = walker_motion(s, 120, np.random.default_rng(1)).rotations[::20]  # 6 keys
    off = s.offsets * s.meters_per_unit
    got = key_dna(q, off, s.parents, 2)
    assert got.shape == (2, s.num_joints - 1, 3) and got.dtype == np.float32
    assert np.allclose(got, root_free_poses(q[pick_frames(rotation_change(q), 2)], off, s.parents), atol=1e-6)
    assert key_dna(q, off, s.parents, 50).shape[0] == 6  # at most one pose per key
    assert np.array_equal(key_dna(np.stack([q, q[::-1]]), off, s.parents, 2)[0], got)  # per window when batched


def test_draw_dna_of_a_given_clip():
    from keyfill.errors import DataError
    from keyfill.learn.gan.dna import DnaBank

    bank = DnaBank(np.arange(5 * 2 * 3, dtype=np.float32).reshape(5, 2, 3), np.array([0, 0, 1, 1, 1]))
    got = draw_dna(bank, np.random.default_rng(0), 3, clip=1)
    assert sorted(got[:, 0, 0].tolist()) == [12.0, 18.0, 24.0]  # the three poses of clip 1, none repeated
    with pytest.raises(DataError, match="no pose of clip 2"):
        draw_dna(bank, np.random.default_rng(0), 1, clip=2)


def test_later_settings_stay_out_of_old_configs_and_need_their_features(tmp_path):
    plain = GanConfig()
    assert not {"dna_norm", "dna_source", "sketch_stretch"} & set(plain.to_json())  # old folders keep their bytes
    assert GanConfig.from_json(plain.to_json()) == plain
    steer = GanConfig(dna_width=8, style_dim=4, dna_norm=True, dna_source="own")
    assert steer.to_json()["dna_norm"] is True and GanConfig.from_json(steer.to_json()) == steer
    with pytest.raises(UsageError, match="need a Motion DNA encoder"):
        GanConfig(dna_norm=True)
    with pytest.raises(UsageError, match="dna_source.*any, own"):
        GanConfig(dna_width=8, style_dim=4, dna_source="other")
    f = tmp_path / "steer.json"
    f.write_text(json.dumps({"dna_norm": True, "dna_source": "own"}))
    cfg = read_config(f, dna=True)  # --dna gives the encoder before the file's DNA settings are checked
    assert cfg.dna and cfg.dna_norm and cfg.dna_source == "own"
    with pytest.raises(UsageError, match=r"steer.json: dna_norm and dna_source need"):
        read_config(f)


def test_a_dna_change_moves_the_output_where_a_seed_change_does_not(corpus, tmp_path):
    """At evaluation settings (no noise) the seed only draws a DNA when none is given; given one, the output is
    the DNA's: two seeds give the same bytes, two DNAs different in-betweens (the keys exact in both)."""
    cfg = tiny_config(**{**SPLINE, **STEERING, "output_init": "small", "max_frames": 256, "steps_per_epoch": 3,
                         "noise_dim": 0})
    model = str(fit(GanTask(corpus, cfg, "generator", epochs=1), tmp_path / "steer").model)
    motion = walker_motion(walker_skeleton(), 240, np.random.default_rng(42))
    other = walker_motion(walker_skeleton(), 200, np.random.default_rng(7))
    io.save(other, tmp_path / "a.bvh")
    io.save(other.replace(rotations=np.roll(other.rotations, 1, axis=1)), tmp_path / "b.bvh")  # joints swapped
    keys = Keys(np.array([0, 60, 140, 220]))

    def run(seed, dna):
        return complete(motion, keys, "gan", CompleteOptions(model=model, seed=seed, feet="free",
                                                             dna=dna and str(tmp_path / dna))).motion.rotations

    a1, a2, b1 = run(1, "a.bvh"), run(2, "a.bvh"), run(1, "b.bvh")
    assert np.array_equal(a1, a2)
    # without a DNA such a model takes its keys' own poses, not a seed's draw from the bank
    assert np.array_equal(run(1, None), run(2, None)) and not np.array_equal(run(1, None), a1)
    between = np.setdiff1d(np.arange(221), keys.frames)
    assert np.abs(a1[between] - b1[between]).max() > 1e-4
    assert np.array_equal(a1[keys.frames], b1[keys.frames])
