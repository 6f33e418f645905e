"""CLI smoke tests that `make test-floors` runs on the lowest versions pyproject.toml declares (no torch).

They run in the ordinary suite too. The source scan below keeps numpy-2-only names out of keyfill without
the floors' venv: numpy 1.26, the floor (Blender's bpy pins it), lacks them.
"""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, run

from keyfill import io

ROOT = Path(__file__).resolve().parents[1]
BVH = DATA / "cmu_02_03_cgspeed_first4frames.bvh"
EXAMPLES = ROOT / "examples"

#: numpy names that numpy 2 added (the array-API aliases and new functions) and numpy 1.26 lacks
NUMPY2_ONLY = ("concat", "atan2", "acos", "asin", "atan", "acosh", "asinh", "atanh", "pow", "bitwise_count",
               "bitwise_left_shift", "bitwise_right_shift", "bitwise_invert", "isdtype", "astype", "unstack",
               "permute_dims", "matrix_transpose", "vecdot", "vecmat", "matvec", "cumulative_sum",
               "cumulative_prod", "unique_values", "unique_counts", "unique_inverse", "unique_all", "trapezoid",
               "strings", "bool")


def test_keyfill_uses_no_numpy2_only_names():
    # `xp.` is rotations' numpy-or-torch namespace: torch has the numpy 1.26 spellings too
    pattern = re.compile(r"\b(?:np|numpy|xp)\.(" + "|".join(NUMPY2_ONLY) + r")\b(?!\.)")
    found = [f"{p.relative_to(ROOT)}:{i}: {m.group(0)}"
             for p in sorted((ROOT / "keyfill").rglob("*.py"))
             for i, line in enumerate(p.read_text().splitlines(), 1)
             for m in pattern.finditer(line)]
    assert not found, "numpy 2 only (numpy 1.26 is the floor): " + "; ".join(found)


@pytest.mark.floors
def test_info(capsys):
    code, out, _ = run(capsys, "info", BVH, "--json")
    info = json.loads(out)
    assert code == 0 and (info["frames"], info["joints"], info["fps"]) == (4, 31, 120.0)


@pytest.mark.floors
@pytest.mark.parametrize("suffix", [".bvh", ".usda", ".usdc", ".glb", ".gltf"])
def test_convert_round_trip(capsys, tmp_path, suffix):
    out = tmp_path / f"o{suffix}"
    code, _, err = run(capsys, "convert", BVH, out)
    assert code == 0, err
    a, b = io.load(BVH), io.load(out)
    assert b.num_frames == 4 and b.skeleton.names == a.skeleton.names
    np.testing.assert_allclose(b.world_positions(), a.world_positions(), atol=1e-5)


@pytest.mark.floors
@pytest.mark.parametrize(("source", "method", "suffix"), [
    ("mixamo_keys.usda", "cubic", ".usda"), ("mixamo_keys.glb", "linear", ".glb"),
    ("lamp/keys.usda", "arnn", ".bvh"),  # the shipped lamp model, through onnxruntime
])
def test_complete_hits_the_keys(capsys, tmp_path, source, method, suffix):
    out = tmp_path / f"filled{suffix}"
    code, _, err = run(capsys, "complete", EXAMPLES / source, "-o", out, "--method", method)
    assert code == 0, err
    src, filled = io.load(EXAMPLES / source), io.load(out)
    keys = src.keys.to_list()
    assert filled.num_frames == src.num_frames and len(keys) >= 2
    np.testing.assert_allclose(filled.world_positions()[keys], src.world_positions()[keys], atol=1e-4)


@pytest.mark.floors
def test_edit_tangents_and_pictures(capsys, tmp_path):
    lifted, png = tmp_path / "lifted.usda", tmp_path / "lamp.png"
    code, _, err = run(capsys, "edit-tangents", EXAMPLES / "edit" / "lamp_nod_curves.usda",
                       "--edit", EXAMPLES / "edit" / "lamp_lift.toml", "-o", lifted)
    assert code == 0, err
    code, _, err = run(capsys, "preview", EXAMPLES / "edit" / "lamp_nod_curves.usda", lifted, "-o", png)
    assert code == 0 and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", err
