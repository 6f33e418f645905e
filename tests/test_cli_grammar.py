"""One grammar (issue 32): stdin recognised by its first bytes, --in-format everywhere (info's old --format
still works), -q/-v/--debug after the subcommand too, --model naming its method, BVH units reported as
assumed and stated with --meters-per-unit."""

from __future__ import annotations

import json
import subprocess
import sys
from io import BytesIO, TextIOWrapper
from pathlib import Path

import pytest
from conftest import DATA

from keyfill import io
from keyfill.cli.main import main

MIXAMO = DATA / "bvhtoolbox_test_freebvh_mixamo.bvh"
CMU = DATA / "cmu_02_03_cgspeed_first4frames.bvh"


def run(capsys, *args, stdin: bytes | None = None, monkeypatch=None):
    if stdin is not None:
        monkeypatch.setattr("sys.stdin", TextIOWrapper(BytesIO(stdin)))
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """CMU's 4 frames in every format keyfill writes."""
    folder = tmp_path_factory.mktemp("formats")
    motion = io.load(CMU)
    out = {}
    for name in io.writable():
        path = folder / f"cmu{io.FORMATS[name].suffixes[0]}"
        io.save(motion, path)
        out[name] = path
    return out


@pytest.mark.parametrize("fmt", ["bvh", "usda", "usdc", "glb", "gltf"])
def test_sniff_knows_each_format_by_its_first_bytes(files, fmt):
    data = files[fmt].read_bytes()
    assert io.sniff(data) == fmt
    if fmt == "gltf":
        assert io.sniff(json.dumps({"asset": {"version": "2.0"}}).encode()) == "gltf"


def test_sniff_skips_white_space_and_a_byte_order_mark():
    assert io.sniff(b"\xef\xbb\xbf\r\n  \tHIERARCHY\nROOT Hips") == "bvh"
    assert io.sniff(b"\n#usda 1.0\n") == "usda"
    for other in (b"", b"hello", b"{}", b'{"nodes": []}', b"{not json", b"\xff\xfe"):
        assert io.sniff(other) is None


@pytest.mark.parametrize("fmt", ["bvh", "usda", "usdc", "glb"])
def test_stdin_needs_no_format(capsys, monkeypatch, files, fmt):
    code, out, err = run(capsys, "info", "-", "--json", stdin=files[fmt].read_bytes(), monkeypatch=monkeypatch)
    assert code == 0, err
    d = json.loads(out)
    assert d["format"] == fmt and d["frames"] == 4 and d["joints"] == 31 and d["input"] == "-"


def test_stdin_pipeline_without_formats(tmp_path):
    """`cat walk.bvh | keyfill convert - - --format usda | keyfill complete - -o out.bvh` as a user types it."""
    exe = [sys.executable, "-m", "keyfill"]
    usda = subprocess.run(exe + ["convert", "-", "-", "--format", "usda"], input=MIXAMO.read_bytes(),
                          capture_output=True, check=True).stdout
    out = tmp_path / "out.bvh"
    subprocess.run(exe + ["complete", "-", "-o", str(out), "--key-every", "10"], input=usda, capture_output=True,
                   check=True)
    assert io.load(out).num_frames == 69


def test_in_format_everywhere_and_infos_old_format(capsys, monkeypatch):
    data = MIXAMO.read_bytes()
    for flag in ("--in-format", "--format"):
        code, out, err = run(capsys, "info", "-", flag, "bvh", "--json", stdin=data, monkeypatch=monkeypatch)
        assert code == 0 and json.loads(out)["frames"] == 69, err
    code, out, _ = run(capsys, "info", "--help")
    assert "--in-format" in out and "--format " not in out  # the old name works but is not offered
    code, _, err = run(capsys, "info", MIXAMO, "--in-format", "bvh", "--format", "usda")
    assert code == 2 and "--format is the old name of --in-format" in err


def test_global_options_after_the_subcommand(capsys, tmp_path):
    out = tmp_path / "a.usda"
    code, _, err = run(capsys, "convert", CMU, out, "-q")
    assert code == 0 and err == "" and out.is_file()
    code, _, err = run(capsys, "convert", CMU, out)
    assert code == 0 and "wrote" in err
    code, _, err = run(capsys, "convert", CMU, out, "-v", "-q", "-q")  # counts add up as before the subcommand
    assert code == 0 and err == ""
    code, _, err = run(capsys, "info", tmp_path / "missing.bvh", "-q")
    assert code == 2 and err.startswith("keyfill: error:")
    code, out, _ = run(capsys, "train", "arnn", "--help")
    assert code == 0 and "--quiet" not in out


def test_debug_after_the_subcommand_shows_the_traceback(tmp_path):
    p = subprocess.run([sys.executable, "-m", "keyfill", "info", str(tmp_path / "missing.bvh"), "--debug"],
                       check=False, capture_output=True, text=True)
    assert p.returncode == 1 and "Traceback" in p.stderr and "NoSuchFile" in p.stderr


def test_bvh_units_are_reported_as_assumed(capsys, files):
    code, out, _ = run(capsys, "info", CMU)
    assert code == 0 and "units: cm assumed; BVH does not say" in out
    code, out, _ = run(capsys, "info", CMU, "--json")
    assert json.loads(out)["units_assumed"] is True
    code, out, _ = run(capsys, "info", CMU, "--meters-per-unit", "0.056444", "--json")
    d = json.loads(out)
    assert d["units_assumed"] is False and d["meters_per_unit"] == 0.056444
    code, out, _ = run(capsys, "info", files["usda"], "--json")  # USD records its units
    assert json.loads(out)["units_assumed"] is False
    code, out, _ = run(capsys, "info", files["usda"])
    assert "units: 0.01 m" in out
    code, _, err = run(capsys, "info", CMU, "--meters-per-unit", "-1")
    assert code == 2 and "--meters-per-unit must be a positive number" in err


def test_convert_states_the_units(capsys, tmp_path):
    out = tmp_path / "cmu.usda"
    code, _, err = run(capsys, "convert", CMU, out, "--meters-per-unit", "0.056444")
    assert code == 0, err
    assert io.load(out).skeleton.meters_per_unit == pytest.approx(0.056444)
    code, _, err = run(capsys, "convert", CMU, "-o", tmp_path / "batch/", "--meters-per-unit", "0.05")
    assert code == 2 and "--meters-per-unit" in err


def test_model_folder_names_its_method(capsys, tmp_path):
    from keyfill.learn.registry import METHODS

    folder = METHODS["arnn"].default_model()
    if folder is None:
        pytest.skip("no shipped lamp model")
    src = Path(__file__).resolve().parents[1] / "examples" / "lamp" / "keys.usda"
    code, out, err = run(capsys, "complete", src, "--model", folder, "-o", tmp_path / "f.usda", "--json")
    assert code == 0, err
    assert json.loads(out)["method"] == "arnn"
    code, _, err = run(capsys, "complete", src, "--model", folder, "--method", "transformer", "-o",
                       tmp_path / "g.usda")
    assert code == 2 and "a model of kind 'arnn'" in err
