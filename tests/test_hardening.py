"""Issue 15: hostile inputs end in one clean error line, never an internal error, a blow-up or a hang.

The files in ``tests/data/regress/`` are the small inputs that once crashed
keyfill (see ``tests/data/README.md`` for where each comes from).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from conftest import DATA, one_error_line, run

from keyfill import io
from keyfill.errors import DataError, FormatError
from keyfill.io import bvh, bvh_values, usd
from keyfill.motion import Keys, Motion, Skeleton

REGRESS = DATA / "regress"
MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"



#: regression file -> what its one error line says (``None``: it is read without error)
EXPECTED = {
    "channels0_frames_1e7.bvh": "10000000 frames x 1 joints is more than a 85-byte file can describe",
    "frame_time_1e-320.bvh": "outside 1e-06 to 1e+06 fps",
    "offset_1e39.bvh": "which is not a finite number of at most 1e+12",
    "offset_1_0.bvh": "expected a number in the OFFSET of 'a', found '1_0'",
    "nested_1000_joints.bvh": None,
    "tcps_1e-320.usda": "timeCodesPerSecond: the frame rate",
    "end_inf.usda": "endTimeCode inf is not a time code",
    "end_nan.usda": "endTimeCode nan is not a time code",
    "end_1e8.usda": "100000001 frames is more than keyfill reads",
    "sample_at_1e9.usda": "1000000001 frames is more than keyfill reads",
    "bad_channel_name.usda": "unknown channel 'Wrotation'",
    "negative_key.usda": "key -1 is negative",
    "not_utf8.usda": "not a readable USD file",
    "joints_unregistered_type.usda": "holds a UnregisteredValue, not a token[] of joint paths",
    "animation_source_not_a_relationship.usda": "USD cannot read this file",
    "curves_tangent_slope_1e308.usda": "a key value or tangent is not finite",
    # make fuzz, seed 20261203, case 18594: numpy warned "invalid value encountered in cast" above the line
    "ibm_signalling_nan.glb": "inverseBindMatrices) holds a value that is not finite",
    # make fuzz, seed 20261203, case 96786: a joint named by a tab was written to a BVH that could not be read
    "joint_name_tab.usda": "joint 5 is named '\\t', which a BVH file cannot hold",
    # make fuzz, seed 20261204, case 67678: numpy's "divide by zero encountered in det" above the line
    "degenerate_bind_matrix.glb": "is scaled unevenly, sheared or mirrored",
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_regression_files(capsys, tmp_path, name):
    src = REGRESS / name
    out = tmp_path / ("out.usda" if src.suffix == ".bvh" else "out.bvh")
    start = time.perf_counter()
    with warnings.catch_warnings():  # pytest records warnings that a user would see printed above the error line
        warnings.simplefilter("error")
        code, _, err = run(capsys, "convert", src, out)
    assert time.perf_counter() - start < 20
    if EXPECTED[name] is None:
        assert code == 0 and io.load(out).num_joints == io.load(src).num_joints
        return
    line = one_error_line(err)
    assert code == 1 and (name in line or str(out) in line) and EXPECTED[name] in line  # the input, or the output
    assert not out.exists()


def test_every_regression_file_is_listed():
    on_disk = {p.name for p in REGRESS.iterdir() if p.suffix in (".bvh", ".usda", ".toml")}
    assert (REGRESS / "model_config_integer_too_large.json").is_file()
    assert on_disk <= set(EXPECTED) | set(TOML_EXPECTED) | CRASHES


# --- BVH numbers and sizes ---------------------------------------------------------------

SIMPLE = "HIERARCHY\nROOT a\n{\n\tOFFSET 0 0 0\n\tCHANNELS 3 Xrotation Yrotation Zrotation\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n1 2 3\n4 5 6\n"


@pytest.mark.parametrize("token", ["1_0", "inf", "nan", "0x10", "1e", "١", "+-1", "1e999"])
def test_one_number_grammar_for_offsets_and_motion(token):
    with pytest.raises(FormatError, match=":4:"):
        bvh.parse(SIMPLE.replace("OFFSET 0 0 0", f"OFFSET {token} 0 0"), "x.bvh")
    with pytest.raises(FormatError, match=":10:"):
        bvh.parse(SIMPLE.replace("1 2 3", f"{token} 2 3"), "x.bvh")


@pytest.mark.parametrize("token", ["1.", ".5", "+.5e-3", "-0", "00012", "1E5"])
def test_plain_numbers_are_read_alike_everywhere(token):
    m = bvh.parse(SIMPLE.replace("OFFSET 0 0 0", f"OFFSET {token} 0 0").replace("1 2 3", f"1 2 {token}"))
    assert m.skeleton.offsets[0, 0] == float(token)


def test_frames_is_checked_before_anything_is_allocated():
    text = SIMPLE.replace("Frames: 2", "Frames: 99999999999999999999")
    with pytest.raises(FormatError, match="frames is more than keyfill reads"):
        bvh.parse(text)
    with pytest.raises(FormatError, match="'Frames: 5' but 2 lines of motion data follow"):
        bvh.parse(SIMPLE.replace("Frames: 2", "Frames: 5"))
    with pytest.raises(FormatError, match="'Frames:' needs a non-negative whole number"):
        bvh.parse(SIMPLE.replace("Frames: 2", "Frames: 1_0"))


def test_limits_can_be_raised(monkeypatch):
    text = (REGRESS / "channels0_frames_1e7.bvh").read_text().replace("10000000", "5000000")
    with pytest.raises(FormatError):
        bvh.parse(text)
    monkeypatch.setenv("KEYFILL_FREE_JOINT_FRAMES", "50000000")
    assert bvh.parse(text).num_frames == 5_000_000


def test_the_motion_block_is_read_in_chunks(monkeypatch):
    m = bvh.read(MIXAMO)
    monkeypatch.setattr(bvh_values, "CHUNK_BYTES", 200)  # many chunks; error lines still exact
    again = bvh.parse(bvh.dumps(m))
    assert np.array_equal(again.rotations, bvh.parse(bvh.dumps(m)).rotations)
    lines = bvh.dumps(m).split("\n")
    first = next(i for i, line in enumerate(lines) if line.startswith("Frame Time")) + 1
    lines[first + 40] = lines[first + 40].replace(" ", " x", 1)
    with pytest.raises(FormatError, match=f":{first + 41}: 'x"):
        bvh.parse("\n".join(lines), "m.bvh")


def test_deep_hierarchies_have_a_stated_limit():
    deep = 1200
    text = "HIERARCHY\n" + "".join(f"{'ROOT' if i == 0 else 'JOINT'} j{i}\n{{\nOFFSET 0 1 0\nCHANNELS 0\n" for i in range(deep))
    text += "}\n" * deep + "MOTION\nFrames: 1\nFrame Time: 0.1\n\n"
    with pytest.raises(FormatError, match="1001 joints deep; keyfill reads hierarchies up to 1000 deep"):
        bvh.parse(text, "deep.bvh")


# --- writers refuse what readers would refuse ----------------------------------------------

def _one_joint(fps=30.0, offset=0.0, position=0.0):
    sk = Skeleton(names=["a"], parents=[-1], offsets=[[offset, 0, 0]], channels=[("Xposition", "Yposition", "Zposition")])
    rot = np.zeros((2, 1, 4))
    rot[..., 0] = 1
    pos = np.zeros((2, 1, 3))
    pos[1, 0, 0] = position
    return Motion(sk, fps, rot, pos)


@pytest.mark.parametrize("kw,match", [({"position": 1e39}, "beyond"), ({"offset": 1e20}, "beyond"), ({"fps": 1e-320}, "frame rate")])
@pytest.mark.parametrize("suffix", [".bvh", ".usda"])
def test_writers_refuse_values_out_of_range(tmp_path, kw, match, suffix):
    with pytest.raises(DataError, match=match):
        io.save(_one_joint(**kw), tmp_path / ("x" + suffix))
    assert list(tmp_path.iterdir()) == []


# --- USD ------------------------------------------------------------------------------------

def test_sparse_usd_frames_are_what_usd_resolves(tmp_path):
    """Frames between samples are interpolated in numpy; they must equal USD's own Get at each frame."""
    from pxr import Usd

    m = bvh.read(MIXAMO)
    path = tmp_path / "keys.usda"
    usd.write(m.replace(keys=Keys([0, 7, 30, 31, 68])), path, sparse=True)
    got = usd.read(path)
    stage = Usd.Stage.Open(str(path))
    anim = next(p for p in stage.Traverse() if p.GetTypeName() == "SkelAnimation")
    rot_attr, pos_attr = anim.GetAttribute("rotations"), anim.GetAttribute("translations")
    for f in range(m.num_frames):
        q = np.asarray(rot_attr.Get(f), dtype=np.float64)[:, [3, 0, 1, 2]]
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        assert np.allclose(got.rotations[f], q, atol=2e-6), f
        assert np.allclose(got.positions[f], np.asarray(pos_attr.Get(f)), atol=1e-4), f


