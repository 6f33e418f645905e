"""One JSON schema for every command's ``--json`` (docs/json.md): each command on a small fixture, its fields and
their types; and the error object on stdout for bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA

from keyfill import io
from keyfill.characters.lamp import from_variables
from keyfill.cli.main import main
from keyfill.motion import Keys

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"
EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
LAMP_KEYS = EXAMPLES / "lamp" / "keys.usda"
LAMP_CURVES = EXAMPLES / "edit" / "lamp_nod_curves.usda"
LAMP_LIFT = EXAMPLES / "edit" / "lamp_lift.toml"

#: the fields every ``--json`` summary has, and what they hold
COMMON = {"input": (str, list, type(None)), "output": (str, type(None))}


def run_json(capsys, *args) -> tuple[int, dict]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert out.strip(), f"nothing on stdout; stderr: {err}"
    return code, json.loads(out)


def check_schema(d: dict) -> None:
    """The rules of docs/json.md that hold for every command."""
    for field, types in COMMON.items():
        assert field in d and isinstance(d[field], types), (field, d.get(field))
    if isinstance(d["input"], list):
        assert all(isinstance(x, str) for x in d["input"])
    for count in ("frames", "joints", "channels"):  # always a count where present
        if count in d:
            assert type(d[count]) is int and d[count] >= 0, (count, d[count])
    if "frame_range" in d:
        first, last = d["frame_range"]
        assert type(first) is int and type(last) is int and first <= last
        assert d["frames"] == last - first + 1
    if "frames_drawn" in d:
        assert all(type(f) is int for f in d["frames_drawn"]) and d["frames"] == len(d["frames_drawn"])
    if "model" in d or "model_path" in d:
        assert isinstance(d["model"], (str, type(None))) and isinstance(d["model_path"], (str, type(None)))
        assert (d["model"] is None) == (d["model_path"] is None)
        if d["model"] is not None:
            assert "/" not in d["model"] and " " not in d["model"]  # an id, not prose or a path
            assert Path(d["model_path"]).is_absolute() and Path(d["model_path"]).exists()
    for old in ("file", "folder", "key_residual_position", "key_residual_rotation_rad", "num_joints"):
        assert old not in d, old
    for f in ("file", "folder"):
        assert f not in d
    if "inputs" in d:  # a batch: how many inputs, and ``files`` one outcome per input
        assert type(d["inputs"]) is int and d["inputs"] == len(d["files"]) == len(d["input"])
    if "files" in d:  # only ever a batch's outcomes (plot's legend names are ``labels``)
        assert isinstance(d["files"], list) and "inputs" in d
        for outcome in d["files"]:
            assert isinstance(outcome["input"], str) and isinstance(outcome["output"], str)
            assert outcome["status"] in ("done", "redone", "skipped", "failed")
            check_schema(outcome)


def check_key_residual(d: dict) -> None:
    block = d["key_residual"]
    assert set(block) == {"position", "rotation_rad", "removed"}
    assert isinstance(block["position"], float) and isinstance(block["rotation_rad"], float)
    assert type(block["removed"]) is bool and block["position"] >= 0 and block["rotation_rad"] >= 0


@pytest.fixture(scope="module")
def hops(tmp_path_factory):
    """A 'keyfill simulate'-style folder of 6 lamp sequences (tests/data/lamp_hops_seed1.npz)."""
    folder = tmp_path_factory.mktemp("hops")
    d = np.load(DATA / "lamp_hops_seed1.npz")
    lines = []
    for run, (values, keys, name) in enumerate(zip(d["values"][:6], d["keys"][:6], d["names"][:6])):
        io.save(from_variables(values, 60.0, keys=Keys(keys)), folder / f"{name}.usda")
        lines.append(json.dumps({"id": str(name), "file": f"{name}.usda", "run": run, "keys": keys.tolist()}))
    (folder / "manifest.jsonl").write_text("\n".join(lines) + "\n")
    return folder


# --- each command ---------------------------------------------------------------------------------


def test_info(capsys):
    code, d = run_json(capsys, "info", MIXAMO, "--json")
    assert code == 0
    check_schema(d)
    assert d["input"] == str(MIXAMO) and d["output"] is None and d["format"] == "bvh"
    assert (d["frames"], d["joints"], d["channels"]) == (69, 55, 168)
    assert d["units_assumed"] is True and d["meters_per_unit"] == 0.01
    assert isinstance(d["hierarchy"], list) and d["hierarchy"][0]["name"] == "mixamorig:Hips"


def test_convert_single_and_batch(capsys, tmp_path):
    code, d = run_json(capsys, "convert", CMU, tmp_path / "cmu.usda", "--json")
    assert code == 0
    check_schema(d)
    assert (d["input"], d["output"], d["frames"], d["joints"]) == (str(CMU), str(tmp_path / "cmu.usda"), 4, 31)
    code, d = run_json(capsys, "convert", CMU, MIXAMO, "-o", tmp_path / "batch/", "--format", "usda", "--json")
    assert code == 0 and isinstance(d["output"], str)
    assert not isinstance(d.get("frames"), list)
    check_schema(d)
    assert sorted(d["input"]) == sorted([str(CMU), str(MIXAMO)]) and d["inputs"] == 2
    assert {(f["input"], f["frames"], f["joints"]) for f in d["files"]} == {(str(CMU), 4, 31), (str(MIXAMO), 69, 55)}


def test_complete_baseline_learned_and_batch(capsys, tmp_path):
    code, d = run_json(capsys, "complete", MIXAMO, "--keys", "0,30,68", "-o", tmp_path / "c.bvh", "--json")
    assert code == 0
    check_schema(d)
    check_key_residual(d)
    assert d["method"] == "cubic" and d["frames"] == 69 and d["model"] is None and d["keys"] == [0, 30, 68]
    assert d["key_residual"]["removed"] is False and d["key_residual"]["position"] < 1e-9

    code, d = run_json(capsys, "complete", LAMP_KEYS, "--method", "arnn", "-o", tmp_path / "l.usda", "--json")
    assert code == 0
    check_schema(d)
    check_key_residual(d)
    assert d["method"] == "arnn" and d["model"] == "lamp-arnn" and d["key_residual"]["removed"] is True
    code, raw = run_json(capsys, "complete", LAMP_KEYS, "--method", "arnn", "--no-exact-keys",
                         "-o", tmp_path / "raw.usda", "--json")
    assert code == 0 and raw["key_residual"]["removed"] is False
    assert raw["key_residual"]["position"] == pytest.approx(d["key_residual"]["position"])

    code, d = run_json(capsys, "complete", CMU, MIXAMO, "--key-every", "3", "-o", tmp_path / "batch/", "--json")
    assert code == 0 and isinstance(d["output"], str)
    check_schema(d)
    assert sorted(d["input"]) == sorted([str(CMU), str(MIXAMO)])
    for outcome in d["files"]:
        if outcome.get("status") in ("done", "redone"):
            check_key_residual(outcome)
            assert type(outcome["frames"]) is int


def test_retarget(capsys, tmp_path):
    code, d = run_json(capsys, "retarget", CMU, "--to", CMU, "-o", tmp_path / "r.bvh", "--json")
    assert code == 0
    check_schema(d)
    assert d["frames"] == 4 and d["joints"] == 31
    code, d = run_json(capsys, "retarget", CMU, MIXAMO, "--to", CMU, "-o", tmp_path / "rb/", "--json")
    assert code == 0
    check_schema(d)
    assert sorted(d["input"]) == sorted([str(CMU), str(MIXAMO)]) and d["done"] == 2


def test_plot_has_a_frame_range(capsys, tmp_path):
    code, d = run_json(capsys, "plot", MIXAMO, "--frames", "10:20", "-o", tmp_path / "p.png", "--json")
    assert code == 0
    check_schema(d)
    assert d["input"] == [str(MIXAMO)] and d["frame_range"] == [10, 19] and d["frames"] == 10
    assert d["labels"] == [MIXAMO.stem] and "files" not in d


def test_preview_lists_the_frames_drawn(capsys, tmp_path):
    code, d = run_json(capsys, "preview", CMU, "-o", tmp_path / "p.png", "--size", "64x64", "--json")
    assert code == 0
    check_schema(d)
    assert d["input"] == [str(CMU)] and d["frames_drawn"] and d["frames"] == len(d["frames_drawn"])
    from PIL import Image

    with Image.open(tmp_path / "p.png") as im:  # size: the file written; frame_size: one filmstrip frame
        assert d["size"] == list(im.size) and d["frame_size"] == [64, 64] and d["kind"] == "filmstrip"


def test_edit_tangents_and_pose(capsys, tmp_path):
    code, d = run_json(capsys, "edit-tangents", LAMP_CURVES, "--edit", LAMP_LIFT, "-o", tmp_path / "e.usda",
                       "--json")
    assert code == 0
    check_schema(d)
    assert d["input"] == str(LAMP_CURVES) and d["output"] == str(tmp_path / "e.usda")
    edit = tmp_path / "pose.toml"
    edit.write_text("pins = [{ joint = 'base' }]\n[[edit]]\njoint = 'head'\nmove = [0, 0.02, 0]\n")
    code, d = run_json(capsys, "pose", LAMP_CURVES, "--edit", edit, "--frame", 10, "-o", tmp_path / "p.usda",
                       "--json")
    assert code == 0
    check_schema(d)


def test_simulate(capsys, tmp_path):
    pytest.importorskip("pybullet")
    code, d = run_json(capsys, "simulate", "-o", tmp_path / "sim", "--count", 1, "--iterations", 2,
                       "--max-runs", 1, "--workers", 1, "--json")
    assert code == 0
    check_schema(d)
    assert d["input"] is None and d["output"] == str(tmp_path / "sim")


def test_train_evaluate_export_and_the_model_names_its_method(capsys, tmp_path, hops):
    pytest.importorskip("torch")
    model = tmp_path / "lamp"
    code, d = run_json(capsys, "-q", "train", "arnn", hops, "-o", model, "--epochs", 1, "--batch-size", 3, "--json")
    assert code == 0
    check_schema(d)
    assert d["input"] == [str(hops)] and d["model"] == "lamp" and d["model_path"] == str(model.resolve())

    code, d = run_json(capsys, "evaluate", model, hops, "--json")
    assert code == 0
    check_schema(d)
    assert d["input"] == [str(hops)] and d["model"] == "lamp"
    code, d = run_json(capsys, "evaluate", "linear", hops, "--no-baselines", "--json")
    assert code == 0 and d["model"] is None

    # --model without --method: the folder's kind
    src = next(hops.glob("*.usda"))
    code, d = run_json(capsys, "complete", src, "--model", model, "-o", tmp_path / "f.usda", "--json")
    assert code == 0 and d["method"] == "arnn" and d["model"] == "lamp"
    check_key_residual(d)

    pytest.importorskip("onnx")
    code, d = run_json(capsys, "export", model, "-o", tmp_path / "lamp.onnx", "--json")
    assert code == 0
    check_schema(d)
    assert d["input"] == str(model) and d["model"] == "lamp" and d["kind"] == "arnn"

    pytest.importorskip("onnxruntime")  # a graph names its method too; its id is the file's stem
    code, d = run_json(capsys, "complete", src, "--model", tmp_path / "lamp.onnx", "-o", tmp_path / "g.usda", "--json")
    assert code == 0 and d["method"] == "arnn" and d["model"] == "lamp" and d["runtime"] == "onnx"
    assert d["model_path"] == str((tmp_path / "lamp.onnx").resolve())


# --- the error object -----------------------------------------------------------------------------


def test_errors_are_a_json_object_on_stdout_too(capsys, tmp_path):
    code, d = run_json(capsys, "info", tmp_path / "missing.bvh", "--json")
    assert code == 2 and set(d) == {"error"}
    e = d["error"]
    assert set(e) == {"message", "file", "line", "exit_code"} and e["exit_code"] == 2
    assert e["file"] == str(tmp_path / "missing.bvh") and e["line"] is None and "no such file" in e["message"]

    bad = tmp_path / "bad.bvh"
    bad.write_text(MIXAMO.read_text().replace("Frame Time:", "Frame Tim:", 1))
    code = main(["convert", str(bad), str(tmp_path / "o.usda"), "--json"])
    out, err = capsys.readouterr()
    e = json.loads(out)["error"]
    assert code == 1 and e["file"] == str(bad) and type(e["line"]) is int and e["exit_code"] == 1
    assert err.startswith("keyfill: error: ") and len(err.strip().splitlines()) == 1  # the stderr line as well

    code, d = run_json(capsys, "complete", MIXAMO, "-o", tmp_path / "x.bvh", "--key-every", 0, "--json")
    assert code == 2 and d["error"]["exit_code"] == 2 and "--key-every" in d["error"]["message"]
    code, d = run_json(capsys, "plot", MIXAMO, "--no-such-option", "--json")
    assert code == 2 and d["error"]["exit_code"] == 2 and d["error"]["file"] is None


def test_without_json_nothing_reaches_stdout_on_failure(capsys, tmp_path):
    assert main(["info", str(tmp_path / "missing.bvh")]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("keyfill: error: ")


def test_key_residual_measured_at_the_keys_equals_snap_to_keys_report():
    from keyfill.learn.exact_keys import key_residual, snap_to_keys

    walk = io.load(MIXAMO)
    rng = np.random.default_rng(3)
    noisy = walk.replace(positions=walk.positions + rng.normal(0, 0.1, walk.positions.shape))
    for keys in (Keys([0, 30, 68]), Keys([0, 30, 68]).restrict(walk.skeleton, ["mixamorig:Hips"], "position")):
        report = snap_to_keys(noisy, walk, keys)[1]
        measured = key_residual(noisy, walk, keys)
        assert measured["key_residual_position"] == report["key_residual_position"] > 0
        assert measured["key_residual_rotation_rad"] == report["key_residual_rotation_rad"]
