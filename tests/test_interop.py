"""keyfill against independent readers: bvhio (default suite) and Blender (``-m interop``).

Both compare world joint positions, the quantity that every reader must agree
on whatever its internal conventions: keyfill's forward kinematics
(``Motion.world_positions()``) against bvhio's ``PositionWorld`` and against
the bone heads that Blender computes after importing keyfill's BVH and USD
output. Each shared fixture is checked as it came and, for bvhio, also after
keyfill wrote it back, so the writer is checked by a peer too. The CMU and
Mixamo copies in ``tests/data`` keep the bvhio check alive without the shared
folder; the Bandai fixtures (6 channels on every joint) come from it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import BVH_FIXTURES, DATA, shared_path

from keyfill import io
from keyfill.motion import Motion

sys.path.insert(0, str(Path(__file__).parent / "interop"))
from blender_check import blender_deviation, blender_missing, pymotion_world_positions

#: bvhio reads one ROOT per file, so the local edge-layout fixtures are not for it
LOCAL_FIXTURES = ["cmu_02_03_cgspeed_first4frames.bvh", "bvhtoolbox_test_freebvh_mixamo.bvh"]
SHARED_ONLY = sorted(p.name for p in BVH_FIXTURES.glob("*.bvh") if p.name not in LOCAL_FIXTURES) or ["(absent)"]
#: bvhio keeps transforms in float32 (glm.vec3 / glm.quat): tolerance relative to the skeleton's height
BVHIO_TOL = 1e-4
#: Blender works in float32 too; the issue's bound, relative to the skeleton's height
BLENDER_TOL = 1e-4


def height(motion: Motion) -> float:
    """The skeleton's rest height (extent along Y of the rest pose), in file units."""
    return float(np.ptp(motion.skeleton.rest_world_positions()[:, 1]))


def bvhio_world_positions(path: Path, names: tuple[str, ...]) -> np.ndarray:
    """bvhio's world position of every joint ``(F, J, 3)``, joints in the order of ``names``."""
    bvhio = pytest.importorskip("bvhio")
    root = bvhio.readAsHierarchy(str(path))
    joints = {joint.Name: joint for joint, _, _ in root.layout()}
    assert sorted(joints) == sorted(names), "bvhio sees other joints than keyfill"
    order = [joints[n] for n in names]
    num_frames = len(root.Keyframes)
    out = np.empty((num_frames, len(names), 3))
    for f in range(num_frames):
        root.loadPose(f)
        out[f] = [tuple(j.PositionWorld) for j in order]
    return out


def fixture(name: str) -> Path:
    return shared_path("bvh_fixtures", name)


@pytest.mark.parametrize(
    "path", [DATA / n for n in LOCAL_FIXTURES] + [BVH_FIXTURES / n for n in SHARED_ONLY], ids=lambda p: p.name
)
def test_world_positions_match_bvhio(path, tmp_path):
    if not path.exists():
        path = shared_path("bvh_fixtures", path.name)  # skips with the reason
    name = path.name
    motion = io.load(path)
    ours = motion.world_positions()
    tol = BVHIO_TOL * height(motion)

    theirs = bvhio_world_positions(path, motion.skeleton.names)
    assert theirs.shape == ours.shape
    assert np.abs(theirs - ours).max() < tol

    # keyfill's own output, read by bvhio, gives the same world positions.
    written = tmp_path / name
    io.save(motion, written)
    theirs_written = bvhio_world_positions(written, motion.skeleton.names)
    assert np.abs(theirs_written - ours).max() < tol


def test_bvhio_comparison_can_fail(tmp_path):
    """The check above is not vacuous: one changed channel value is caught."""
    motion = io.load(DATA / "bvhtoolbox_test_freebvh_mixamo.bvh")
    rot = motion.rotations.copy()
    rot[5, 1] = [np.cos(0.05), 0, np.sin(0.05), 0]  # frame 5: the first spine joint's rotation replaced by 0.1 rad about Y
    io.save(motion.replace(rotations=rot), tmp_path / "changed.bvh")
    theirs = bvhio_world_positions(tmp_path / "changed.bvh", motion.skeleton.names)
    dev = np.abs(theirs - motion.world_positions()).max(axis=(1, 2))
    assert dev[5] > 100 * BVHIO_TOL * height(motion)
    assert np.delete(dev, 5).max() < BVHIO_TOL * height(motion)