def test_a_long_time_range_reads_fast(tmp_path):
    text = (REGRESS / "end_1e8.usda").read_text().replace("endTimeCode = 100000000", "endTimeCode = 200000")
    path = tmp_path / "long.usda"
    path.write_text(text)
    start = time.perf_counter()
    m = io.load(path)
    assert m.num_frames == 200001 and time.perf_counter() - start < 10
    assert np.allclose(m.rotations[5], m.rotations[-1])  # held after the last sample


# --- edit files --------------------------------------------------------------------------------

TOML_EXPECTED = {
    "edit_huge_integer_move.toml": "move is about 1e400, beyond 1e+12",
    "edit_huge_integer_frame.toml": "frame is about 1e30, beyond 1e+12",
    "edit_huge_integer_epsilon.toml": "epsilon is 99999999999999999999, beyond 1e+12",
    "edit_huge_integer_stiffness.toml": "stiffness of head is about 1e400, beyond 1e+12",
    "edit_5000_digit_integer.toml": "not a usable edit file",
    "edit_nested_arrays.toml": "nested too deeply",
}


@pytest.mark.parametrize("name", sorted(TOML_EXPECTED))
def test_edit_files_with_numbers_at_the_edges(capsys, tmp_path, name):
    curves = Path(__file__).parent.parent / "examples" / "edit" / "lamp_nod_curves.usda"
    code, _, err = run(capsys, "edit-tangents", curves, "--edit", REGRESS / name, "-o", tmp_path / "out.usda")
    line = one_error_line(err)
    assert code == 1 and name in line and TOML_EXPECTED[name] in line


