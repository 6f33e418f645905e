"""The gan's spline base (``GanConfig.base = "spline"``, issue 31's third recipe; docs/gan.md): the base is keyfill's
cubic spline through RC-FK, a fresh model completes as the spline, training data carries the spline of its keys,
the graph takes the base, and the settings it cannot serve are refused."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from gan_helpers import built, fit, synthetic_corpus, tiny_config, world
from synthetic_corpus import walker_motion, walker_skeleton
from test_gan_recipe2 import RECIPE2

from keyfill import rotations as R
from keyfill.errors import UsageError
from keyfill.interpolate import cubic, cubic_arrays, linear
from keyfill.learn.completion import CompleteOptions
from keyfill.learn.gan.config import GanConfig
from keyfill.learn.gan.poses import clip_pool, relative_positions, turn
from keyfill.learn.gan.ranges import estimate_ranges, inside
from keyfill.learn.gan.rcfk import RCFK
from keyfill.learn.gan.sampling import clip_window, training_sequence
from keyfill.learn.gan.spline_base import heading_quat, spline_root, spline_values, turned_rotations
from keyfill.learn.gan.task import GanTask
from keyfill.learn.registry import complete
from keyfill.motion import Keys

pytestmark = pytest.mark.usefixtures("one_torch_thread")

SPLINE = {**RECIPE2, "base": "spline", "output_init": "zero"}


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return synthetic_corpus(tmp_path_factory.mktemp("spline"), clips_per_style=2)


@pytest.fixture(scope="module")
def models(corpus, tmp_path_factory):
    """``(fresh, trained)``: spline-base model folders, untrained (zero output layer) and after 2 steps."""
    root = tmp_path_factory.mktemp("spline_models")
    cfg = tiny_config(**{**SPLINE, "max_frames": 256, "steps_per_epoch": 2, "style_dim": 4, "dna_width": 8})
    task = GanTask(corpus, cfg, "generator", epochs=1)
    fresh = task.save(root / "fresh", built(task), [])
    trained = fit(GanTask(corpus, cfg, "generator", epochs=1), root / "trained").model
    from safetensors.numpy import load_file

    assert not any(k.startswith("path.") for k in load_file(trained / "weights.safetensors"))  # no predictor
    return fresh, trained


@pytest.fixture(scope="module")
def motion():
    return walker_motion(walker_skeleton(), 240, np.random.default_rng(42))


@pytest.mark.parametrize("up", ["Y", "Z"])
def test_heading_quat_turns_as_the_positions_turn(up):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(5, 3))
    for angle in (0.3, -2.0, 3.1):
        assert np.allclose(R.quat_rotate(np.broadcast_to(heading_quat(angle, up), (5, 4)), points),
                           turn(points, angle, up), atol=1e-12)


def test_turned_rotations_turn_the_pose_they_make(corpus):
    s = corpus.skeleton
    q = corpus.quats[:3]
    turned = turned_rotations(q, 0.7, s.up_axis)
    assert np.array_equal(turned[:, 1:], q[:, 1:])  # local rotations below the root stay
    assert np.allclose(relative_positions(turned, s.offsets, s.parents),
                       turn(relative_positions(q, s.offsets, s.parents), 0.7, s.up_axis), atol=1e-9)


def test_the_spline_values_through_rcfk_are_keyfills_cubic_spline(corpus):
    s = corpus.skeleton
    ranges = estimate_ranges(s, corpus.quats)
    q = corpus.quats[:150].astype(np.float64)
    k = np.array([0, 17, 60, 100, 149])
    v = spline_values(ranges, 160, k, q[k])  # 10 frames after the last key hold it
    assert v.shape == (6 + 3 * len(ranges.driven), 160) and v.dtype == np.float32
    rc = RCFK(s.parents, s.offsets, ranges)
    _, got = rc(torch.as_tensor(v)[None])
    cq, _ = cubic_arrays(q, np.zeros((150, 1, 3)), k)
    want = relative_positions(cq, s.offsets, s.parents)
    # frames where the spline stays in every range (RC-FK clips the others; the spine's static angle
    # wobbles by 0.05 degrees along the spline)
    ok = inside(ranges, cq, tolerance=np.radians(0.1)).all(-1)
    assert ok.mean() > 0.9
    height = np.ptp(want[..., 1])
    assert np.abs(got[0, :150].numpy()[ok] - want[ok]).max() < 1e-3 * height
    assert np.allclose(got[0, 150:].numpy(), got[0, 149].numpy(), atol=1e-5)
    root = spline_root(160, k, corpus.root[:150][k])
    assert np.allclose(root[k], corpus.root[:150][k]) and np.allclose(root[150:], root[149])


def test_a_fresh_spline_model_completes_as_the_cubic_spline(models, motion):
    keys = Keys(np.array([0, 40, 100, 160, 239]))
    gan = complete(motion, keys, "gan", CompleteOptions(model=str(models[0]), feet="free")).motion
    spline = cubic(motion, keys)
    a, b = world(gan), world(spline)
    height = np.ptp(b[..., 1])
    assert np.abs(a - b).max() < 0.02 * height  # RC-FK clips the spline into the joints' ranges
    assert np.abs(a - b).mean() < 1e-3 * height
    assert np.array_equal(gan.rotations[keys.frames], motion.rotations[keys.frames])
    assert np.array_equal(gan.positions[keys.frames], motion.positions[keys.frames])


def test_a_fresh_linear_base_model_completes_as_the_protocols_interpolation(corpus, motion, tmp_path):
    cfg = tiny_config(**{**SPLINE, "base": "linear", "max_frames": 256})
    task = GanTask(corpus, cfg, "generator", epochs=1)
    folder = task.save(tmp_path / "linear", built(task), [])
    keys = Keys(np.array([0, 40, 100, 160, 239]))
    a = world(complete(motion, keys, "gan", CompleteOptions(model=str(folder), feet="free")).motion)
    b = world(linear(motion, keys))
    height = np.ptp(b[..., 1])
    assert np.abs(a - b).max() < 0.02 * height and np.abs(a - b).mean() < 1e-3 * height
    k = np.array([0, 10, 30])
    roots = np.array([[0.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 2.0]])
    assert np.allclose(spline_root(31, k, roots, "linear")[20], [1.0, 0.5, 1.0])  # halfway from key 1 to key 2


def test_a_trained_spline_model_moves_off_the_spline_and_hits_its_keys(models, motion):
    keys = Keys(np.array([0, 50, 130, 200]))
    out = complete(motion, keys, "gan", CompleteOptions(model=str(models[1]), feet="free")).motion
    assert np.array_equal(out.rotations[keys.frames], motion.rotations[keys.frames])
    assert np.abs(world(out) - world(cubic(motion, keys))).max() > 1e-3


def test_windows_and_sequences_carry_the_spline_of_their_own_keys(corpus):
    cfg = tiny_config(**{**SPLINE, "max_gap": 60})
    ranges = estimate_ranges(corpus.skeleton, corpus.quats)
    pool = clip_pool(corpus, rotations=True)
    s = corpus.skeleton
    rc = RCFK(s.parents, s.offsets * s.meters_per_unit, ranges)
    rng = np.random.default_rng(1)
    for make in (clip_window, training_sequence):
        for _ in range(4):
            a = make(pool, rng, cfg, ranges=ranges)
            k = np.flatnonzero(a["key_mask"])
            with torch.no_grad():
                _, rel = rc(torch.as_tensor(a["base"])[None])
            J = s.num_joints
            keyed = a["dense"][: 3 * J].T.reshape(-1, J, 3)[k, 1:]  # the keys' root-relative joints
            assert np.abs(rel[0, k, 1:].numpy() - keyed).max() < 1e-3  # metres; turned as the positions are
            assert np.allclose(a["spline_root"][k], a["key_root"][k], atol=1e-5)


def test_the_spline_settings_that_cannot_work_are_refused(corpus, tmp_path):
    with pytest.raises(UsageError, match="partial keys"):
        GanConfig(**{**SPLINE, "partial_keys": True, "max_gap": 300})
    cfg = tiny_config(**SPLINE)
    with pytest.raises(UsageError, match="path predictor"):
        GanTask(corpus, cfg, "generator", path_model=tmp_path)
    with pytest.raises(UsageError, match="no path predictor"):
        GanTask(corpus, cfg, "path")
    with pytest.raises(UsageError, match="base"):
        GanConfig(base="bezier")


def test_the_spline_models_graph_takes_the_base_and_equals_torch(models, motion):
    pytest.importorskip("onnxruntime")
    pytest.importorskip("onnxscript")
    from keyfill.cli.main import main
    from keyfill.learn import onnx as kx

    assert main(["export", str(models[1])]) == 0
    graph = kx.open_graph(models[1] / kx.GRAPH)
    assert [i.name for i in graph.session.get_inputs()] == ["dense", "dna", "dna_valid", "base"]
    assert [o.name for o in graph.session.get_outputs()] == ["quats"]
    keys = Keys(np.array([0, 50, 130, 200]))
    out = {rt: complete(motion, keys, "gan", CompleteOptions(model=str(models[1]), seed=3, runtime=rt))
           for rt in ("torch", "onnx")}
    assert out["onnx"].info["runtime"] == "onnx"
    a, b = world(out["torch"].motion), world(out["onnx"].motion)
    assert np.abs(a - b).max() <= 1e-4 * np.ptp(a[..., 1])


def test_lafan_windows_complete_through_the_spline_base(models, motion):
    from keyfill.learn.corpus import fold_root
    from keyfill.learn.gan.model import load_model

    model = load_model(models[0])
    q, p = fold_root(motion.rotations, motion.positions, motion.skeleton.parents)
    quats, root = np.stack([q[0:60], q[90:150]]), np.stack([p[0:60, 0], p[90:150, 0]])
    k = np.append(np.arange(10), 59)
    gq, gr = model.benchmark_method(0)(model.skeleton, quats, root, k)
    _, cp = cubic_arrays(quats.transpose(1, 0, 2, 3).reshape(60, -1, 4), root.transpose(1, 0, 2), k)
    assert np.allclose(gr, cp.transpose(1, 0, 2), atol=1e-6 * np.ptp(root))  # the root is the spline's
    assert np.abs(gq[:, k] - quats[:, k]).max() < 1e-9


def test_the_quality_report_of_a_spline_model_keys_its_base(models, corpus):
    """Table 4's figures through a base: the key layouts carry their rotations, and the keys come out of the
    network about where the spline puts them (on the keys, but for range clipping and the correction)."""
    from keyfill.learn.gan.model import load_model
    from keyfill.learn.gan.quality import quality_report

    model = load_model(models[1])
    report = quality_report(model, corpus, range(len(corpus)), sequences=2, frames=200, seed=0)
    full = report["key_errors"]["full"]
    assert full["root_cm"] < 1e-6  # the root path is the spline through the key roots
    assert np.isfinite(full["joints_cm"]) and report["dna_error_1_cm"] > 0


def test_benchmark_windows_keep_the_keys_quaternion_hemisphere(models, motion):
    """RC-FK gives the root with w >= 0; the LaFAN1 metrics compare quaternions sign and all, so a window whose
    root turns through 180 degrees between its keys (w crosses 0) must not flip sign there."""
    from keyfill.learn.corpus import fold_root
    from keyfill.learn.gan.model import load_model

    model = load_model(models[1])
    q, p = fold_root(motion.rotations, motion.positions, motion.skeleton.parents)
    q = q[:60].copy()  # the root turns from 144 to 234 degrees: w crosses 0 at frame 24, in the gap
    q[:, 0] = R.quat_continuous_np(np.stack([heading_quat(a, motion.skeleton.up_axis)
                                             for a in np.pi * (0.8 + np.arange(60) / 120)]))
    assert q[0, 0, 0] > 0 > q[-1, 0, 0]
    quats, root = np.stack([q, -q]), np.stack([p[0:60, 0], p[0:60, 0]])
    k = np.append(np.arange(10), 59)
    gq, _ = model.benchmark_method(0)(model.skeleton, quats, root, k)
    assert np.array_equal(gq[:, k], quats[:, k])
    assert (np.sum(gq[:, 1:] * gq[:, :-1], axis=-1) > 0).all()
