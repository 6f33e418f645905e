"""``--up-axis`` for BVH input, which records no up axis (Blender exports Z-up BVH): into the outputs' metadata."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import one_error_line, run
from pxr import Usd, UsdGeom

from keyfill import io
from keyfill.errors import UsageError

#: a Z-up chain 20 units tall (Blender's BVH export: Z is up in the file's own numbers), two frames
ZUP = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 100
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 0 10
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head
    {
      OFFSET 0 0 10
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 0 5
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
0 0 100 0 0 0 0 0 0 0 0 0
5 0 100 10 0 0 0 20 0 0 0 0
"""


@pytest.fixture
def zup(tmp_path):
    path = tmp_path / "blender_export.bvh"
    path.write_text(ZUP)
    return path


def test_a_z_up_bvh_lands_z_up_in_usd(capsys, tmp_path, zup):
    out = tmp_path / "shot.usda"
    code, _, err = run(capsys, "convert", zup, out, "--up-axis", "z")  # any case
    assert code == 0, err
    assert UsdGeom.GetStageUpAxis(Usd.Stage.Open(str(out))) == UsdGeom.Tokens.z
    source, back = io.load(zup), io.load(out)
    assert source.skeleton.up_axis == "Y" and back.skeleton.up_axis == "Z"
    np.testing.assert_allclose(back.world_positions(), source.world_positions(), atol=1e-4)  # values unchanged
    assert np.ptp(back.skeleton.rest_world_positions()[:, 2]) == pytest.approx(20.0)  # the height is on Z


def test_complete_takes_the_up_axis_too(capsys, tmp_path, zup):
    out = tmp_path / "filled.usda"
    code, _, err = run(capsys, "complete", zup, "--keys", "0,1", "-o", out, "--up-axis", "Z")
    assert code == 0, err
    assert UsdGeom.GetStageUpAxis(Usd.Stage.Open(str(out))) == UsdGeom.Tokens.z
    code, _, err = run(capsys, "complete", zup, zup, "-o", tmp_path / "many/", "--up-axis", "Z")
    assert code == 2 and "--up-axis take one file" in err


def test_a_z_up_bvh_is_turned_y_up_in_gltf_and_back(capsys, tmp_path, zup):
    out = tmp_path / "shot.gltf"
    code, _, err = run(capsys, "convert", zup, out, "--up-axis", "Z")
    assert code == 0, err
    nodes = {n["name"]: n for n in json.loads(out.read_text())["nodes"]}
    np.testing.assert_allclose(nodes["Hips"]["translation"], [0, 1, 0], atol=1e-12)  # the root turned Y-up, metres
    back = io.load(out)
    assert back.skeleton.up_axis == "Z"
    np.testing.assert_allclose(back.world_positions(), io.load(zup).world_positions(), atol=1e-4)


def test_info_says_which_axis_it_assumed(capsys, tmp_path, zup):
    code, out, _ = run(capsys, "info", zup)
    assert code == 0 and "up axis Y assumed; BVH does not say (--up-axis states it)" in out
    code, out, _ = run(capsys, "info", zup, "--up-axis", "Z", "--json")
    d = json.loads(out)
    assert code == 0 and (d["up_axis"], d["up_axis_assumed"]) == ("Z", False)
    usd = tmp_path / "shot.usda"
    io.save(io.load(zup, up_axis="Z"), usd)
    code, out, _ = run(capsys, "info", usd, "--up-axis", "Y", "--json")  # a file that records its axis keeps it
    d = json.loads(out)
    assert code == 0 and (d["up_axis"], d["up_axis_assumed"]) == ("Z", False)


@pytest.mark.parametrize(("axis", "words"), [("W", "--up-axis must be X, Y or Z, got 'W'"),
                                             ("X", "--up-axis X is not supported")])
def test_an_axis_keyfill_cannot_take_is_one_line(capsys, tmp_path, zup, axis, words):
    out = tmp_path / "shot.usda"
    code, _, err = run(capsys, "convert", zup, out, "--up-axis", axis)
    assert code == 2 and words in one_error_line(err) and not out.exists()
    with pytest.raises(UsageError) as e:
        io.load(zup, up_axis=axis)
    assert e.value.params == ("up_axis",)


def test_a_batch_refuses_the_option(capsys, tmp_path, zup):
    code, _, err = run(capsys, "convert", zup, "-o", tmp_path / "out", "--format", "usda", "--up-axis", "Z")
    assert code == 2 and "--up-axis take one SRC and DST" in one_error_line(err)