# --- model folders ---------------------------------------------------------------------------------

MODEL = Path(__file__).parent.parent / "keyfill" / "learn" / "models" / "lamp-arnn"
LAMP_KEYS = Path(__file__).parent.parent / "examples" / "lamp" / "keys.usda"


def _model_with(tmp_path, config_text: str) -> Path:
    folder = tmp_path / "model"
    shutil.copytree(MODEL, folder, ignore=shutil.ignore_patterns("model.onnx"))  # the torch path's checks
    (folder / "config.json").write_text(config_text)
    return folder


@pytest.mark.parametrize("change,fragment", [
    (lambda c: c.replace('"sizes": {}', '"sizes": {"hidden_size": 30000}'), "describes a network of"),
    (lambda c: c.replace('"parents": [\n      -1,', '"parents": [\n      5,'), "skeleton.parents[0] must be"),
    (lambda c: c.replace('"offsets": [\n      [\n        0.0,', '"offsets": [\n      [\n        "x",'), "skeleton.offsets[0][0] must be"),
    (lambda c: c.replace("0.2657059614611094", "NaN"), "NaN is not a number JSON allows"),
    (lambda c: c.replace("0.2657059614611094", "1e999"), "is not a finite number"),
    (lambda c: (REGRESS / "model_config_integer_too_large.json").read_text(), "does not fit in 64 bits"),
    (lambda c: c.replace('"sizes": {}', '"sizes": ' + "[" * 5000 + "]" * 5000), "nested too deeply"),
    # make fuzz, seed 2026113, cases 3023 and 3755: finite but absurd statistics overflowed (numpy's warnings
    # printed, then "frame 0 holds a value that is not finite" without the model's name)
    (lambda c: c.replace("-0.13508971124162533", "1e+308"), "normali"),
    (lambda c: c.replace("-0.19818995774627715", "-1e+39"), "normali"),
    (lambda c: c.replace("0.21328981920422926", "1e-320"), "normali"),
])
def test_tampered_model_configs_are_one_clean_error(capsys, tmp_path, change, fragment):
    folder = _model_with(tmp_path, change((MODEL / "config.json").read_text()))
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, _, err = run(capsys, "complete", LAMP_KEYS, "-o", tmp_path / "o.usda", "--method", "arnn",
                           "--model", folder)
    line = one_error_line(err)
    assert code == 1 and fragment in line and str(folder) in line, line
    assert time.perf_counter() - start < 20


