"""Long takes: the gan fills a key range of any length by overlapping windows (issue 44).

A window spans at most ``GanConfig.max_frames`` frames from a key to a key; consecutive windows share
frames, which are cross-faded; the keys stay exact. Nothing here is timed (docs/gan.md, "Long takes", has
the figures); the tiny models have 256-frame windows, so a 1,500-frame take has a dozen.
"""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import fit, synthetic_corpus, tiny_config, world
from synthetic_corpus import walker_motion, walker_skeleton
from test_gan_recipe2 import RECIPE2

from keyfill import io
from keyfill.errors import UsageError
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.gan import model as gan_model
from keyfill.learn.gan.long_takes import latent_steps, take_noise, windows
from keyfill.learn.gan.model import complete_motion, load_model
from keyfill.learn.registry import complete
from keyfill.motion import Keys

pytestmark = pytest.mark.usefixtures("one_torch_thread")

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "human" / "keys.usda"
#: the tiny models' window (frames): a 1,500-frame take needs a dozen of them
WINDOW = 256


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """``((folder, model) of the second recipe with Motion DNA and partial keys, of the first recipe with
    noise)``, each trained for a handful of steps, both with :data:`WINDOW`-frame windows."""
    from keyfill.learn.gan.task import GanTask

    root = tmp_path_factory.mktemp("gan_long")
    corpus = synthetic_corpus(root / "clips", clips_per_style=2)
    cfg = tiny_config(**{**RECIPE2, "max_frames": WINDOW, "steps_per_epoch": 2, "style_dim": 4, "dna_width": 8,
                         "partial_keys": True})
    path_dir = fit(GanTask(corpus, cfg, "path", epochs=1), root / "path").model
    full = fit(GanTask(corpus, cfg, "generator", path_model=path_dir, epochs=1), root / "full").model
    noisy_cfg = tiny_config(max_frames=WINDOW, steps_per_epoch=1)
    noisy_path = fit(GanTask(corpus, noisy_cfg, "path", epochs=1), root / "noisy_path").model
    noisy = fit(GanTask(corpus, noisy_cfg, "generator", path_model=noisy_path, epochs=1), root / "noisy").model
    return (full, load_model(full)), (noisy, load_model(noisy))


@pytest.fixture(scope="module")
def take():
    """A 1,500-frame walk of the training skeleton."""
    return walker_motion(walker_skeleton(), 1500, np.random.default_rng(44))


KEYS = Keys(np.r_[np.arange(3, 1490, 40), 1490])


def shared_frames(plan, k) -> list[tuple[int, int]]:
    """The frames ``(first, last)`` each pair of consecutive windows of ``plan`` shares."""
    return [(int(k[nxt[0]]), int(k[prev[1]])) for prev, nxt in itertools.pairwise(plan)]


# --- the windows --------------------------------------------------------------------------------