# --- Blender (optional: pytest -m interop) -----------------------------------

#: one fixture per layout: 6 channels on every joint (ZXY), 3 channels ZYX with a
#: 120 fps T-pose (CMU), ZYX with ``:`` in every name (Mixamo)
BLENDER_FIXTURES = [
    "dataset-1_dash_normal_001.bvh",
    "cmu_02_03_cgspeed_first4frames.bvh",
    "bvhtoolbox_test_freebvh_mixamo.bvh",
]


@pytest.fixture(scope="module")
def blender():
    why = blender_missing()
    if why:
        pytest.skip(why)


@pytest.mark.interop
@pytest.mark.parametrize("suffix", [".bvh", ".usda", ".usdc", ".glb"])
@pytest.mark.parametrize("name", BLENDER_FIXTURES)
def test_blender_imports_keyfill_output_with_same_world_positions(blender, name, suffix, tmp_path):
    motion = io.load(fixture(name))
    per_frame, h, result = blender_deviation(motion, tmp_path, suffix)
    assert result["frames"] == motion.num_frames == len(per_frame)
    worst = per_frame.max()
    assert worst < BLENDER_TOL * h, f"Blender deviates by {worst:.3g} units ({worst / h:.2g} of the height)"


@pytest.mark.interop
@pytest.mark.parametrize("suffix", [".bvh", ".usda", ".glb"])
def test_blender_comparison_can_fail(blender, suffix, tmp_path):
    """A file whose Hips rotation at frame 5 is replaced (0.1 rad about Y) is caught at frame 5 only."""
    motion = io.load(fixture("dataset-1_walk_normal_002.bvh"))
    rot = motion.rotations.copy()
    rot[5, 1] = [np.cos(0.05), 0, np.sin(0.05), 0]
    per_frame, h, _ = blender_deviation(motion.replace(rotations=rot), tmp_path, suffix, expected=motion)
    assert per_frame[5] > 100 * BLENDER_TOL * h
    assert np.delete(per_frame, 5).max() < BLENDER_TOL * h


# --- every BVH layout keyfill writes, in Blender and pymotion (pytest -m interop) ---------------------

#: (case, source, --bvh-layout): the lamp from its USD (one rotation channel per joint recorded; auto writes it
#: full), the edge layouts (two roots, 0 to 6 channels) forced full, and mocap (already full) kept as it is
BVH_LAYOUTS = [
    ("lamp-auto", Path(__file__).parents[1] / "examples" / "lamp" / "truth.usda", None),
    ("edges-full", DATA / "edge_layouts_crlf.bvh", "full"),
    ("cmu-source", DATA / "cmu_02_03_cgspeed_first4frames.bvh", "source"),
]
#: the issue's bound for every layout, relative to the skeleton's height
LAYOUT_TOL = 1e-5


@pytest.mark.interop
@pytest.mark.parametrize("case, source, layout", BVH_LAYOUTS, ids=[c[0] for c in BVH_LAYOUTS])
def test_blender_and_pymotion_import_every_bvh_layout_keyfill_writes(blender, case, source, layout, tmp_path):
    motion = io.load(source)
    per_frame, h, result = blender_deviation(motion, tmp_path, ".bvh", bvh_layout=layout)
    assert result["frames"] == motion.num_frames
    assert per_frame.max() < LAYOUT_TOL * h, f"Blender deviates by {per_frame.max() / h:.2g} of the height"
    written = io.load(tmp_path / "motion.bvh")
    assert written.skeleton.has_full_layout
    theirs = pymotion_world_positions(tmp_path / "motion.bvh")
    assert theirs["names"] == list(motion.skeleton.names)
    assert np.abs(np.asarray(theirs["positions"]) - motion.world_positions()).max() < LAYOUT_TOL * h


@pytest.mark.interop
def test_blender_and_pymotion_refuse_the_lamps_own_layout(blender, tmp_path):
    """Why auto writes the lamp full: its own layout (one rotation channel per joint) stops both readers."""
    motion = io.load(BVH_LAYOUTS[0][1])
    with pytest.raises(RuntimeError, match="Blender failed"):
        blender_deviation(motion, tmp_path, ".bvh", bvh_layout="source")
    with pytest.raises(RuntimeError, match="pymotion failed"):
        pymotion_world_positions(tmp_path / "motion.bvh")
