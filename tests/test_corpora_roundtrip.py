"""Every clip of the Bandai-Namco corpora survives BVH -> BVH and BVH -> USD -> BVH.

BVH -> BVH reproduces every rotation (angle below 1e-6 rad) and translation
(1e-6 units); BVH -> USD -> BVH keeps world joint positions within 1e-4 of the
skeleton's height (USD stores 32-bit floats); written Euler curves have no
360-degree jumps. Dataset-1 runs by default, dataset-2 (2,501 clips) is `slow`.
"""

import numpy as np
import pytest

from keyfill import rotations as R
from keyfill.errors import DataError
from keyfill.io import bvh, usd
from keyfill.learn.corpus import locate
from keyfill.motion import ROTATION_CHANNELS


def corpus_files(name):
    try:
        folder = locate(name)
    except DataError as e:
        pytest.skip(f"needs the {name} corpus: {e}")
    return sorted(folder.glob("*.bvh"))


def check_clip(path, tmp_path):
    m = bvh.read(path)
    text = bvh.dumps(m)
    again = bvh.parse(text)
    angle = R.quat_angle(m.rotations, again.rotations).max()
    shift = np.abs(m.positions - again.positions).max()
    assert angle < 1e-6, f"{path.name}: rotation off by {angle:.2e} rad"
    assert shift < 1e-6, f"{path.name}: translation off by {shift:.2e}"

    values = bvh.pose_to_channels(again)
    is_rot = np.array([c in ROTATION_CHANNELS for chans in m.skeleton.channels for c in chans])
    jump = np.abs(np.diff(values[:, is_rot], axis=0)).max(initial=0)
    assert jump < 180, f"{path.name}: an Euler curve jumps {jump:.1f} degrees between frames"

    out = tmp_path / "clip.usdc"
    usd.write(m, out)
    back = bvh.parse(bvh.dumps(usd.read(out)))
    height = np.ptp(m.skeleton.rest_world_positions()[:, 1])
    err = np.abs(back.world_positions() - m.world_positions()).max()
    assert err < 1e-4 * height, f"{path.name}: world positions off by {err:.2e} (height {height:.1f})"
    assert back.skeleton.channels == m.skeleton.channels and back.skeleton.names == m.skeleton.names


def test_bandai_dataset1_every_clip(tmp_path):
    files = corpus_files("bandai1")
    assert len(files) == 174
    for path in files:
        check_clip(path, tmp_path)


@pytest.mark.slow
def test_bandai_dataset2_every_clip(tmp_path):
    files = corpus_files("bandai2")
    assert len(files) == 2501
    for path in files:
        check_clip(path, tmp_path)
