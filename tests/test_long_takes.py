"""Long takes (issue 44): the streaming BVH reader, writer and template, and the baselines' blocks give the
same numbers whatever the chunk or block size; a 100,000-frame take round-trips through BVH and glTF."""

from pathlib import Path

import numpy as np
import pytest
from conftest import DATA

from keyfill import interpolate, io
from keyfill import rotations as R
from keyfill.io import bvh, bvh_values
from keyfill.learn.registry import complete
from keyfill.motion import Keys, Motion

CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"


def long_motion(frames: int, seed: int = 0) -> Motion:
    """The CMU fixture's skeleton (31 joints) moving smoothly for ``frames`` frames: each joint's rotation
    and the root's position a random walk, the root turning through many whole turns."""
    base = bvh.read(CMU)
    rng = np.random.default_rng(seed)
    J = base.skeleton.num_joints
    rotvec = np.cumsum(rng.normal(scale=0.02, size=(frames, J, 3)), axis=0)
    rotvec[:, 0, 1] = np.linspace(0, 40 * np.pi, frames)  # 20 turns about the vertical
    rot = R.quat_mul(base.rotations[:1], R.quat_from_rotvec(rotvec))
    pos = np.broadcast_to(base.positions[:1], (frames, J, 3)).copy()
    pos[:, 0] += np.cumsum(rng.normal(scale=0.5, size=(frames, 3)), axis=0)
    return base.replace(rotations=R.quat_normalize(rot), positions=pos)


def test_the_reader_gives_the_same_numbers_in_any_chunk_size(tmp_path, monkeypatch):
    """A file streamed in chunks shorter than a line (and a header read 50 bytes at a time) reads as the
    whole text parsed at once."""
    path = tmp_path / "walk.bvh"
    bvh.write(long_motion(300), path)
    whole = bvh.parse(path.read_bytes())
    monkeypatch.setattr(bvh_values, "CHUNK_BYTES", 100)
    monkeypatch.setattr(bvh, "HEAD_BYTES", 50)
    streamed = bvh.read(path)
    assert np.array_equal(streamed.rotations, whole.rotations)
    assert np.array_equal(streamed.positions, whole.positions)


def test_a_short_file_is_refused_with_its_line_when_streamed(tmp_path, monkeypatch):
    text = bvh.dumps(long_motion(50)).replace("Frames: 50", "Frames: 60")
    path = tmp_path / "short.bvh"
    path.write_text(text)
    monkeypatch.setattr(bvh_values, "CHUNK_BYTES", 100)
    with pytest.raises(io.FormatError, match="'Frames: 60' but 50 lines"):
        bvh.read(path)


def test_the_template_is_followed_the_same_in_any_chunk_size(tmp_path, monkeypatch):
    """A completion written next to its input keeps the input's own numbers at the keys, streaming the input
    a few rows at a time or all at once: the same bytes."""
    src = tmp_path / "in.bvh"
    bvh.write(long_motion(400), src)
    motion = bvh.read(src)
    result = complete(motion, Keys(np.arange(0, 400, 37)), "cubic").motion
    bvh.write(result, tmp_path / "whole.bvh", template=src)
    monkeypatch.setattr(bvh_values, "CHUNK_BYTES", 333)
    bvh.write(result, tmp_path / "chunked.bvh", template=src)
    assert (tmp_path / "chunked.bvh").read_bytes() == (tmp_path / "whole.bvh").read_bytes()
    # and the keys print as the input printed them
    given = bvh.parse_values(src.read_bytes())[2]
    written = bvh.parse_values((tmp_path / "whole.bvh").read_bytes())[2]
    assert np.array_equal(written[::37], given[::37])


def test_euler_curves_continue_across_blocks():
    """Blocks of 7 frames give the curves one block gives (to rounding): the 20 turns of the root unwrap
    across every block boundary, none is wrapped back."""
    motion = long_motion(500)
    small = np.concatenate([a for _, a in motion.euler_blocks(block=7)])
    whole = np.concatenate([a for _, a in motion.euler_blocks(block=10**6)])
    assert np.abs(small - whole).max() < 1e-9
    assert np.ptp(small[:, 0]) > 30 * np.pi  # the turns are there, not wrapped away


