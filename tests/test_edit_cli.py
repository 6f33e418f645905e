"""The CLI of tangent editing: convert --curves, edit-tangents, pose; bad edit files; infeasible edits."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_edit_character import character

from keyfill import io
from keyfill import rotations as R
from keyfill.cli.main import main
from keyfill.io import usd_curves

REACH = """
pins = ["Hips"]

[[contact]]
joint = "Toes_L"
frames = [10, 20]

[[edit]]
joint = "Hand_L"
frame = 15
move = [0, 8, 4]
"""


@pytest.fixture()
def curves_file(tmp_path, capsys):
    src = tmp_path / "wave.bvh"
    io.save(character(), src)
    out = tmp_path / "wave_curves.usda"
    assert main(["convert", str(src), str(out), "--curves", "--keys", "0,10,20,30,40"]) == 0
    capsys.readouterr()
    return out


def run(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_convert_edit_and_back(tmp_path, capsys, curves_file):
    edit = tmp_path / "reach.toml"
    edit.write_text(REACH)
    out = tmp_path / "edited.usda"
    code, stdout, err = run(capsys, "edit-tangents", curves_file, "--edit", edit, "-o", out, "--json")
    assert code == 0, err
    report = json.loads(stdout)["edits"][0]
    for key in (
        "iterations",
        "distance",
        "worst_pin_violation",
        "worst_contact_violation",
        "worst_limit_margin",
        "optimised_tangents",
        "solve_ms",
    ):
        assert key in report
    assert report["reached"] and report["iterations"] >= 1 and report["optimised_tangents"] > 0
    assert "edit 1: Hand_L at frame 15 reached its target" in err
    bvh = tmp_path / "edited.bvh"
    assert run(capsys, "convert", out, bvh)[0] == 0
    before, after = io.load(curves_file), io.load(bvh)
    hand = before.skeleton.index("Hand_L")
    moved = after.world_positions()[15, hand] - before.world_positions()[15, hand]
    np.testing.assert_allclose(moved, [0, 8, 4], atol=0.2)
    keys = [0, 10, 20, 30, 40]
    assert R.quat_angle(after.rotations[keys], before.rotations[keys]).max() < 1e-6  # BVH text keeps ~1e-9


def test_same_inputs_give_the_same_bytes(tmp_path, capsys, curves_file):
    edit = tmp_path / "reach.toml"
    edit.write_text(REACH)
    for name in ("a", "b"):  # one file name: the animation is named after the output's stem
        (tmp_path / name).mkdir()
        assert run(capsys, "edit-tangents", curves_file, "--edit", edit, "-o", tmp_path / name / "out.usda")[0] == 0
    assert (tmp_path / "a" / "out.usda").read_bytes() == (tmp_path / "b" / "out.usda").read_bytes()


BAD = {
    "unknown joint": (
        "[[edit]]\njoint = 'Hnad_L'\nframe = 15\nmove = [0, 1, 0]\n",
        "edit 1: unknown joint 'Hnad_L'",
        1,
    ),
    "frame outside": (
        "[[edit]]\njoint = 'Hand_L'\nframe = 55\nmove = [0, 1, 0]\n",
        "frame 55 is outside the curves",
        1,
    ),
    "target nan": ("[[edit]]\njoint = 'Hand_L'\nframe = 15\ntarget = [0, nan, 0]\n", "target is nan", 1),
    "contact between keys": (
        "[[contact]]\njoint = 'Toes_L'\nframes = [10, 15]\n[[edit]]\njoint = 'Hand_L'\nframe = 15\nmove = [0, 1, 0]\n",
        "frame 15 is not a key (keys: 0, 10, 20, 30, 40)",
        1,
    ),
    "limits the keys break": (
        "[limits]\n'LowerArm_L.Yrotation' = [0, 50]\n[[edit]]\njoint = 'Hand_L'\nframe = 15\nmove = [0, 1, 0]\n",
        "the key at frame 10 is already outside it",
        2,
    ),
    "frame at a key": ("[[edit]]\njoint = 'Hand_L'\nframe = 20\nmove = [0, 1, 0]\n", "frame 20 is a key", 1),
    "typo": ("[[edit]]\njoint = 'Hand_L'\nframe = 15\nmvoe = [0, 1, 0]\n", "unknown field 'mvoe'", 1),
    "not toml": ("[[edit]\njoint = 'Hand_L'\n", "not valid TOML", 1),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_edit_files_give_one_clear_error_and_no_output(tmp_path, capsys, curves_file, case):
    text, message, line = BAD[case]
    edit = tmp_path / "bad.toml"
    edit.write_text(text)
    out = tmp_path / "out.usda"
    code, stdout, err = run(capsys, "edit-tangents", curves_file, "--edit", edit, "-o", out)
    assert code == 1 and stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"keyfill: error: {edit}:{line}: ") and message in lines[0]
    assert not out.exists() and list(tmp_path.glob(".out*")) == []


def test_infeasible_edit_writes_nothing_unless_best_effort(tmp_path, capsys, curves_file):
    edit = tmp_path / "lift.toml"
    edit.write_text(
        "[[contact]]\njoint = 'Toes_L'\nframes = [10, 20]\n[[contact]]\njoint = 'Toes_R'\nframes = [10, 20]\n"
        "[[edit]]\njoint = 'Hips'\nframe = 15\nmove = [0, 40, 0]\n"
    )
    out = tmp_path / "out.usda"
    code, _, err = run(capsys, "edit-tangents", curves_file, "--edit", edit, "-o", out)
    assert code == 1 and "conflicting constraints: contact Toes_" in err and "nothing written" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()
    code, stdout, err = run(capsys, "edit-tangents", curves_file, "--edit", edit, "-o", out, "--best-effort", "--json")
    assert code == 0 and out.exists()
    assert json.loads(stdout)["edits"][0]["reached"] is False and "did NOT reach" in err


def test_pose_changes_a_key(tmp_path, capsys, curves_file):
    edit = tmp_path / "pose.toml"
    edit.write_text("pins = ['Head']\n[[edit]]\njoint = 'Hand_L'\nmove = [0, 6, 0]\n")
    out = tmp_path / "posed.usda"
    code, stdout, err = run(capsys, "pose", curves_file, "--edit", edit, "--frame", 30, "-o", out, "--json")
    assert code == 0, err
    assert json.loads(stdout)["edits"][0]["kind"] == "pose"
    before, after = usd_curves.read(curves_file), usd_curves.read(out)
    changed = np.flatnonzero(np.any(after.values != before.values, axis=1)).tolist()
    assert changed == [3]
    code, _, err = run(capsys, "pose", curves_file, "--edit", edit, "--frame", 25, "-o", out)
    assert code == 1 and "frame 25 is not a key" in err


def test_usage_errors(tmp_path, capsys, curves_file):
    edit = tmp_path / "reach.toml"
    edit.write_text(REACH)
    code, _, err = run(
        capsys, "edit-tangents", curves_file, "--edit", edit, "-o", tmp_path / "o.usda", "--solver", "nope"
    )
    assert code == 2 and "QP solver 'nope' is not installed; available: " in err
    code, _, err = run(capsys, "convert", curves_file, tmp_path / "x.bvh", "--curves", "--keys", "0,10")
    assert code == 2 and "--curves writes a USD curves file" in err


def test_curves_input_must_be_a_curves_file(tmp_path, capsys):
    edit = tmp_path / "reach.toml"
    edit.write_text(REACH)
    bvh = tmp_path / "wave.bvh"
    io.save(character(), bvh)
    plain = tmp_path / "plain.usda"
    io.save(character(), plain)
    for src, message, exit_code in (
        (bvh, "not a keyfill curves file (a .usda", 1),
        (plain, "no Curves prim", 1),
        (tmp_path / "missing.usda", "no such file", 2),  # a missing path is a usage error everywhere
    ):
        code, _, err = run(capsys, "edit-tangents", src, "--edit", edit, "-o", tmp_path / "o.usda")
        assert code == exit_code and message in err and len(err.strip().splitlines()) == 1