@pytest.mark.parametrize("every,max_frames,overlap", [(40, 256, 636), (60, 8192, 636), (7, 100, 30), (90, 400, 50)])
def test_windows_run_key_to_key_within_max_frames_and_overlap(every, max_frames, overlap):
    k = np.r_[np.arange(5, 50_000, every), 50_003]
    plan = windows(k, max_frames, overlap)
    assert plan[0][0] == 0 and plan[-1][1] == len(k) - 1
    for i, j in plan:
        assert j > i and k[j] - k[i] + 1 <= max_frames
        # as many keys as fit: the next key would not
        assert j == len(k) - 1 or k[j + 1] - k[i] + 1 > max_frames
    share = min(overlap, max_frames // 4)
    for (_, before), (i0, j0), (i1, j1) in zip([(0, 0), *plan], plan, plan[1:], strict=False):
        assert i0 < i1 <= j0 < j1 and i1 >= before  # no frame in three windows
        # they share at least `share` frames where the keys allow, and no key more than that needs
        assert k[j0] - k[i1] >= share or i1 in (i0 + 1, before)
        assert i1 == j0 or k[j0] - k[i1 + 1] < share
    # linear: the windows advance by at least max_frames minus the overlap and two gaps
    assert len(plan) <= 1 + (k[-1] - k[0]) / (max_frames - share - 2 * every)


def test_a_range_of_max_frames_is_one_window_and_a_gap_that_fills_a_window_shares_only_its_key():
    assert windows(np.array([0, 100, 255]), 256) == [(0, 2)]
    assert windows(np.array([7]), 256) == [(0, 0)]
    # gaps of 200 frames in 256-frame windows: no key lies in the overlap, so consecutive windows share a key
    assert windows(np.array([0, 200, 400, 600]), 256) == [(0, 1), (1, 2), (2, 3)]


# --- completing long takes ------------------------------------------------------------------


def test_a_long_take_is_its_windows_cross_faded(models, take):
    """Outside the shared frames the take holds each window completed on its own; where two windows overlap,
    the root moves from the earlier window's path to the later one's."""
    model = models[0][1]
    k = KEYS.frames
    out, info = complete_motion(model, take, KEYS, seed=4)
    plan = windows(k, WINDOW)
    assert info["windows"] == len(plan) >= 8 and info["frames_generated"] == k[-1] - k[0] + 1
    shared = shared_frames(plan, k)
    assert all(b - a >= WINDOW // 4 for a, b in shared)
    hips = take.skeleton.index("Hips")
    for n, (i, j) in enumerate(plan):
        alone, _ = complete_motion(model, take, Keys(k[i : j + 1]), seed=4)
        a = shared[n - 1][1] + 1 if n else k[0]  # after the fade-in from the previous window
        b = shared[n][0] if n < len(shared) else k[-1] + 1  # before the fade-out into the next
        np.testing.assert_allclose(out.rotations[a:b], alone.rotations[a:b], atol=1e-12)
        np.testing.assert_allclose(out.positions[a:b], alone.positions[a:b], atol=1e-9)
        if n:  # the fade from the previous window's path to this one's
            fa, fb = shared[n - 1]
            prev, _ = complete_motion(model, take, Keys(k[plan[n - 1][0] : plan[n - 1][1] + 1]), seed=4)
            p, p0, p1 = (m.positions[fa : fb + 1, hips] for m in (out, prev, alone))
            np.testing.assert_allclose(p[0], p0[0], atol=1e-9)
            np.testing.assert_allclose(p[-1], p1[-1], atol=1e-9)
            along = np.linalg.norm(p - p0, axis=-1) + np.linalg.norm(p1 - p, axis=-1)
            np.testing.assert_allclose(along, np.linalg.norm(p1 - p0, axis=-1), atol=1e-6)
            assert np.linalg.norm(p1 - p0, axis=-1).max() > 1.0  # the windows differ there (cm): a fade to test


@pytest.mark.parametrize("which", [0, 1], ids=["dna", "noise"])
def test_seams_are_no_rougher_than_the_windows(models, take, which, monkeypatch):
    """The largest joint acceleration where windows meet is within that of the frames inside windows (a window
    written over its predecessor without the fade jumps there)."""
    model = models[which][1]
    filled, _ = complete_motion(model, take, KEYS, seed=2)
    acc = np.linalg.norm(np.diff(world(filled), 2, axis=0), axis=-1).max(-1)  # (F - 2,) per frame, cm
    k = KEYS.frames
    seam = np.zeros(len(acc), bool)
    for a, b in shared_frames(windows(k, WINDOW), k):
        seam[a - 1 : b] = True
    inside = ~seam
    inside[: k[0]] = inside[k[-1] - 1 :] = False
    assert acc[seam].max() <= 1.5 * acc[inside].max()
    # the same take with each window simply written over the last shows the seams this guards against
    monkeypatch.setattr(gan_model, "windows", lambda k, m: windows(k, m, overlap=0))  # share only boundary keys
    hard, _ = complete_motion(model, take, KEYS, seed=2)
    hard_acc = np.linalg.norm(np.diff(world(hard), 2, axis=0), axis=-1).max(-1)
    assert hard_acc[seam].max() > 1.5 * acc[inside].max()


@pytest.mark.parametrize("which", [0, 1], ids=["dna", "noise"])
def test_a_long_take_is_deterministic_and_the_seed_changes_it(models, take, which):
    model = models[which][1]
    a, info = complete_motion(model, take, KEYS, seed=1)
    again, _ = complete_motion(model, take, KEYS, seed=1)
    other, _ = complete_motion(model, take, KEYS, seed=2)
    assert info["windows"] > 1
    assert np.array_equal(a.rotations, again.rotations) and np.array_equal(a.positions, again.positions)
    # another DNA from the bank (a tiny model barely listens to it), or other noise
    assert np.abs(a.rotations - other.rotations).max() > (1e-3 if model.config.noise_dim else 1e-7)


def test_a_noisy_models_take_has_one_draw_of_noise_over_its_windows(models):
    """A range of one window gets the noise ``generate`` draws from the seed (its bytes as before windows
    existed); a long take one draw over the latent steps its windows reach, which they share where they
    overlap, not a fresh draw from the seed each."""
    model = models[1][1]
    k = KEYS.frames
    for keys in (k[:6], k):
        plan = windows(keys, WINDOW)
        noise = take_noise(model.config.noise_dim, keys, plan, 3)
        i, j = plan[-1]
        steps = (keys[i] - keys[0]) // 64 + latent_steps(int(keys[j] - keys[i]) + 1)
        assert noise.shape == (1, model.config.noise_dim, steps)
        assert np.array_equal(noise, torch.randn(noise.shape, generator=torch.Generator().manual_seed(3)).numpy())
    assert take_noise(0, k, windows(k, WINDOW), 3) is None  # a noise-free model


def test_keys_stay_exact_and_partial_keys_need_a_root_in_every_window(models, take):
    model = models[0][1]
    done = complete(take, KEYS, "gan", CompleteOptions(model=str(models[0][0]), seed=0))
    k = KEYS.frames
    assert done.info["windows"] > 1
    assert np.array_equal(done.motion.rotations[k], take.rotations[k])
    assert np.array_equal(done.motion.positions[k], take.positions[k])
    # partial keys: half-body keys everywhere, the root only at the first keys: later windows have no anchor
    J = take.num_joints
    mask = np.zeros((len(k), J), bool)
    mask[:, 4:] = True
    mask[:3, :2] = True
    with pytest.raises(UsageError, match=r"root's position .* keys \d+-\d+ give none"):
        complete_motion(model, take, Keys(k, mask=mask.copy()), seed=0)
    mask[:, :2] = True  # the root at every key: fine
    out, info = complete_motion(model, take, Keys(k, mask=mask), seed=0)
    assert info["windows"] > 1 and np.all(np.isfinite(out.rotations))


def test_gaps_longer_than_max_gap_are_still_refused(models, take):
    with pytest.raises(UsageError, match="fills gaps of at most 120 frames"):
        complete_motion(models[1][1], take, Keys(np.array([0, 100, 300])), seed=0)


# --- the shipped model -----------------------------------------------------------------------


def test_the_shipped_gan_completes_20000_frames_with_exact_keys():
    if gan_model.DEFAULT_MODEL is None:
        pytest.skip("needs the shipped gan model (the distribution models/bandai)")
    example = io.load(EXAMPLE)
    reps = -(-20_000 // example.num_frames)
    step = example.positions[-1, 0] - example.positions[0, 0]
    step["XYZ".index(example.skeleton.up_axis)] = 0.0  # along the ground
    pos = np.concatenate([example.positions + n * step * (np.arange(example.num_joints) == 0)[:, None]
                          for n in range(reps)])[:20_000]
    motion = example.replace(rotations=np.concatenate([example.rotations] * reps)[:20_000], positions=pos, keys=None)
    keys = Keys(np.r_[np.arange(0, 20_000, 60), 19_999])
    start = time.process_time()
    done = complete(motion, keys, "gan", CompleteOptions(seed=1))
    print(f"20,000 frames: {time.process_time() - start:.1f} s of CPU ({done.info.get('runtime', 'torch')})")
    m, k = done.motion, keys.frames
    assert m.num_frames == 20_000 and done.info["windows"] == 3
    assert np.array_equal(m.rotations[k], motion.rotations[k]) and np.array_equal(m.positions[k], motion.positions[k])
    assert np.all(np.isfinite(m.rotations)) and np.allclose(np.linalg.norm(m.rotations, axis=-1), 1)
    assert np.abs(np.diff(m.positions[:, 0], axis=0)).max() < 50.0  # cm per frame: no jumps at the seams
