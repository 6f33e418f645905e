"""Fitting Bezier curves to dense motion: exact at keys, least-squares between."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import shared_path
from test_edit_character import character

from keyfill import io
from keyfill import rotations as R
from keyfill.edit.fit import controls_of, fit
from keyfill.errors import DataError
from keyfill.motion import Keys


def test_fit_recovers_curves_from_their_own_frames():
    m = character()
    c = fit(m, m.keys)
    # curves with uniform timing and unified keys are what fit produces: refitting their
    # bake must give them back (values and slopes) to rounding
    again = fit(c.bake(), m.keys)
    np.testing.assert_allclose(again.values, c.values, atol=1e-12)
    np.testing.assert_allclose(again.out_tan, c.out_tan, atol=1e-9)
    np.testing.assert_allclose(again.in_tan, c.in_tan, atol=1e-9)
    assert not again.broken.any()


def test_fit_is_exact_at_keys_and_close_between():
    m = character()
    c = fit(m, Keys(np.array([0, 8, 20, 33, 40])))
    b = c.bake()
    k = [0, 8, 20, 33, 40]
    assert R.quat_angle(b.rotations[k], m.rotations[k]).max() < 1e-12
    err = np.linalg.norm(b.world_positions() - m.world_positions(), axis=-1)
    assert err.max() < 2.0  # cm, sinusoids between keys 8 to 13 frames apart
    assert err.max() > 1e-3  # and it is a fit, not a copy
    # the tangents are unified with a third of each segment as width
    assert not c.broken.any()
    np.testing.assert_allclose(c.out_tan[:-1, 0, 0], np.diff(c.times) / 3)


def test_controls_are_rotations_and_moving_translations():
    m = character()
    ctl = controls_of(m)
    names = [c.name(m.skeleton) for c in ctl]
    assert "Hips.Xposition" in names and "Hand_L.Zrotation" in names
    assert sum(c.is_rotation for c in ctl) == 3 * m.num_joints and len(ctl) == 3 * m.num_joints + 3
    assert len(controls_of(m, all_channels=True)) == m.skeleton.num_channels


def test_a_rotation_about_a_missing_channel_is_refused():
    m = character()
    sk = m.skeleton
    chans = list(sk.channels)
    chans[sk.index("Neck")] = ("Zrotation",)
    with pytest.raises(DataError, match="Neck"):
        fit(m.replace(skeleton=sk.replace(channels=tuple(chans))), m.keys)


def test_bandai_walk_fits_72_controls():
    path = shared_path("bvh_fixtures", "dataset-1_walk_normal_002.bvh")
    m = io.load(path)
    c = fit(m, Keys.parse("0,10,20,30"))
    assert c.num_controls == 72  # joint_Root and Hips translate; 22 joints x 3 rotations
    b = c.bake()
    assert R.quat_angle(b.rotations[[0, 10, 20, 30]], m.rotations[[0, 10, 20, 30]]).max() < 1e-12


def test_keys_on_every_frame_reproduce_the_motion():
    m = character(num_frames=6)
    c = fit(m, Keys(np.arange(6)))
    assert R.quat_angle(c.bake().rotations, m.rotations).max() < 1e-12
    assert np.all(np.isfinite(c.out_tan))
