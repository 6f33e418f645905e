"""The command line: info, convert, complete, stdin/stdout pipelines and every bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import DATA

from keyfill import io
from keyfill.cli.main import main
from keyfill.io import bvh

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def assert_one_line_error(err: str, *fragments: str):
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("keyfill: error: ")
    for f in fragments:
        assert f in lines[0], lines[0]
    assert "Traceback" not in err


# --- info and convert -----------------------------------------------------------------


def test_info_json(capsys):
    code, out, _err = run(capsys, "info", MIXAMO, "--json")
    assert code == 0
    d = json.loads(out)
    assert d["frames"] == 69 and d["joints"] == 55 and d["channels"] == 168 and d["fps"] == 30
    assert d["hierarchy"][0]["name"] == "mixamorig:Hips" and d["hierarchy"][0]["euler_order"] == "ZYX"
    assert d["hierarchy"][1]["parent"] == "mixamorig:Hips"
    assert d["keys"] is None
    lo, hi = np.array(d["bounding_box"]["min"]), np.array(d["bounding_box"]["max"])
    assert np.all(hi > lo)


def test_info_text(capsys):
    code, out, _ = run(capsys, "info", CMU)
    assert code == 0
    assert "4 frames at 120 fps" in out and "31 joints, 96 channels" in out
    assert "LeftToeBase" in out


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usd", ".bvh"])
def test_convert_round_trip(capsys, tmp_path, suffix):
    out = tmp_path / ("walk" + suffix)
    code, _, err = run(capsys, "convert", MIXAMO, out)
    assert code == 0 and "wrote" in err
    back = io.load(out)
    m = bvh.read(MIXAMO)
    assert back.skeleton.names == m.skeleton.names
    assert np.abs(back.world_positions() - m.world_positions()).max() < 1e-3


def test_pipeline_through_stdin_and_stdout(tmp_path):
    """`cat walk.bvh | keyfill convert - - ... | keyfill info - ...` as a user types it."""
    exe = [sys.executable, "-m", "keyfill"]
    usda = subprocess.run(
        exe + ["convert", "-", "-", "--in-format", "bvh", "--format", "usda"],
        input=MIXAMO.read_bytes(), capture_output=True, check=True,
    ).stdout
    assert usda.startswith(b"#usda 1.0")
    info = subprocess.run(exe + ["info", "-", "--format", "usda", "--json"], input=usda, capture_output=True, check=True)
    assert json.loads(info.stdout)["frames"] == 69
    bvh_out = subprocess.run(
        exe + ["complete", "-", "-o", "-", "--in-format", "usda", "--format", "bvh", "--key-every", "10"],
        input=usda, capture_output=True, check=True,
    ).stdout
    m = bvh.parse(bvh_out)
    assert m.num_frames == 69 and m.skeleton.names[0] == "mixamorig:Hips"


# --- complete ---------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["linear", "cubic"])
def test_complete_hits_keys_exactly(capsys, tmp_path, method):
    out = tmp_path / "filled.bvh"
    code, stdout, _ = run(capsys, "complete", MIXAMO, "-o", out, "--keys", "0,12,30,68", "--method", method, "--json")
    assert code == 0
    report = json.loads(stdout)
    assert report["keys"] == [0, 12, 30, 68] and report["method"] == method and report["exact_keys"] is True
    src, got = bvh.read(MIXAMO), bvh.read(out)
    written_src = bvh.parse(bvh.dumps(src))  # both through the same 12-digit text
    k = [0, 12, 30, 68]
    np.testing.assert_allclose(got.positions[k], written_src.positions[k], atol=1e-9)
    assert not np.allclose(got.positions[20], src.positions[20])


def test_complete_reads_keys_from_a_sparse_usd_file(capsys, tmp_path):
    m = bvh.read(MIXAMO)
    from keyfill.motion import Keys

    keyfile = tmp_path / "keys.usda"
    io.usd.write(m.replace(keys=Keys([0, 30, 68])), keyfile, sparse=True)
    out = tmp_path / "filled.usda"
    code, stdout, _ = run(capsys, "complete", keyfile, "-o", out, "--json")
    assert code == 0 and json.loads(stdout)["keys"] == [0, 30, 68]
    filled = io.load(out)
    assert filled.num_frames == 69 and filled.keys.to_list() == [0, 30, 68]


def test_complete_is_deterministic(capsys, tmp_path):
    a, b = tmp_path / "a.bvh", tmp_path / "b.bvh"
    for out in (a, b):
        assert run(capsys, "complete", MIXAMO, "-o", out, "--key-every", "7")[0] == 0
    assert a.read_bytes() == b.read_bytes()


# --- bad input: one line, non-zero exit, no output file ----------------------------------

GOOD = MIXAMO.read_text().replace("\r\n", "\n")
HEADER, MOTION = GOOD.split("MOTION\n")
MOTION_LINES = MOTION.splitlines()  # Frames, Frame Time, 69 data lines
FIRST_DATA_LINE = HEADER.count("\n") + 4  # 1-based line number of the first data line


def _with(lines_after_motion):
    return HEADER + "MOTION\n" + "\n".join(lines_after_motion) + "\n"


def _replace_value(line_index, token_index, value):
    lines = list(MOTION_LINES)
    toks = lines[2 + line_index].split()
    toks[token_index] = value
    lines[2 + line_index] = " ".join(toks)
    return _with(lines)


BAD_BVH = {
    "empty": ("", ["the file is empty"]),
    "not bvh": ("hello world\n", ["not a BVH file"]),
    "truncated hierarchy": (HEADER[: len(HEADER) // 2], ["ends early"]),
    "truncated motion": (_with(MOTION_LINES[:40]), ["'Frames: 69' but 38 lines of motion data follow"]),
    "frames count disagrees": (_with(MOTION_LINES + MOTION_LINES[-2:]), ["'Frames: 69' but 71 lines"]),
    "wrong number of values": (
        _with(MOTION_LINES[:7] + [" ".join(MOTION_LINES[7].split()[:-1])] + MOTION_LINES[8:]),
        [f":{FIRST_DATA_LINE + 5}:", "167 values on this line, expected 168"],
    ),
    "nan": (_replace_value(3, 10, "nan"), [f":{FIRST_DATA_LINE + 3}:", "NaN or infinite"]),
    "inf": (_replace_value(9, 0, "-inf"), [f":{FIRST_DATA_LINE + 9}:", "NaN or infinite"]),
    "not a number": (_replace_value(2, 4, "1.2.3"), [f":{FIRST_DATA_LINE + 2}:", "'1.2.3' is not a number"]),
    "unknown channel": (GOOD.replace("Xrotation", "Wrotation", 1), [":5:", "unknown channel 'Wrotation'"]),
    "four channels": (
        GOOD.replace("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 4 Xposition Zrotation Yrotation Xrotation", 1),
        [":9:", "has 4 channels"],
    ),
    "five channels": (
        GOOD.replace("CHANNELS 3 Zrotation Yrotation Xrotation", "CHANNELS 5 Xposition Yposition Zrotation Yrotation Xrotation", 1),
        [":9:", "has 5 channels"],
    ),
    "frame time zero": (GOOD.replace("Frame Time: 0.0333333", "Frame Time: 0"), ["'Frame Time:' must be positive"]),
    "frame time negative": (GOOD.replace("Frame Time: 0.0333333", "Frame Time: -0.1"), ["must be positive"]),
}


@pytest.mark.parametrize("case", sorted(BAD_BVH))
@pytest.mark.parametrize("command", ["convert", "complete"])
def test_bad_bvh_input(capsys, tmp_path, case, command):
    text, fragments = BAD_BVH[case]
    src = tmp_path / "bad.bvh"
    src.write_text(text)
    out = tmp_path / "out.usda"
    args = ["convert", src, out] if command == "convert" else ["complete", src, "-o", out, "--keys", "0,5"]
    code, _stdout, err = run(capsys, *args)
    assert code == 1
    assert_one_line_error(err, "bad.bvh", *fragments)
    assert not out.exists() and list(tmp_path.iterdir()) == [src]


@pytest.mark.parametrize(
    "keys,fragment",
    [("0,99", "key 99 is out of range: the motion has 69 frames"), ("0,5,5", "key 5 appears twice"),
     ("7", "at least 2 keys are needed, got 1"), ("10,3", "keys must be in increasing order"),
     ("0,a", "--keys takes frame numbers"), ("-1,4", "key -1 is negative")],
)
def test_bad_keys(capsys, tmp_path, keys, fragment):
    out = tmp_path / "out.bvh"
    code, _, err = run(capsys, "complete", MIXAMO, "-o", out, "--keys", keys)
    assert code == 2
    assert_one_line_error(err, fragment)
    assert not out.exists()


def test_file_without_keys_needs_key_options(capsys, tmp_path):
    code, _, err = run(capsys, "complete", MIXAMO, "-o", tmp_path / "o.bvh")
    assert code == 2
    assert_one_line_error(err, "records no keys")


def test_unknown_suffix_and_missing_folder_and_missing_file(capsys, tmp_path):
    code, _, err = run(capsys, "convert", MIXAMO, tmp_path / "out.obj")
    assert code == 2 and not (tmp_path / "out.obj").exists()
    assert_one_line_error(err, "unknown file type '.obj'")
    code, _, err = run(capsys, "convert", MIXAMO, tmp_path / "nope" / "out.usda")
    assert code == 2 and not (tmp_path / "nope").exists()
    assert_one_line_error(err, "the output folder", "does not exist")
    code, _, err = run(capsys, "info", tmp_path / "missing.bvh")
    assert code == 2  # a missing path is a usage error in every command (issue 48)
    assert_one_line_error(err, "missing.bvh", "no such file")
    code, _, err = run(capsys, "convert", MIXAMO, "-")
    assert code == 2
    assert_one_line_error(err, "needs --format")


def test_usd_without_skeleton_or_animation(capsys, tmp_path):
    from pxr import Usd, UsdGeom, UsdSkel

    no_skel = tmp_path / "noskel.usda"
    stage = Usd.Stage.CreateNew(str(no_skel))
    UsdGeom.Xform.Define(stage, "/World")
    stage.GetRootLayer().Save()
    code, _, err = run(capsys, "convert", no_skel, tmp_path / "o.bvh")
    assert code == 1 and not (tmp_path / "o.bvh").exists()
    assert_one_line_error(err, "noskel.usda", "no UsdSkel Skeleton")

    no_anim = tmp_path / "noanim.usda"
    stage = Usd.Stage.CreateNew(str(no_anim))
    UsdSkel.Skeleton.Define(stage, "/Skel").CreateJointsAttr(["a"])
    stage.GetRootLayer().Save()
    code, _, err = run(capsys, "convert", no_anim, tmp_path / "o.bvh")
    assert code == 1 and not (tmp_path / "o.bvh").exists()
    assert_one_line_error(err, "noanim.usda", "no UsdSkel SkelAnimation")


def test_usage_errors_are_one_line_with_exit_2(capsys):
    code, _, err = run(capsys, "convert", MIXAMO)
    assert code == 2
    assert_one_line_error(err, "Missing argument 'DST'", "keyfill convert --help")
    code, _, err = run(capsys, "complete", MIXAMO, "-o", "x.bvh", "--method", "magic")
    assert code == 2
    assert_one_line_error(err, "'magic' is not one of")


def test_failed_write_leaves_no_partial_file(capsys, tmp_path):
    """A motion that its BVH layout cannot hold fails before anything appears."""
    m = bvh.read(DATA / "edge_layouts_crlf.bvh")
    pos = m.positions.copy()
    pos[:, 2, 0] += 5  # 'Head' has no position channels
    usd_path = tmp_path / "moved.usda"
    io.save(m.replace(positions=pos), usd_path)
    out = tmp_path / "back.bvh"
    code, _, err = run(capsys, "convert", usd_path, out, "--bvh-layout", "source")
    assert code == 1
    assert_one_line_error(err, "joint 'Head' moves away from its OFFSET at frame 0", "--bvh-layout full gives")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["moved.usda"]


def test_debug_shows_the_traceback(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "keyfill", "--debug", "info", str(tmp_path / "missing.bvh")],
        capture_output=True, text=True, check=False,
    )
    assert r.returncode == 1 and "Traceback" in r.stderr
    r = subprocess.run([sys.executable, "-m", "keyfill", "info", str(tmp_path / "missing.bvh")], capture_output=True, text=True, check=False)
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.startswith("keyfill: error:")
