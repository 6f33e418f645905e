"""Representative frames (section 3.5.1): the frames of largest joint-rotation change, poses without root rotation."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_corpus import walker_motion, walker_skeleton

from keyfill import rotations as R
from keyfill.errors import UsageError
from keyfill.learn.representative import (
    pick_frames,
    representative_frames,
    representative_poses,
    rotation_change,
)
from keyfill.motion import Motion


def jerky_motion(spikes: dict) -> Motion:
    """The walker standing in its rest pose, turning slowly, with a joint flicked for one frame at each spike."""
    sk = walker_skeleton()
    m = Motion.rest(sk, 100)
    rot = m.rotations.copy()
    rot[:, 1] = R.euler_to_quat(np.stack([np.zeros(100), np.zeros(100), np.linspace(0, 3, 100)], -1), "ZXY")
    for f, (joint, angle) in spikes.items():
        rot[f, sk.index(joint)] = R.quat_from_rotvec(np.array([angle, 0.0, 0.0]))
    return m.replace(rotations=rot)


def test_picks_the_frames_with_the_largest_rotation_change():
    m = jerky_motion({20: ("Spine", 0.9), 55: ("Leg_L", 0.5), 80: ("Head", 0.7), 90: ("Foot_R", 0.2)})
    assert representative_frames(m, 3).tolist() == [20, 55, 80]
    assert representative_frames(m, 4).tolist() == [20, 55, 80, 90]
    # the hips' turn is the root's (joint_Root is static and folded away): it adds no change
    ch = rotation_change(m.rotations)  # without folding, the hips (joint 1) would count
    assert ch[30] > 0 and representative_frames(m, 1).tolist() == [20]


def test_change_is_half_the_angle_to_each_neighbour():
    q = np.zeros((3, 2, 4))
    q[..., 0] = 1
    q[1, 1] = R.quat_from_rotvec(np.array([0.0, 0.4, 0.0]))
    assert np.allclose(rotation_change(q), [0.4, 0.4, 0.4])


def test_after_the_peaks_the_largest_other_frames_fill_in():
    change = np.array([0.0, 5.0, 4.0, 1.0, 3.0, 0.0])
    assert pick_frames(change, 2).tolist() == [1, 4]  # the two local maxima
    assert pick_frames(change, 3).tolist() == [1, 2, 4]  # then frame 2 (4.0), not a maximum
    assert pick_frames(change, 10).tolist() == list(range(6))
    with pytest.raises(UsageError):
        pick_frames(change, 0)


def test_poses_face_one_way_whatever_the_heading():
    m = walker_motion(walker_skeleton(), 60, np.random.default_rng(3))
    turn = R.quat_from_rotvec(np.array([0.0, 1.3, 0.0]))
    rot = m.rotations.copy()
    rot[:, 1] = R.quat_mul(turn, rot[:, 1])  # the hips (the folded root) turned about the up axis
    a = representative_poses(m, [5, 30])
    b = representative_poses(m.replace(rotations=rot), [5, 30])
    assert a.shape == (2, m.num_joints - 1, 3) and np.allclose(a, b)
    with pytest.raises(UsageError, match="frame 60 is outside"):
        representative_poses(m, [1, 60])


def test_info_lists_representative_frames(tmp_path, capsys):
    import json

    from keyfill import io
    from keyfill.cli.main import main

    m = jerky_motion({20: ("Spine", 0.9), 55: ("Leg_L", 0.5), 80: ("Head", 0.7)})
    io.save(m, tmp_path / "jerky.bvh")
    capsys.readouterr()
    assert main(["info", str(tmp_path / "jerky.bvh"), "--representative", "3", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["representative_frames"] == [20, 55, 80]
    assert main(["info", str(tmp_path / "jerky.bvh"), "--representative", "0"]) == 2
    out = capsys.readouterr()
    assert out.out == "" and out.err.startswith("keyfill: error:") and len(out.err.splitlines()) == 1
