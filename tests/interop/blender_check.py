"""The keyfill side of the Blender check (runs in keyfill's venv, not Blender's).

Blender's ``bpy`` wheel lives in its own venv, ``.venv-blender`` at the
repository root (it pins numpy<2). :func:`blender_deviation` writes a motion
with keyfill, runs ``blender_world_positions.py`` in that venv as a
subprocess, and compares Blender's bone heads with keyfill's forward
kinematics. Used by ``tests/test_interop.py`` and
``benchmarks/blender_interop.py``.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np

from keyfill import io
from keyfill.io.usd import joint_paths
from keyfill.motion import Motion

ROOT = Path(__file__).resolve().parents[2]
BLENDER_PYTHON = ROOT / ".venv-blender" / "bin" / "python"
SCRIPT = Path(__file__).with_name("blender_world_positions.py")
PYMOTION_SCRIPT = Path(__file__).with_name("pymotion_world_positions.py")
#: how to install the side venv (also quoted in skip messages)
INSTALL = "`make test-interop`, which installs bpy==5.0.1 and upc-pymotion there"


def blender_missing() -> str | None:
    """Why Blender cannot be used here, or None when ``.venv-blender`` has a working ``bpy``."""
    if not BLENDER_PYTHON.exists():
        return f"no Blender venv at {BLENDER_PYTHON.parent.parent} (create it with: {INSTALL})"
    probe = subprocess.run(
        [str(BLENDER_PYTHON), "-c", "import bpy, pymotion; print(bpy.app.version_string)"],
        capture_output=True, text=True, timeout=120, check=False,
    )
    if probe.returncode != 0:
        last = (probe.stderr.strip().splitlines() or ["no output"])[-1]
        return f"bpy or pymotion does not import in {BLENDER_PYTHON}: {last} (install them with: {INSTALL})"
    return None


def blender_world_positions(path: Path, meters_per_unit: float) -> dict:
    """Run Blender on ``path``; the JSON result of ``blender_world_positions.py``."""
    out = Path(str(path) + ".blender.json")
    proc = subprocess.run(
        [str(BLENDER_PYTHON), str(SCRIPT), str(path), "--scale", repr(meters_per_unit), "--out", str(out)],
        capture_output=True, text=True, timeout=600, check=False,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"Blender failed on {path} (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return json.loads(out.read_text())


def to_blender_frame(world: np.ndarray, meters_per_unit: float) -> np.ndarray:
    """Y-up world positions ``(..., 3)`` in file units -> Blender's Z-up meters: ``s * (x, -z, y)``."""
    x, y, z = np.moveaxis(world, -1, 0)
    return meters_per_unit * np.stack([x, -z, y], axis=-1)


def bone_names(motion: Motion, fmt: str) -> list[str]:
    """Blender's bone name for each joint: the BVH or glTF name, or the UsdSkel joint path's last component."""
    if fmt in ("bvh", "gltf"):
        return [n.encode("utf-8")[:63].decode("utf-8", "ignore") for n in motion.skeleton.names]
    return [p.rsplit("/", 1)[-1] for p in joint_paths(motion.skeleton)]


def pymotion_world_positions(path: Path) -> dict:
    """Run pymotion (in Blender's venv) on the BVH file ``path``; the JSON result of
    ``pymotion_world_positions.py``."""
    out = Path(str(path) + ".pymotion.json")
    proc = subprocess.run([str(BLENDER_PYTHON), str(PYMOTION_SCRIPT), str(path), "--out", str(out)],
                          capture_output=True, text=True, timeout=600, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"pymotion failed on {path} (exit {proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return json.loads(out.read_text())


def blender_deviation(
    motion: Motion, folder: Path, suffix: str, expected: Motion | None = None, bvh_layout: str | None = None
) -> tuple[np.ndarray, float, dict]:
    """Write ``motion`` as ``folder/motion<suffix>`` with keyfill, import it in Blender, compare.

    Blender's bone heads are compared with the world joint positions of
    ``expected`` (default: ``motion`` itself). ``bvh_layout``: the layout of a BVH file
    (:func:`keyfill.io.save`).

    Returns ``(per_frame, height, blender_result)``: per frame ``(F,)``, the
    largest distance between a Blender bone head and keyfill's world joint
    position, in file units; the skeleton's rest height (extent along Y, same
    units); the JSON result of the Blender script.
    """
    expected = motion if expected is None else expected
    path = Path(folder) / f"motion{suffix}"
    io.save(motion, path, bvh_layout=bvh_layout if suffix == ".bvh" else None)
    sk = motion.skeleton
    result = blender_world_positions(path, sk.meters_per_unit)
    fmt = {".bvh": "bvh", ".glb": "gltf", ".gltf": "gltf"}.get(suffix, "usd")
    if result["frames"] != motion.num_frames:
        raise AssertionError(f"Blender sees {result['frames']} frames, keyfill wrote {motion.num_frames}")
    names = bone_names(motion, fmt)
    missing = [n for n in names if n not in result["bones"]]
    if missing:
        raise AssertionError(f"Blender has no bone {missing[0]!r}; its bones: {result['bones']}")
    blender = np.asarray(result["positions"], dtype=np.float64)[:, [result["bones"].index(n) for n in names]]
    want = to_blender_frame(expected.world_positions(), sk.meters_per_unit)
    per_frame = np.linalg.norm(blender - want, axis=-1).max(axis=-1) / sk.meters_per_unit
    height = float(np.ptp(sk.rest_world_positions()[:, 1]))
    return per_frame, height, result
