"""Bezier curves: exact evaluation, derivatives, holds, validation, baking."""

from __future__ import annotations

import numpy as np
import pytest
from test_edit_character import character

from keyfill import rotations as R
from keyfill.curves import evaluate_segments, solve_bezier_time
from keyfill.edit.fit import fit
from keyfill.edit.move import tangent_derivatives
from keyfill.errors import DataError


def random_curves(seed: int, broken: bool = True):
    """The character's fitted curves with random tangents (widths inside Eq. 7, any heights)."""
    rng = np.random.default_rng(seed)
    m = character()
    c = fit(m, m.keys)
    K, C = c.values.shape
    seg = np.diff(c.times)
    in_w = np.concatenate([seg[:1], seg])[:, None] * rng.uniform(0.02, 0.98, (K, C))
    out_w = np.concatenate([seg, seg[-1:]])[:, None] * rng.uniform(0.02, 0.98, (K, C))
    in_tan = np.stack([in_w, rng.normal(0, 0.3, (K, C))], -1)
    out_tan = np.stack([out_w, rng.normal(0, 0.3, (K, C))], -1)
    br = np.ones((K, C), bool) if broken else np.zeros((K, C), bool)
    if not broken:  # unified: the in side has the out side's slope
        in_tan[..., 1] = out_tan[..., 1] / out_tan[..., 0] * in_tan[..., 0]
    return c.replace(in_tan=in_tan, out_tan=out_tan, broken=br)


def test_solve_bezier_time_is_exact_even_at_flat_spots():
    rng = np.random.default_rng(0)
    n = 20000
    a = rng.uniform(0, 1, n)
    b = 1 - rng.uniform(0, 1, n)
    a[:50], b[:50] = 1.0, 0.0  # x'(1/2) = 0: the hardest case Eq. 7 allows
    a[50:100], b[50:100] = 0.0, 1.0  # x'(0) = x'(1) = 0
    u = rng.uniform(0, 1, n)
    lam = solve_bezier_time(u, a, b)
    x = 3 * a * lam * (1 - lam) ** 2 + 3 * b * lam**2 * (1 - lam) + lam**3
    assert np.all((lam >= 0) & (lam <= 1))
    assert np.abs(x - u).max() < 1e-13
    # linear timing is solved exactly at once
    lin = solve_bezier_time(u, np.full(n, 1 / 3), np.full(n, 2 / 3))
    np.testing.assert_allclose(lin, u, atol=1e-15)


def test_evaluation_follows_the_bezier_control_points():
    c = random_curves(1)
    lam = np.linspace(0, 1, 101)
    k, i = 2, 7
    t0, t1 = c.times[k], c.times[k + 1]
    px = [t0, t0 + c.out_tan[k, i, 0], t1 - c.in_tan[k + 1, i, 0], t1]
    py = [
        c.values[k, i],
        c.values[k, i] + c.out_tan[k, i, 1],
        c.values[k + 1, i] - c.in_tan[k + 1, i, 1],
        c.values[k + 1, i],
    ]
    basis = np.stack([(1 - lam) ** 3, 3 * lam * (1 - lam) ** 2, 3 * lam**2 * (1 - lam), lam**3], -1)
    x, y = basis @ px, basis @ py
    got = c.evaluate(x, controls=[i])[:, 0]
    np.testing.assert_allclose(got, y, atol=1e-11)


def test_keys_holds_and_time_derivative():
    c = random_curves(2)
    np.testing.assert_allclose(c.evaluate(c.times), c.values, atol=1e-12)
    np.testing.assert_allclose(c.evaluate([-5.0, c.times[0]]), c.values[[0, 0]], atol=1e-12)
    np.testing.assert_allclose(c.evaluate([c.times[-1] + 3]), c.values[[-1]], atol=1e-12)
    assert np.all(c.derivative([-5.0, c.times[-1] + 3]) == 0)
    t = np.linspace(0.3, 39.7, 57)
    t = t[np.abs(t[:, None] - c.times).min(axis=1) > 1e-3]  # broken keys have two slopes
    h = 1e-6
    fd = (c.evaluate(t + h) - c.evaluate(t - h)) / (2 * h)
    np.testing.assert_allclose(c.derivative(t), fd, atol=1e-6 * np.abs(fd).max())


def test_tangent_derivatives_match_finite_differences():
    c = random_curves(3)
    t = np.linspace(20.1, 29.9, 23)  # inside segment 2 (keys 20 and 30)
    seg = c.segment(t)
    cols = np.arange(c.num_controls)
    got = tangent_derivatives(evaluate_segments(c.arrays(), t, seg, cols))  # (T, C, 4)
    h = 1e-7
    for col, (name, k, comp) in enumerate([("out_tan", 2, 0), ("out_tan", 2, 1), ("in_tan", 3, 0), ("in_tan", 3, 1)]):
        up, down = getattr(c, name).copy(), getattr(c, name).copy()
        up[k, :, comp] += h
        down[k, :, comp] -= h
        fd = (c.replace(**{name: up}).evaluate(t) - c.replace(**{name: down}).evaluate(t)) / (2 * h)
        np.testing.assert_allclose(got[..., col], fd, atol=1e-6)


def test_widths_longer_than_the_segment_are_refused():
    c = random_curves(4)
    out = c.out_tan.copy()
    out[1, 0, 0] = 11.0  # segment 10 -> 20 is 10 frames long
    with pytest.raises(DataError, match="backwards in time"):
        c.replace(out_tan=out)
    with pytest.raises(DataError, match="strictly increasing"):
        c.replace(times=c.times[::-1].copy())


def test_bake_gives_the_motion_at_the_keys():
    m = character()
    c = fit(m, m.keys)
    b = c.bake()
    assert b.keys.to_list() == list(m.keys.frames) and b.num_frames == m.num_frames
    k = m.keys.frames
    assert R.quat_angle(b.rotations[k], m.rotations[k]).max() < 1e-12
    np.testing.assert_allclose(b.positions[k], m.positions[k], atol=1e-12)
