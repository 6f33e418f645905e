"""Curve files: pxr.Ts splines beside a UsdSkel Skeleton; keyfill and pxr evaluate alike."""

from __future__ import annotations

import numpy as np
import pytest
from test_curves import random_curves
from test_edit_character import character

from keyfill import io
from keyfill import rotations as R
from keyfill.edit.fit import fit
from keyfill.errors import FormatError
from keyfill.files import quiet_stderr
from keyfill.io import usd_curves


def pxr_values(path, curves, times) -> np.ndarray:
    """``attr.Get(t)`` of every control attribute (radians and file units, as keyfill)."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    prim = usd_curves.curves_prim(stage)
    out = np.full((len(times), curves.num_controls), np.nan)
    for attr in prim.GetAttributes():
        if not attr.HasSpline():
            continue
        data = attr.GetCustomDataByKey("keyfill")
        i = curves.control_index(f"{data['joint']}.{data['channel']}")
        out[:, i] = [attr.Get(Usd.TimeCode(float(t))) for t in times]
    return out


@pytest.mark.parametrize("suffix", ["usda", "usdc"])
def test_round_trip_keeps_every_key_and_tangent(tmp_path, suffix):
    c = random_curves(5)
    broken = c.broken.copy()
    broken[::2] = False
    c = c.replace(broken=broken)
    path = tmp_path / f"curves.{suffix}"
    usd_curves.save(c, path)
    back = usd_curves.read(path)
    assert back.controls == c.controls and back.num_frames == c.num_frames and back.fps == c.fps
    np.testing.assert_array_equal(back.times, c.times)
    np.testing.assert_array_equal(back.values, c.values)  # bit for bit
    np.testing.assert_allclose(back.in_tan, c.in_tan, rtol=1e-15, atol=1e-15)  # stored as width and slope
    np.testing.assert_allclose(back.out_tan, c.out_tan, rtol=1e-15, atol=1e-15)
    np.testing.assert_array_equal(back.broken, broken)


@pytest.mark.parametrize("broken", [True, False])
def test_pxr_evaluates_what_keyfill_evaluates(tmp_path, broken):
    c = random_curves(6, broken=broken)
    path = tmp_path / "curves.usda"
    usd_curves.save(c, path)
    t = np.linspace(-3, 43, 461)
    theirs = pxr_values(path, c, t)
    ours = c.evaluate(t)
    assert np.abs(theirs - ours).max() < 1e-6


def test_loading_a_curves_file_bakes_the_curves(tmp_path):
    m = character()
    c = fit(m, m.keys)
    path = tmp_path / "c.usda"
    usd_curves.save(c, path)
    baked = io.load(path)
    assert baked.keys.to_list() == list(m.keys.frames)
    ref = c.bake()
    assert R.quat_angle(baked.rotations, ref.rotations).max() < 1e-12
    np.testing.assert_allclose(baked.positions, ref.positions, atol=1e-12)
    # the stored SkelAnimation (float32) is the same motion, for viewers that only know UsdSkel
    stored = io.usd.read(path)
    assert R.quat_angle(stored.rotations, ref.rotations).max() < 1e-6
    # and a .bvh output bakes too
    usd_curves.save(c, tmp_path / "c.bvh")
    assert R.quat_angle(io.load(tmp_path / "c.bvh").rotations, ref.rotations).max() < 1e-9


def test_writing_is_deterministic(tmp_path):
    c = random_curves(7)
    a, b = tmp_path / "a" / "walk.usda", tmp_path / "b" / "walk.usda"  # one name: the animation takes the stem
    for out in (a, b):
        out.parent.mkdir()
        usd_curves.save(c, out)
    assert a.read_bytes() == b.read_bytes()


def _edit_spline(path, name, change):
    from pxr import Sdf, Usd

    layer = Sdf.Layer.FindOrOpen(str(path))
    stage = Usd.Stage.Open(layer)
    attr = usd_curves.curves_prim(stage).GetAttribute(name)
    spline = attr.GetSpline()
    change(spline)
    attr.SetSpline(spline)
    with quiet_stderr():
        layer.Save()


def test_foreign_splines_hermite_and_linear_are_read(tmp_path):
    from pxr import Ts

    c = random_curves(8)
    path = tmp_path / "c.usda"
    usd_curves.save(c, path)

    def hermite_and_linear(spline):
        spline.SetCurveType(Ts.CurveTypeHermite)
        knots = spline.GetKnots()
        k = knots[10.0]
        k.SetNextInterpolation(Ts.InterpLinear)
        spline.SetKnot(k)

    _edit_spline(path, "Neck_Xrotation", hermite_and_linear)
    back = usd_curves.read(path)
    t = np.linspace(0, 40, 401)
    i = back.control_index("Neck.Xrotation")
    assert np.abs(pxr_values(path, back, t)[:, i] - back.evaluate(t)[:, i]).max() < 1e-6


def test_bad_splines_are_refused_with_the_attribute_name(tmp_path):
    from pxr import Ts

    c = random_curves(9)
    path = tmp_path / "c.usda"
    usd_curves.save(c, path)

    def drop_knot(spline):
        spline.RemoveKnot(20.0)

    _edit_spline(path, "Head_Yrotation", drop_knot)
    with pytest.raises(FormatError, match="Head_Yrotation has knots at 0, 10, 30, 40"):
        usd_curves.read(path)

    usd_curves.save(c, path)

    def held(spline):
        k = spline.GetKnots()[10.0]
        k.SetNextInterpolation(Ts.InterpHeld)
        spline.SetKnot(k)

    _edit_spline(path, "Head_Yrotation", held)
    with pytest.raises(FormatError, match="holds its value"):
        io.load(path)


def test_a_plain_usd_file_is_not_a_curves_file(tmp_path):
    m = character()
    io.save(m, tmp_path / "plain.usda")
    with pytest.raises(FormatError, match="not a keyfill curves file"):
        usd_curves.read(tmp_path / "plain.usda")
