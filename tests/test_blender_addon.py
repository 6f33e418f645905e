"""The Blender extension (blender/keyfill_blender, issue 47) in bpy 5.0.1 (``pytest -m interop``).

Each test runs ``tests/interop/blender_addon_check.py`` in ``.venv-blender`` (bpy, and keyfill installed
there by ``make test-interop``) on a 10 s Bandai-Namco clip (22 bones, 301 frames of
``dataset-2_walk_elderly_001.bvh``, CC BY-NC: read from data/bandai2, never committed; skipped without it):

* the conversion module against keyfill's own BVH reader: world positions to 1e-5 of the height;
* the zip (``make blender-extension``) installed with bpy's ``extensions.package_install_files``, the clip
  keyed every 15 frames, Fill In-betweens against ``keyfill complete`` on the keys Blender's BVH exporter
  wrote (cubic and transformer: 1e-5 of the height at every frame), at most 2x the CLI's time,
  keys untouched, undo restoring the action, errors as reports;
* the same through the executable fallback (*Run keyfill: Executable*, ``.venv/bin/keyfill``, keyfill made
  unimportable in Blender's Python; the operator's report names the backend), and a missing or non-executable
  *keyfill Executable* refused with one error report naming it, the action unchanged;
* the conversion's quaternion signs and frame rate: those keyfill's BVH reader gives for Blender's export
  (the transformer's result depends on the sign at the first key: docs/blender.md);
* Edit Tangents: Hand_L's tail reaches the 3D cursor within 1e-3 of the height, no key value changes.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from keyfill import io

sys.path.insert(0, str(Path(__file__).parent / "interop"))
from blender_check import BLENDER_PYTHON, blender_missing

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(__file__).parent / "interop" / "blender_addon_check.py"
CLIP = ROOT / "data" / "bandai2" / "bandai_namco_motiondataset2" / "data" / "dataset-2_walk_elderly_001.bvh"
ZIP = ROOT / "out" / "blender" / "keyfill-0.1.0.zip"
KEYFILL = ROOT / ".venv" / "bin" / "keyfill"  # the CLI the fills are compared with, and the add-on's executable
KEYS = list(range(0, 301, 15))

pytestmark = pytest.mark.interop


@pytest.fixture(scope="module")
def blender():
    why = blender_missing()
    if why:
        pytest.skip(why)
    probe = subprocess.run([str(BLENDER_PYTHON), "-c", "import keyfill"], capture_output=True, check=False)
    if probe.returncode:
        pytest.skip("keyfill does not import in .venv-blender (make test-interop installs it there)")
    if not CLIP.exists():
        pytest.skip(f"needs {CLIP} (Bandai-Namco dataset-2, unpacked by `make corpora`); it is absent here")
    if not ZIP.exists():
        pytest.skip(f"needs {ZIP} (make blender-extension)")


def run(tmp_path: Path, *args: str) -> dict:
    out = tmp_path / "result.json"
    env = {"HOME": str(tmp_path / "home"), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run([str(BLENDER_PYTHON), str(SCRIPT), *args, "--out", str(out)], capture_output=True,
                          text=True, timeout=600, check=False, env=env)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return json.loads(out.read_text())


def height(motion) -> float:
    return float(np.ptp(motion.skeleton.rest_world_positions()[:, 1]))


def test_conversion_agrees_with_keyfills_bvh_reader(blender, tmp_path):
    result = run(tmp_path, "convert", str(CLIP))
    motion = io.load(CLIP)
    want, h = motion.world_positions(), height(motion)
    for label in ("default", "object"):  # Blender's Z-up metres import; the file's axes under a turned object
        r = result[label]
        idx = [motion.skeleton.names.index(n) for n in r["names"]]
        got = np.asarray(r["world"])
        assert got.shape == want[:, idx].shape
        assert np.abs(got - want[:, idx]).max() < 1e-5 * h, label
        for f, heads in r["blender_heads"]:  # Blender's own bone heads agree too
            assert np.abs(np.asarray(heads) - want[f][idx]).max() < 1e-5 * h
        assert r["roundtrip_rot"] < 1e-12


def _cli(keys_bvh: Path, out: Path, method: str) -> float:
    t0 = time.perf_counter()
    subprocess.run([str(KEYFILL), "complete", str(keys_bvh), "-o", str(out), "--method",
                    method, "--keys", ",".join(map(str, KEYS))], check=True, capture_output=True)
    return time.perf_counter() - t0


def _one_line_error(report: str | None, *names: str) -> str:
    """An operator's ERROR report (as bpy raises it): one line, ``Error: keyfill...``, naming ``names``."""
    assert report is not None and "Traceback" not in report
    lines = report.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: keyfill"), report
    assert all(n in lines[0] for n in names), (names, report)
    return lines[0]