@pytest.mark.parametrize("method", ["cubic", "linear"])
def test_the_baselines_are_the_same_in_any_block_size(method, monkeypatch):
    motion = long_motion(1000)
    keys = Keys(np.arange(0, 1000, 29))
    whole = complete(motion, keys, method).motion
    monkeypatch.setattr(interpolate, "BLOCK", 13)
    blocks = complete(motion, keys, method).motion
    assert np.array_equal(whole.rotations, blocks.rotations)
    assert np.array_equal(whole.positions, blocks.positions)


@pytest.mark.slow  # about 10 s of CPU per format
@pytest.mark.parametrize("suffix", [".bvh", ".glb", ".gltf"])  # .usda, .usdc: tests/test_usd_scale.py
def test_a_100k_frame_take_round_trips(suffix, tmp_path):
    """100,000 frames of 31 joints (at 120 fps: 14 minutes, beyond the times 32-bit floats hold to a
    frame's thousandth): read back as written (BVH: to its 12 digits, glTF: to float32); a BVH written
    again, following the first file, is the same bytes."""
    motion = long_motion(100_000)
    (tmp_path / "again").mkdir()  # the same name in another folder (glTF names its animation after it)
    first, second = tmp_path / ("take" + suffix), tmp_path / "again" / ("take" + suffix)
    io.save(motion, first)
    back = io.load(first)
    assert back.num_frames == 100_000 and back.skeleton.names == motion.skeleton.names
    tol = 1e-6 if suffix == ".bvh" else 1e-5
    height = np.ptp(motion.skeleton.rest_world_positions()[:, 1])
    assert R.quat_angle(back.rotations, motion.rotations).max() < tol
    assert np.abs(back.positions - motion.positions).max() < tol * max(height, np.abs(motion.positions).max())
    if suffix == ".bvh":
        io.save(back, second, source=first)
        assert Path(second).read_bytes() == Path(first).read_bytes()


def test_a_gltf_may_describe_as_much_as_its_bin_file_holds(tmp_path, monkeypatch):
    """The bound on frames x joints a file may describe counts the .bin a .gltf names, not its JSON alone
    (100,000 frames in a .gltf were refused as 'more than a 23186-byte file can describe')."""
    monkeypatch.setenv("KEYFILL_FREE_JOINT_FRAMES", "1")  # (almost) no allowance beyond the files' bytes
    motion = long_motion(2000)
    io.save(motion, tmp_path / "take.gltf")
    assert (tmp_path / "take.gltf").stat().st_size < 2000 * (31 + 8)  # the JSON alone could not describe it
    assert io.load(tmp_path / "take.gltf").num_frames == 2000


@pytest.mark.parametrize("rows", [1, 7, 65_536])
def test_the_writers_value_check_names_the_first_bad_number_in_any_block_size(rows, monkeypatch):
    """limits.check_values looks at the positions a block of frames at a time (no full-size temporary before
    every writer): whatever the block, it names the first frame and joint beyond the limit, as one look at
    the whole array did."""
    from keyfill import limits
    from keyfill.errors import DataError

    monkeypatch.setattr(limits, "CHECK_ROWS", rows)
    m = long_motion(40)
    limits.check_values(m)
    pos = m.positions.copy()
    pos[23, 4, 2], pos[31, 2, 0] = 1e14, -1e15
    with pytest.raises(DataError, match=f"joint {m.skeleton.names[4]!r} at frame 23 is beyond"):
        limits.check_values(m.replace(positions=pos))


@pytest.mark.parametrize("rows", [1, 7, 65_536])
def test_a_motion_names_its_first_frame_that_is_not_finite_in_any_block_size(rows, monkeypatch):
    """A Motion checks its values a block of frames at a time (no whole-take temporary each time one is made):
    whatever the block, it names the first frame holding a value that is not finite."""
    from keyfill import motion as motion_module
    from keyfill.errors import DataError

    monkeypatch.setattr(motion_module, "FINITE_BLOCK", rows)
    m = long_motion(40)
    rot, pos = m.rotations.copy(), m.positions.copy()
    rot[29, 3, 2], pos[17, 5, 0] = np.nan, np.inf
    with pytest.raises(DataError, match="frame 17 holds a value that is not finite"):
        m.replace(rotations=rot, positions=pos)
    with pytest.raises(DataError, match="frame 29 holds a value that is not finite"):
        m.replace(rotations=rot)