def test_weights_that_overflow_are_one_clean_error(capsys, tmp_path):
    """Finite weights whose products overflow float32: the model is named, nothing is written."""
    from safetensors.torch import load_file, save_file

    folder = _model_with(tmp_path, (MODEL / "config.json").read_text())
    tensors = load_file(folder / "weights.safetensors")
    for name in ("ff.first.weight", "ff.out.weight"):
        tensors[name] = torch.full_like(tensors[name], 3e38)
    save_file(tensors, folder / "weights.safetensors")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, _, err = run(capsys, "complete", LAMP_KEYS, "-o", tmp_path / "o.usda", "--method", "arnn",
                           "--model", folder)
    line = one_error_line(err)
    assert code == 1 and str(folder) in line and "the network's output is not finite" in line, line
    assert not (tmp_path / "o.usda").exists()


HUMAN_KEYS = Path(__file__).parent.parent / "examples" / "human" / "keys_15.usda"


def _set(path, value):
    """A change of a config: ``path`` (keys and indices) set to ``value``."""
    def change(config):
        node = config
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value
    return change


@pytest.mark.parametrize("model,change,fragment", [
    ("bandai2-transformer", _set(("statistics", "pos_mean", 1), 1e308), "statistics.pos_mean[1] must be a number from"),
    ("bandai2-transformer", _set(("statistics", "pos_std", 1), 1e300), "statistics.pos_std[1] must be a number from"),
    ("bandai2-transformer", _set(("architecture", "heads"), 0), "heads must be a whole number from 1"),
    ("bandai2-transformer", _set(("architecture", "layers"), 10**9), "layers must be a whole number from 1"),
    ("bandai2-transformer", _set(("architecture", "d_model"), 10**9), "d_model must be a whole number from 1"),
    ("bandai2-gan", _set(("gan", "output_smoothing"), 1e308), "gan.output_smoothing must be a whole number"),
    ("bandai2-gan", _set(("gan", "output_smoothing"), 10**6), "output_smoothing must be an even order"),
    ("bandai2-gan", _set(("gan", "style_dim"), 10**9), "must be from 0 to 65536"),
    ("bandai2-gan", _set(("ranges", "hi", 0, 0), 1e308), "ranges.hi[0][0] must be a number from"),
    ("bandai2-gan", _set(("fps",), 1e-300), "fps must be a number from 1e-06"),
])
def test_tampered_human_model_configs_are_one_clean_error(capsys, tmp_path, model, change, fragment):
    """Probes of session 8: absurd numbers in a shipped human model's config.json were numpy warnings, an
    error about frame 0, an internal TypeError or ZeroDivisionError, or an allocation of hundreds of GB."""
    folder = tmp_path / "model"
    from keyfill.learn.installed_models import shipped

    shutil.copytree(shipped(model), folder, ignore=shutil.ignore_patterns("model.onnx"))  # the torch path
    config = json.loads((folder / "config.json").read_text())
    change(config)
    (folder / "config.json").write_text(json.dumps(config))
    method = "gan" if "gan" in model else "transformer"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, _, err = run(capsys, "complete", HUMAN_KEYS, "-o", tmp_path / "o.usda", "--method", method,
                           "--model", folder)
    line = one_error_line(err)
    assert code == 1 and str(folder) in line and fragment in line, line
    assert not (tmp_path / "o.usda").exists()


