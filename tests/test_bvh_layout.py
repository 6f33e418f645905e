"""BVH channel layouts of outputs (issue 43): ``--bvh-layout auto|source|full``.

Blender's BVH importer (``KeyError: (2, None, None)``) and pymotion refuse joints with fewer than three rotation
channels; the lamp (whose USD records its own layout: one rotation channel per joint) and BVH edge layouts have
them. ``full`` writes three rotations on every joint and three positions on roots and translating joints;
``auto`` keeps a BVH source's layout (a BVH-to-BVH round trip stays lossless) and a layout already full, and
writes the others full. Blender itself imports each layout in ``tests/test_interop.py`` (``-m interop``).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA, one_error_line, run

from keyfill import io
from keyfill.characters import lamp
from keyfill.motion import FULL_ROTATIONS

EDGES = DATA / "edge_layouts_crlf.bvh"  # two roots, 0 to 6 channels per joint, a root with 2 position channels
CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"
LAMP = DATA.parent.parent / "examples" / "lamp" / "keys.usda"


def channels(path) -> list[list[str]]:
    """The channel names of each ``CHANNELS`` line of a BVH file, in file order."""
    return [line.split()[2:] for line in path.read_text().splitlines() if line.strip().startswith("CHANNELS")]


def world_error(a, b) -> float:
    """The largest world joint position difference, relative to the larger extent of ``a``."""
    scale = max(1.0, float(np.ptp(a.world_positions(), axis=(0, 1)).max()))
    return float(np.abs(a.world_positions() - b.world_positions()).max()) / scale


def test_the_full_layout_holds_the_same_motion(tmp_path):
    m = io.load(EDGES)
    assert not m.skeleton.has_full_layout
    full = m.skeleton.full_layout()
    assert full.has_full_layout and full.full_layout().channels == full.channels
    assert full.names == m.skeleton.names and np.array_equal(full.parents, m.skeleton.parents)
    # each joint's rotation order is kept, completed with the axes it lacked
    assert [o for o in full.euler_orders] == list(m.skeleton.euler_orders[:2]) + ["ZXY"] + \
        list(m.skeleton.euler_orders[3:])  # 'Head' (CHANNELS 0) gets the mocap order
    assert full.channels[2] == FULL_ROTATIONS
    assert full.channels[1] == ("Xrotation", "Zrotation", "Yrotation")  # 'Spine-1' was 'Xrotation Zrotation'
    io.save(m, tmp_path / "full.bvh", bvh_layout="full")
    back = io.load(tmp_path / "full.bvh")
    assert back.skeleton.channels == full.channels
    assert world_error(m, back) < 1e-10
    assert back.skeleton.full_layout().channels == back.skeleton.channels  # a full layout stays as it is


def test_the_full_layout_gives_moving_joints_position_channels(capsys, tmp_path):
    """'Head' (CHANNELS 0) moved in USD: its own layout cannot hold that (one line naming the way out); auto and
    full give it position channels."""
    m = io.load(EDGES)
    pos = m.positions.copy()
    pos[:, 2, 0] += 5
    moved = m.replace(positions=pos)
    io.save(moved, tmp_path / "moved.usda")
    code, _, err = run(capsys, "convert", tmp_path / "moved.usda", tmp_path / "own.bvh", "--bvh-layout", "source")
    assert code == 1 and "--bvh-layout full gives" in one_error_line(err)
    assert run(capsys, "convert", tmp_path / "moved.usda", tmp_path / "auto.bvh")[0] == 0
    back = io.load(tmp_path / "auto.bvh")
    assert back.skeleton.channels[2] == ("Xposition", "Yposition", "Zposition", *FULL_ROTATIONS)
    assert world_error(moved, back) < 1e-6  # UsdSkel keeps translations in float32


def test_a_bvh_source_keeps_its_layout_by_default(capsys, tmp_path):
    """BVH to BVH stays lossless: the edge layouts come back line for line (convert and complete alike)."""
    assert run(capsys, "convert", EDGES, tmp_path / "same.bvh")[0] == 0
    assert channels(tmp_path / "same.bvh") == channels(EDGES)
    assert run(capsys, "complete", EDGES, "--keys", "0,1,2", "-o", tmp_path / "done.bvh")[0] == 0
    assert channels(tmp_path / "done.bvh") == channels(EDGES)
    # a completion that turns 'Spine-1' (Xrotation Zrotation) about Y too fits only a full layout
    code, _, err = run(capsys, "complete", EDGES, "--keys", "0,2", "-o", tmp_path / "cubic.bvh")
    assert code == 1 and "its channels (Xrotation Zrotation) cannot hold" in one_error_line(err)
    code, _, err = run(capsys, "complete", EDGES, "--keys", "0,2", "-o", tmp_path / "cubic.bvh", "--bvh-layout", "full")
    assert code == 0, err
    assert run(capsys, "convert", EDGES, tmp_path / "full.bvh", "--bvh-layout", "full")[0] == 0
    assert all(len([c for c in cs if c.endswith("rotation")]) == 3 for cs in channels(tmp_path / "full.bvh"))


def test_the_lamp_from_usd_is_written_full_and_stays_a_lamp(capsys, tmp_path):
    """The lamp's USD records one rotation channel per joint: its BVH is written full (auto), and that file is
    still a lamp: the ARNN completes it."""
    out = tmp_path / "lamp.bvh"
    assert run(capsys, "convert", LAMP, out)[0] == 0
    assert channels(out) == [["Xposition", "Yposition", "Zposition", *FULL_ROTATIONS]] + [list(FULL_ROTATIONS)] * 3
    back = io.load(out)
    assert lamp.is_lamp(back.skeleton)
    assert world_error(io.load(LAMP), back) < 1e-10
    code, _, err = run(capsys, "complete", out, "--method", "arnn", "--key-every", "10", "-o", tmp_path / "a.bvh")
    assert code == 0, err
    assert channels(tmp_path / "a.bvh") == channels(out)
    # --bvh-layout source writes the lamp's own layout
    assert run(capsys, "convert", LAMP, tmp_path / "own.bvh", "--bvh-layout", "source")[0] == 0
    assert channels(tmp_path / "own.bvh") == [list(c) for c in lamp.CHANNELS]


def test_a_full_layout_is_kept_whatever_the_source(capsys, tmp_path):
    """A layout already full (mocap: CMU) is the same through USD and glTF under auto."""
    for suffix in (".usda", ".glb"):
        mid = tmp_path / f"cmu{suffix}"
        assert run(capsys, "convert", CMU, mid)[0] == 0
        assert run(capsys, "convert", mid, tmp_path / f"back{suffix}.bvh")[0] == 0
        assert channels(tmp_path / f"back{suffix}.bvh") == channels(CMU)


def test_a_batch_lays_out_its_bvh_outputs_and_records_the_layout(capsys, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    (src / "lamp.usda").write_bytes(LAMP.read_bytes())
    (src / "edges.bvh").write_bytes(EDGES.read_bytes())
    out = tmp_path / "out"
    assert run(capsys, "convert", src, "-o", f"{out}/", "--format", "bvh", "--bvh-layout", "source")[0] == 0
    assert channels(out / "lamp.bvh") == [list(c) for c in lamp.CHANNELS]
    assert channels(out / "edges.bvh") == channels(EDGES)
    # another layout is another recipe: both outputs are redone
    code, _, err = run(capsys, "convert", src, "-o", f"{out}/", "--format", "bvh", "--bvh-layout", "full")
    assert code == 0, err
    assert io.load(out / "lamp.bvh").skeleton.has_full_layout and io.load(out / "edges.bvh").skeleton.has_full_layout
    # without --format, the layout applies to the BVH outputs only
    mixed = tmp_path / "mixed"
    code, _, err = run(capsys, "convert", src, "-o", f"{mixed}/", "--bvh-layout", "full")
    assert code == 0, err
    assert io.load(mixed / "edges.bvh").skeleton.has_full_layout and (mixed / "lamp.usda").is_file()


@pytest.mark.parametrize("args", [
    ("convert", EDGES, "{tmp}/x.usda", "--bvh-layout", "full"),
    ("complete", EDGES, "--keys", "0,2", "-o", "{tmp}/x.glb", "--bvh-layout", "source"),
    ("convert", EDGES, "-o", "{tmp}/x/", "--format", "usdc", "--bvh-layout", "full"),
    ("convert", EDGES, "{tmp}/x.usda", "--curves", "--keys", "0,2", "--bvh-layout", "full"),
])
def test_a_layout_for_an_output_that_is_not_bvh_is_refused(capsys, tmp_path, args):
    code, _, err = run(capsys, *[str(a).format(tmp=tmp_path) for a in args])
    assert code == 2
    assert "--bvh-layout" in one_error_line(err)
    assert not list(tmp_path.iterdir())


def test_an_unknown_layout_is_refused(capsys, tmp_path):
    code, _, err = run(capsys, "convert", EDGES, tmp_path / "x.bvh", "--bvh-layout", "blender")
    assert code == 2 and "'blender' is not one of" in one_error_line(err)
    with pytest.raises(Exception, match="unknown BVH layout 'blender'"):
        io.save(io.load(EDGES), tmp_path / "y.bvh", bvh_layout="blender")
    assert not list(tmp_path.iterdir())


def test_bvhio_reads_the_lamp_written_full(capsys, tmp_path):
    """bvhio (float32) gives the lamp's world positions from keyfill's full-layout BVH (Blender and pymotion do
    too: tests/test_interop.py, -m interop)."""
    bvhio = pytest.importorskip("bvhio")
    out = tmp_path / "lamp.bvh"
    assert run(capsys, "convert", LAMP, out)[0] == 0
    motion = io.load(out)
    root = bvhio.readAsHierarchy(str(out))
    joints = {joint.Name: joint for joint, _, _ in root.layout()}
    theirs = np.empty((motion.num_frames, motion.num_joints, 3))
    for f in range(motion.num_frames):
        root.loadPose(f)
        theirs[f] = [tuple(joints[n].PositionWorld) for n in motion.skeleton.names]
    height = float(np.ptp(motion.skeleton.rest_world_positions()[:, 1]))
    assert np.abs(theirs - motion.world_positions()).max() < 1e-5 * height