def _fill(tmp_path: Path, method: str, where: str = "python") -> tuple[dict, np.ndarray, float, float]:
    """Fill In-betweens in Blender against the CLI on the keys Blender exported. ``where``: ``python`` (the add-on's
    default preferences, keyfill importable in .venv-blender) or ``executable`` (*Run keyfill: Executable* at
    ``KEYFILL``, keyfill unimportable in Blender's Python)."""
    keys_bvh = tmp_path / "keys.bvh"
    backend = ["--backend", "EXECUTABLE", "--executable", str(KEYFILL), "--no-import"] if where == "executable" else []
    r = run(tmp_path, "fill", str(CLIP), "--zip", str(ZIP), "--every", "15", "--method", method,
            "--exported", str(keys_bvh), *backend)
    cli_seconds = _cli(keys_bvh, tmp_path / "cli.bvh", method)
    cli = io.load(tmp_path / "cli.bvh")
    idx = [cli.skeleton.names.index(n) for n in r["bones"]]
    dev = np.linalg.norm(np.asarray(r["heads"]) - cli.world_positions()[:, idx], axis=-1).max(axis=-1) / height(cli)
    print(f"{method} ({where}): deviation from the CLI {dev.max():.3g} of the height; operator {r['seconds']:.2f} s, "
          f"CLI {cli_seconds:.2f} s")
    assert r["module"] == "bl_ext.user_default.keyfill" and r["result"] == ["FINISHED"]
    assert r["keyfill_importable"] == (where == "python")
    assert f"keyfill {method} ({where}): filled " in r["reports"], r["reports"]  # the backend it used
    assert r["keys_kept"] and r["points_after"] > r["points_before"]
    assert r["undo_restored"]
    _one_line_error(r["error_report"], "/nonexistent/model")  # in process "no such model"; the CLI's "does not exist"
    assert "Traceback" not in r["error_stderr"]
    return r, dev, r["seconds"], cli_seconds


def test_fill_cubic_equals_the_cli(blender, tmp_path):
    _, dev, seconds, cli_seconds = _fill(tmp_path, "cubic")
    assert dev.max() < 1e-5
    assert seconds <= 2 * cli_seconds


def test_fill_transformer_equals_the_cli(blender, tmp_path):
    """The shipped transformer's result depends on the sign of the quaternions at the first key (q and -q: the
    same rotation): UpperLeg_L's sign alone moved it by 0.032 of the height at frame 141 when the operator
    handed keyfill w >= 0 and the CLI read w < 0 from the exported Euler angles. The operator now hands keyfill
    the signs (and the frame rate) its BVH reader gives for Blender's export (docs/blender.md)."""
    _, dev, seconds, cli_seconds = _fill(tmp_path, "transformer")
    assert dev.max() < 1e-5
    assert seconds <= 2 * cli_seconds


@pytest.mark.parametrize("method", ["cubic", "transformer"])
def test_fill_through_the_executable_equals_the_cli(blender, tmp_path, method):
    """The executable fallback: keys written as BVH in a temporary folder, ``keyfill complete --keys`` run, its
    BVH read back; the same result as the CLI on Blender's own export. keyfill is unimportable in Blender's
    Python for this run, so an in-process fill would fail, and the operator's report says which backend ran."""
    _, dev, _, _ = _fill(tmp_path, method, where="executable")
    assert dev.max() < 1e-5


def test_fill_refuses_a_missing_or_non_executable_keyfill(blender, tmp_path):
    """A *keyfill Executable* that is not there, or not executable (the real launcher without its execute bit):
    one error report naming it, nothing on stderr, the action unchanged; under *Executable* with keyfill
    importable (the preference is obeyed) and under *Automatic* with keyfill unimportable (the fallback)."""
    missing = tmp_path / "nowhere" / "keyfill"
    plain = tmp_path / "keyfill"
    plain.write_bytes(KEYFILL.read_bytes())
    plain.chmod(0o644)
    r = run(tmp_path, "refuse", str(CLIP), "--zip", str(ZIP), "--executable", str(missing),
            "--executable", str(plain))
    cases = r["cases"]
    assert [(c["backend"], c["executable"], c["keyfill_importable"]) for c in cases] == [
        ("EXECUTABLE", str(missing), True), ("EXECUTABLE", str(plain), True), ("AUTO", str(missing), False)]
    for c in cases:
        print(c["backend"], _one_line_error(c["error"], repr(c["executable"])))
        assert c["result"] is None and c["stderr"] == ""
        assert c["unchanged"]


def test_edit_tangents_reaches_the_cursor(blender, tmp_path):
    r = run(tmp_path, "tangents", str(CLIP), "--zip", str(ZIP))
    print(f"edit tangents: {r['distance']:.3g} m from the target ({r['distance'] / r['height']:.2g} of the height), "
          f"moved {r['moved']:.3g} m, {r['seconds']:.2f} s")
    assert r["result"] == ["FINISHED"]
    assert r["distance"] < 1e-3 * r["height"]
    assert r["changed_key_values"] == 0
    assert r["undo_restored"]
