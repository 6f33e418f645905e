"""The Blender extension's own numpy modules (blender/keyfill_blender/convert.py and backend.py, issue 47)
without Blender: in the ordinary suite, so CI checks the sign and frame-rate rules that the Blender tests
(tests/test_blender_addon.py, ``-m interop``) check end to end."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _extension_modules():
    """The extension's convert and backend modules without bpy (its __init__ registers Blender classes, so the
    package is made here as a bare namespace; the two modules need numpy only)."""
    import importlib
    import types

    pkg = sys.modules.get("keyfill_blender")
    if pkg is None:
        pkg = types.ModuleType("keyfill_blender")
        pkg.__path__ = [str(ROOT / "blender" / "keyfill_blender")]
        sys.modules["keyfill_blender"] = pkg
    return importlib.import_module("keyfill_blender.convert"), importlib.import_module("keyfill_blender.backend")


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_quaternion_signs_are_the_bvh_readers(order):
    """bvh_hemisphere gives exactly the quaternions keyfill's BVH reader makes of the Euler angles the extension
    (and Blender's exporter) writes, whatever sign it is handed; euler_angles picks the solution nearer zero."""
    from keyfill import rotations as R

    convert, _ = _extension_modules()
    rng = np.random.default_rng(47)
    q = rng.normal(size=(2000, 1, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    signed = convert.bvh_hemisphere(q, [order])
    flipped = convert.bvh_hemisphere(q * np.where(rng.random((2000, 1, 1)) < 0.5, -1.0, 1.0), [order])
    angles = convert.euler_angles(q[:, 0], order)
    read = R.euler_to_quat(angles, order)  # keyfill's reader: the product of the axis quaternions
    assert np.abs(signed[:, 0] - read).max() < 1e-12
    assert np.array_equal(signed, flipped)  # the sign handed in does not matter
    assert np.abs(np.abs(np.sum(signed * q, axis=-1)) - 1).max() < 1e-12  # same rotations
    assert np.all(np.abs(angles).max(axis=-1) <= np.pi + 1e-12)
    other = np.stack([angles[:, 0] - np.pi * np.sign(angles[:, 0]), np.pi * np.sign(angles[:, 1]) - angles[:, 1],
                      angles[:, 2] - np.pi * np.sign(angles[:, 2])], axis=-1)
    assert np.all(np.abs(angles).sum(axis=-1) <= np.abs(other).sum(axis=-1) + 1e-9)
    assert np.abs(R.quat_to_matrix(R.euler_to_quat(other, order)) - R.quat_to_matrix(read)).max() < 1e-9


def test_frame_rate_is_the_bvh_readers():
    """Blender's BVH importer leaves fps_base 0.999999 (30.00003 fps for a 30 fps file): keyfill's reader snaps
    the exported frame time to 30, so the operator does too (else keyfill resamples through its rig bridge)."""
    from types import SimpleNamespace

    _, backend = _extension_modules()

    def rate(fps, base):
        return backend.frame_rate(SimpleNamespace(render=SimpleNamespace(fps=fps, fps_base=base)))

    assert rate(30, 0.999999) == 30.0
    assert rate(24, 1.0) == 24.0
    assert abs(rate(24, 1.001) - 24 / 1.001) < 1e-12  # NTSC rates stay as they are
    assert rate(30, 1.0001) != 30.0