# --- a crash inside usd-core (see tests/data/README.md) ---------------------------------------------

#: inputs that once killed the process: asking a Ts knot for a missing customData key with
#: GetCustomDataByKey segfaults in usd-core 26.11; keyfill/io/usd_curves.py now reads the whole dictionary
CRASHES = {"curves_knot_without_broken.usda"}


def test_curves_knot_without_broken_flag(tmp_path):
    """A curves file whose knot has no 'broken' flag reads (tangents decide), in a subprocess: a segfault would kill
    the test runner."""
    proc = subprocess.run([sys.executable, "-m", "keyfill", "convert", str(REGRESS / "curves_knot_without_broken.usda"),
                           str(tmp_path / "o.bvh")], capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "o.bvh").is_file()


# --- the command line ----------------------------------------------------------------------------

def test_bare_keyfill_prints_the_help_as_written(capsys):
    code, out, err = run(capsys)
    assert code == 2 and out.startswith("Usage: keyfill") and len(out.splitlines()) > 10 and err == ""


@pytest.mark.parametrize("command", [["convert", "-", "out.usda"], ["complete", "-", "-o", "out.usda", "--keys", "0,1"],
                                     ["plot", "-", "-o", "out.png"]])
def test_reading_stdin_asks_for_in_format(capsys, monkeypatch, tmp_path, command):
    """Standard input is recognised by its first bytes; what is no motion file asks for --in-format."""
    from io import BytesIO, TextIOWrapper

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("sys.stdin", TextIOWrapper(BytesIO(b"no motion here\n")))
    code, _, err = run(capsys, *command)
    assert code == 2 and "cannot tell the format of standard input" in one_error_line(err)
    assert "give --in-format" in err


def test_a_key_out_of_a_file_is_bad_data_not_bad_usage(capsys, tmp_path):
    code, _, err = run(capsys, "complete", REGRESS / "negative_key.usda", "-o", tmp_path / "o.bvh")
    assert code == 1 and "negative_key.usda" in one_error_line(err)


def test_data_errors_name_the_file(capsys, tmp_path):
    src = tmp_path / "inf.usda"
    src.write_text((REGRESS / "end_nan.usda").read_text().replace("endTimeCode = nan", "endTimeCode = 1").replace(
        "[(0, 0, 0)],\n            }", "[(0, 0, 1e39)],\n            }", 1))
    code, _, err = run(capsys, "convert", src, tmp_path / "o.bvh")
    line = one_error_line(err)
    assert code == 1 and "inf.usda" in line


# --- progress ----------------------------------------------------------------------------------------

def test_long_reads_and_writes_report_progress(tmp_path):
    from keyfill import progress

    seen = []

    class Bar:
        def __init__(self, description, total, unit):
            self.description, self.total, self.done = description, total, 0
            seen.append(self)

        def update(self, n):
            self.done += n

        def close(self):
            pass

    m = bvh.read(MIXAMO)
    progress.listen(Bar)
    try:
        io.save(m, tmp_path / "a.usda")
        io.save(m, tmp_path / "a.bvh")
        io.load(tmp_path / "a.bvh")
        io.load(tmp_path / "a.usda")
    finally:
        progress.listen(None)
    assert [b.description for b in seen] == ["writing USD", "writing BVH", "reading BVH", "reading USD"]
    assert all(b.done == b.total for b in seen), [(b.description, b.done, b.total) for b in seen]


