"""Rig states and Jacobians: forward kinematics agrees with keyfill.kinematics; ds/dc with finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from test_curves import random_curves

from keyfill import rotations as R
from keyfill.characters.lamp import from_variables
from keyfill.curves import controls_to_pose
from keyfill.edit.fit import fit
from keyfill.edit.rig import Point, Rig
from keyfill.kinematics import fk
from keyfill.motion import Keys


def lamp_curves():
    t = np.arange(25) / 30.0
    v = np.stack(
        [
            0.3 * t,
            0.05 + 0.1 * np.sin(4 * t),
            0.2 * np.sin(3 * t),
            0.5 + 0.3 * np.sin(5 * t),
            -0.8 + 0.2 * np.cos(4 * t),
            0.4 * np.sin(2 * t),
        ],
        -1,
    )
    m = from_variables(v, 30.0)
    return fit(m, Keys(np.array([0, 8, 16, 24])))


@pytest.mark.parametrize("which", ["character", "lamp"])
def test_states_match_keyfill_kinematics(which):
    c = random_curves(11) if which == "character" else lamp_curves()
    rig = Rig(c.skeleton, c.controls)
    t = np.array([0.0, 3.3, 12.5, 21.0])
    vals = c.evaluate(t)
    rot, pos = controls_to_pose(c.skeleton, c.controls, vals)
    wr, wp = fk(rot, pos, c.skeleton.parents)
    off = np.array([3.0, -2.0, 5.0]) * (0.01 if which == "lamp" else 1.0)
    points = [Point(j, off, orientation=True) for j in range(c.skeleton.num_joints)]
    frames = rig.frames(vals, rig.joints_for(points))
    for p in points:
        got_pos, got_rot = rig.state(frames, p)
        np.testing.assert_allclose(got_pos, wp[:, p.joint] + R.quat_rotate(wr[:, p.joint], off), atol=1e-10)
        np.testing.assert_allclose(got_rot, R.quat_to_matrix(wr[:, p.joint]), atol=1e-12)


@pytest.mark.parametrize("which", ["character", "lamp"])
def test_jacobian_matches_finite_differences(which):
    c = random_curves(12) if which == "character" else lamp_curves()
    rig = Rig(c.skeleton, c.controls)
    vals = c.evaluate(np.array([4.2, 13.7]))
    end = c.skeleton.num_joints - 1
    for p in (Point(end, [0.05, 0.02, 0.0], True), Point(max(end - 5, 1)), Point(0, [0.1, 0.0, 0.2])):
        joints = rig.joints_for([p])
        controls = list(range(c.num_controls))
        frames = rig.frames(vals, joints)
        pos, rot = rig.state(frames, p)
        J = rig.jacobian(frames, p, pos, controls)
        h = 1e-6
        for k in controls:
            v2 = vals.copy()
            v2[:, k] += h
            p2, r2 = rig.state(rig.frames(v2, joints), p)
            np.testing.assert_allclose(J[:, :3, k], (p2 - pos) / h, atol=2e-4 * max(1, np.abs(J).max()))
            if p.orientation:
                w = R.quat_to_rotvec(R.quat_from_matrix(r2 @ np.swapaxes(rot, -1, -2))) / h
                np.testing.assert_allclose(J[:, 3:, k], w, atol=1e-5)


def test_controls_of_a_point():
    c = random_curves(13)
    sk, rig = c.skeleton, Rig(c.skeleton, c.controls)
    names = lambda s: {c.controls[i].name(sk) for i in s}
    hand = sk.index("Hand_L")
    plain = names(rig.controls_of(Point(hand)))
    assert "Hips.Xposition" in plain and "LowerArm_L.Yrotation" in plain
    assert not any(n.startswith("Hand_L.") for n in plain)  # a joint's own rotation does not move it
    assert "Hand_L.Zrotation" in names(rig.controls_of(Point(hand, [5, 0, 0])))
    assert "Hand_L.Zrotation" in names(rig.controls_of(Point(hand, orientation=True)))
    assert not any("_R." in n or "Leg" in n for n in plain)
