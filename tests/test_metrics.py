"""L2Q, L2P and NPSS: known values, and the golden vectors of the reference benchmark code."""

import json
from pathlib import Path

import numpy as np
import pytest

from keyfill import interpolate
from keyfill import rotations as R
from keyfill.learn.protocols import lafan1 as benchmark
from keyfill.learn.protocols import metrics
from keyfill.motion import Skeleton

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
GOLDEN = SHARED / "golden" / "bandai1_lafan_protocol_golden.npz"
EXPECTED = SHARED / "golden" / "bandai1_lafan_protocol_expected.json"
needs_golden = pytest.mark.skipif(not GOLDEN.is_file(), reason=f"golden vectors not found: {GOLDEN}")


def random_quats(rng, shape):
    return R.quat_normalize(rng.normal(size=shape + (4,)))


def test_l2q_is_the_mean_norm_over_joints_and_components():
    rng = np.random.default_rng(0)
    gt = random_quats(rng, (3, 5, 4))
    pred = gt.copy()
    pred[1, 2, 3] += [0.3, 0.0, 0.4, 0.0]  # one frame, one joint: norm 0.5
    assert metrics.l2q(gt, gt) == 0.0
    assert metrics.l2q(gt, pred) == pytest.approx(0.5 / 15)


def test_l2q_counts_the_quaternion_sign():
    rng = np.random.default_rng(1)
    gt = random_quats(rng, (2, 3, 4))
    pred = gt.copy()
    pred[..., 1, :] *= -1  # same rotations, other hemisphere for one joint
    assert metrics.l2q(gt, pred) == pytest.approx(2.0)


def test_l2p_normalises_by_the_training_statistics():
    gt = np.zeros((2, 4, 3, 3))
    pred = gt.copy()
    pred[..., 0, 0] = 6.0  # joint 0 x off by 6 units on every frame
    std = np.ones(9)
    std[0] = 3.0
    assert metrics.l2p(gt, pred, np.full(9, 5.0), std) == pytest.approx(2.0)


def test_npss_is_zero_for_identical_and_grows_with_spectral_change():
    t = np.linspace(0, 1, 30)
    gt = np.stack([np.sin(2 * np.pi * t), np.cos(2 * np.pi * t)], -1)[None] + 1.0
    slow = gt.copy()
    fast = np.stack([np.sin(8 * np.pi * t), np.cos(8 * np.pi * t)], -1)[None] + 1.0
    assert metrics.npss(gt, slow) == 0.0
    assert metrics.npss(gt, fast) > 0.01


def test_npss_matches_a_direct_computation():
    rng = np.random.default_rng(2)
    gt, pred = rng.normal(size=(3, 7, 5)), rng.normal(size=(3, 7, 5))
    emd, weights = [], []
    for w in range(3):
        for d in range(5):
            g = np.real(np.fft.fft(gt[w, :, d])) ** 2
            p = np.real(np.fft.fft(pred[w, :, d])) ** 2
            emd.append(np.abs(np.cumsum(p / p.sum()) - np.cumsum(g / g.sum())).sum())
            weights.append(g.sum())
    assert metrics.npss(gt, pred) == pytest.approx(np.average(emd, weights=weights), rel=1e-12)


def test_shape_mismatch_is_refused():
    with pytest.raises(ValueError, match="shape"):
        metrics.npss(np.zeros((1, 2, 3)), np.zeros((1, 3, 3)))
    with pytest.raises(ValueError):
        metrics.l2q(np.zeros((1, 2, 3, 4)), np.zeros((1, 2, 3, 3)))


@needs_golden
def test_golden_vectors_from_the_npz():
    """The protocol applied to the reference code's own inputs gives its outputs (1e-4 relative)."""
    z = np.load(GOLDEN)
    expected = json.loads(EXPECTED.read_text())
    J = z["Q_test"].shape[2]
    offsets = np.vstack([np.zeros(3), z["offsets"].reshape(-1, 3)])
    skel = Skeleton([f"j{i}" for i in range(J)], z["parents"], offsets, [()] * J)
    test = benchmark.TestSet(skel, z["Q_test"], z["X_test"][:, :, 0])
    stats = benchmark.Statistics(z["x_mean"].reshape(-1), z["x_std"].reshape(-1))
    methods = {"zerov": interpolate.hold_windows, "interp": interpolate.linear_windows}
    res = benchmark.evaluate(methods, test, stats, benchmark.LENGTHS)
    names = {"quat": "L2Q", "pos": "L2P", "npss": "NPSS"}
    assert len(expected) == 24
    for key, value in expected.items():
        method, metric, _, n = key.replace("@", "_").split("_")
        got = res[method][int(n)][names[metric]]
        assert got == pytest.approx(value, rel=1e-4), key
        assert z[key.replace("@", "_at_")] == pytest.approx(value, rel=1e-12)