BIG = "99999999999999999999"  # beyond a C long: once an OverflowError deep inside numpy, torch or time


@pytest.mark.parametrize("args,fragment", [
    (["complete", MIXAMO, "-o", "o.bvh", "--key-every", "10", "--seed", "-1"],
     "--seed must be between 0 and 2**63-1, got -1"),
    (["complete", HUMAN_KEYS, "-o", "o.usda", "--method", "gan", "--seed", BIG],
     f"--seed must be between 0 and 2**63-1, got {BIG}"),
    (["complete", MIXAMO, "-o", "o.bvh", "--keys", f"0,{BIG}"], f"key {BIG} is out of range"),
    # 10**8 poses of Motion DNA took 23 GB before the kernel killed the process
    (["complete", HUMAN_KEYS, "-o", "o.usda", "--method", "gan", "--dna-count", "100000000"],
     "--dna-count must be between 1 and 8,192"),
    (["complete", MIXAMO, MIXAMO, "-o", "out", "--key-every", "10", "--workers", BIG],
     "--workers must be between 1 and 1,024"),
    (["complete", MIXAMO, MIXAMO, "-o", "out", "--key-every", "10", "--connect-timeout", "1e20", "--scheduler",
      "tcp://127.0.0.1:1"], "--connect-timeout must be positive and at most 86,400 s"),
    (["simulate", "-o", "hops", "--count", "1", "--workers", BIG], "--workers must be between 1 and 1,024"),
    (["train", "arnn", MIXAMO, "-o", "model", "--threads", "0"], "--threads must be between 1 and 1,024, got 0"),
    (["train", "arnn", MIXAMO, "-o", "model", "--seed", BIG], "--seed must be between 0 and 2**63-1"),
    (["preview", MIXAMO, "-o", "o.gif", "--step", BIG], "--step must be between 1 and 10,000,000"),
    (["preview", MIXAMO, "-o", "o.gif", "--fps", "1e308"], "--fps: the frame rate 1e+308 fps is outside"),
    (["preview", MIXAMO, "-o", "o.gif", "--fps", "1e-6"], "a GIF frame lasts at most 655.35 s"),
    (["train", "arnn", MIXAMO, "-o", "model", "--max-deleted", BIG], "--max-deleted must be 0 to 10,000,000"),
    (["train", "arnn", MIXAMO, "-o", "model", "--clip", "nan"], "--clip must be 0 (no clipping) or a positive"),
])
def test_option_numbers_out_of_range_are_one_clean_error(capsys, monkeypatch, tmp_path, args, fragment):
    """Probes of session 9: each was an internal error (an OverflowError or ValueError from numpy, torch or
    time), a numpy warning above a 1-frame GIF, or a memory blow-up. Now one usage line and nothing written."""
    monkeypatch.chdir(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code, _, err = run(capsys, *args)
    line = one_error_line(err)
    assert code == 2 and fragment in line, line
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("setting,fragment", [
    ('"training": {"lr": NaN}', "'lr' must be a number from 0 to 10, not nan"),
    ('"training": {"lr": "x"}', "'lr' must be a number"),
    ('"training": {"epochs": 1.5}', "'epochs' must be a whole number from 1"),
    ('"training": {"weight_decay": -1}', "'weight_decay' must be a number from 0"),
    ('"training": {"window_offset": 0}', "'window_offset' must be a whole number from 1"),
    ('"training": {"grad_clip": -1}', "'grad_clip' must be a number from 0"),
    ('"training": {"layouts": {}}', "layouts must name at least one of"),
    ('"training": {"layouts": {"inbetween": -1}}', "'layouts.inbetween' must be a number from 0"),
    ('"training": {"val_lengths": [100000]}', "'val_lengths' must be a whole number from 1 to 54"),
    ('"training": {"mirror": 3}', "mirror must be true or false"),
    ('"model": {"dropout": 2}', "dropout must be a number from 0 to 0.99, not 2"),
    ('"model": {"fk_weight": NaN}', "fk_weight must be a number from 0 to 1e+06, not nan"),
    ('"model": {"residual": 3}', "residual must be true or false"),
])
def test_bad_transformer_training_settings_are_one_clean_error(capsys, tmp_path, setting, fragment):
    """Probes of session 9: a NaN or negative rate, a float epoch count, a string, no layouts, a window
    offset of 0 or a dropout of 2 were internal errors from torch or numpy; a negative clip, share or loss
    weight, validation lengths no window holds, or a residual of 3, trained silently."""
    config = tmp_path / "config.json"
    config.write_text(f"{{{setting}}}")
    code, _, err = run(capsys, "train", "transformer", MIXAMO, "-o", tmp_path / "model", "--config", config)
    line = one_error_line(err)
    assert code == 2 and fragment in line and "config.json" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["config.json"]


@pytest.mark.parametrize("setting,fragment", [
    ('"lr_path": -1', "'lr_path' must be a number from 0 to 10, not -1"),
    ('"lr_generator": NaN', "'lr_generator' must be a number from 0 to 10, not nan"),
    ('"mask_scale": 0', "'mask_scale' must be a number from 0 (excluded)"),
    ('"max_frames": 0', "'max_frames' must be a number from 1"),
    ('"val_fraction": 2', "'val_fraction' must be a number from 0 to 0.9"),
    ('"lr_path": "x"', "'lr_path' must be a number from 0 to 10, not 'x'"),
])
def test_bad_gan_training_settings_are_one_clean_error(capsys, tmp_path, setting, fragment):
    """Probes of session 9: a negative rate was an internal error from torch; a mask scale of 0 (a division by
    zero), a window of 0 frames or a validation share of 2 trained silently; a string compared as Python does."""
    config = tmp_path / "gan.json"
    config.write_text(f"{{{setting}}}")
    code, _, err = run(capsys, "train", "gan", MIXAMO, "-o", tmp_path / "model", "--stage", "path", "--config", config)
    line = one_error_line(err)
    assert code == 2 and fragment in line and "gan.json" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gan.json"]


def test_info_shows_deep_and_wide_hierarchies(capsys, tmp_path):
    """``info`` of a hierarchy at the depth limit (1,000) prints every joint indented by its depth (it once
    recursed per joint: a RecursionError at 1,000 deep, 74 s for 10,000 joints); ten such chains, 10,000
    joints, are listed the same way."""
    code, out, err = run(capsys, "info", REGRESS / "nested_1000_joints.bvh")
    assert code == 0, err
    rows = [line for line in out.splitlines() if line.startswith("  ")]
    assert len(rows) == 1000 and rows[-1].startswith("  " * 1000)
    def chain(r):
        return "".join(f"JOINT c{r}_{i}\n{{\nOFFSET 0 1 0\nCHANNELS 0\n" for i in range(1, 1000)) + "}\n" * 999

    text = "HIERARCHY\n" + "".join(
        f"ROOT c{r}_0\n{{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n" + chain(r) + "}\n"
        for r in range(10)) + "MOTION\nFrames: 1\nFrame Time: 0.1\n" + " ".join(["0"] * 30) + "\n"
    (tmp_path / "wide.bvh").write_text(text)
    code, out, err = run(capsys, "info", tmp_path / "wide.bvh")
    assert code == 0, err
    rows = [line for line in out.splitlines() if line.startswith("  ")]
    assert len(rows) == 10_000 and rows[999].startswith("  " * 1000 + "c0_999")
