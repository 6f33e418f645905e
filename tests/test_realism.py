"""Foot skating and jitter (keyfill.learn.protocols.metrics) on hand-made motions, and in the LaFAN1 evaluation."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import DATA
from synthetic_corpus import walker_skeleton, write_corpus

from keyfill.cli.main import main
from keyfill.learn.protocols import metrics as realism


def _two_feet(T: int) -> np.ndarray:
    """(1, T, 2, 3) positions in cm: foot 0 slides on the floor at 3 cm/frame along X; foot 1 taps, down every
    other frame, so never two frames in a row on the ground, and moves fast along Z."""
    p = np.zeros((1, T, 2, 3))
    p[0, :, 0, 0] = 3.0 * np.arange(T)
    p[0, :, 1, 1] = np.where(np.arange(T) % 2 == 0, 0.0, 10.0)
    p[0, :, 1, 2] = 50.0 * np.arange(T)
    return p


def test_foot_skating_is_the_speed_of_planted_feet_only():
    p = _two_feet(20)
    # 3 cm/frame at 30 fps = 90 cm/s; 1 unit = 1 cm
    assert realism.foot_skating(p, np.array([0, 1]), "Y", 30.0, 0.01) == pytest.approx(90.0)
    # a foot 2 cm above its lowest point still touches the ground; 3 cm does not
    p[0, :, 0, 1] = np.where(np.arange(20) < 10, 2.0, 0.0)
    assert realism.foot_skating(p, np.array([0]), "Y", 30.0, 0.01) == pytest.approx(90.0)
    p[0, :, 0, 1] = np.where(np.arange(20) < 10, 3.0, 0.0)  # frames 0-9 lifted: pairs 10-18 remain
    assert realism.foot_skating(p, np.array([0]), "Y", 30.0, 0.01) == pytest.approx(90.0)
    p[0, 10:, 0, 0] = p[0, 10, 0, 0]  # ... and the planted half stands still
    assert realism.foot_skating(p, np.array([0]), "Y", 30.0, 0.01) == pytest.approx(0.0)
    # the ground comes from the reference: 5 cm above the reference's floor is in the air
    assert np.isnan(realism.foot_skating(p + [0, 5, 0], np.array([0]), "Y", 30.0, 0.01, reference=p))


def test_jitter_is_the_third_difference_in_meters_per_cubed_second():
    t = np.arange(12, dtype=np.float64)
    p = np.zeros((2, 12, 1, 3))
    p[..., 0] = (0.5 * t**3)[None, :, None]  # third difference 3 cm/frame^3
    assert realism.jitter(p, 30.0, 0.01) == pytest.approx(3.0 * 30.0**3 * 0.01)
    p[..., 0] = (4.0 * t**2 - t)[None, :, None]  # a parabola has no jerk
    assert realism.jitter(p, 30.0, 0.01) == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="at least 4 frames"):
        realism.jitter(p[:, :3], 30.0, 0.01)


def test_foot_joints_by_name_or_as_the_lowest_leaves():
    sk = walker_skeleton()
    named = realism.foot_joints(sk)
    assert [sk.names[j] for j in named] and all("foot" in sk.names[j].lower() or "toe" in sk.names[j].lower()
                                                for j in named)
    renamed = sk.__class__(names=tuple(f"j{i}" for i in range(len(sk.names))), parents=sk.parents,
                           offsets=sk.offsets, channels=sk.channels)
    lowest = realism.foot_joints(renamed)
    assert len(lowest) == 2 and set(lowest) <= set(np.setdiff1d(np.arange(len(sk.names)), sk.parents))


def test_evaluate_reports_skating_and_jitter_beside_the_truth(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("KEYFILL_CACHE", str(tmp_path / "cache"))
    write_corpus(tmp_path / "clips", styles=("happy", "calm"), clips_per_style=2, frames=(90, 120), seed=4)
    assert main(["evaluate", "cubic", str(tmp_path / "clips"), "--test-pattern", "*_calm_*", "--lengths", "5,15",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    for name in ("cubic", "interpolation", "zero-velocity"):
        assert {"skate", "jitter"} <= set(out["results"][name]["15"])
    truth = out["truth"]["15"]
    assert truth["jitter"] > 0 and truth["skate"] >= 0
    assert out["results"]["zero-velocity"]["15"]["jitter"] > out["results"]["cubic"]["15"]["jitter"]
    assert main(["evaluate", "cubic", str(tmp_path / "clips"), "--test-pattern", "*_calm_*", "--lengths", "5"]) == 0
    text = capsys.readouterr().out
    assert "foot skating (cm/s)" in text and "ground truth" in text


def test_a_humanoid_test_set_is_also_scored_with_its_feet_locked():
    from keyfill import interpolate, io
    from keyfill.learn.protocols import lafan1

    walk = io.load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")  # only the hips carry a translation
    J = walk.num_joints
    test = lafan1.TestSet(walk.skeleton, walk.rotations[None], walk.positions[None, :, 0], ("walk",), walk.fps)
    stats = lafan1.Statistics(np.zeros(J * 3), np.ones(J * 3))
    keys = np.array([0, 20, 40, 60])
    out = lafan1.score_keys({"linear": interpolate.linear_windows}, test, stats, keys)["linear"]
    assert {"skate", "jitter", "skate_locked", "jitter_locked"} <= set(out)
    q, r = interpolate.linear_windows(walk.skeleton, test.quats, test.root, keys)
    lq, _ = lafan1.locked_windows(test, lafan1._rig(walk.skeleton), q, r, keys)
    np.testing.assert_array_equal(lq[:, keys], q[:, keys])  # keys stay exact
    assert not np.allclose(lq, q)  # and the legs moved where the feet touch the ground
    assert out["skate_locked"] != out["skate"] and out["jitter_locked"] != out["jitter"]
