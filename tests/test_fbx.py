"""FBX in (keyfill.io.fbx, the ``fbx`` extra): the Blender-made fixtures of tests/data read, converted and refused.

The fixtures come from ``tests/interop/make_fbx.py`` (Blender's own FBX exporter); its docstring gives the
rig and the joint positions at frame 10 that the tests check. ``-m interop`` compares keyfill's world joint
positions with Blender's own import of the same files.
"""

from __future__ import annotations

import builtins
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA, one_error_line, run

from keyfill import io
from keyfill.errors import FormatError, UsageError

ufbx = pytest.importorskip("ufbx", reason="the fbx extra (ufbx) is not installed: pip install 'keyfill[fbx]'")

RIG, ZUP, SKINNED = DATA / "fbx_rig.fbx", DATA / "fbx_rig_zup.fbx", DATA / "fbx_skinned.fbx"
NAMES = ("Hips", "Spine", "Head", "Arm")
#: make_fbx.py's bone heads at frame index 10, Blender's Z-up world, metres
FRAME_10 = np.array([[0.2, 0.0, 1.0], [0.2, 0.0, 1.1], [0.2, -0.4, 1.1], [0.4, -0.35, 1.1]])
FRAME_0 = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.1], [0.0, 0.0, 1.5], [0.2, 0.0, 1.45]])


def y_up(p: np.ndarray) -> np.ndarray:
    """Blender's Z-up point (x, y, z) in the Y-up file Blender exports by default (forward -Z): (x, z, -y)."""
    return np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1)


@pytest.mark.parametrize("path", [RIG, SKINNED, ZUP], ids=lambda p: p.stem)
def test_reads_the_blender_rig(path):
    m = io.load(path)
    sk = m.skeleton
    assert (m.num_frames, m.fps) == (20, 30.0)
    assert sk.names == NAMES and sk.parents.tolist() == [-1, 0, 1, 1]
    assert sk.meters_per_unit == pytest.approx(1.0)  # the Armature node's 100 over the file's cm
    world = m.world_positions() * sk.meters_per_unit
    if path == ZUP:
        assert sk.up_axis == "Z"
        want0, want10 = FRAME_0, FRAME_10
    else:
        assert sk.up_axis == "Y"
        want0, want10 = y_up(FRAME_0), y_up(FRAME_10)
    assert np.abs(world[0] - want0).max() < 1e-6
    assert np.abs(world[10] - want10).max() < 1e-6
    # the root moves 0.02 m along X a frame; the other joints only turn
    assert np.allclose(world[:, 0, 0], 0.02 * np.arange(20), atol=1e-6)
    assert sk.channels[0][:3] == ("Xposition", "Yposition", "Zposition")
    assert all(len(c) == 3 for c in sk.channels[1:])
    assert np.allclose(np.linalg.norm(m.rotations, axis=-1), 1)


def test_rest_offsets_are_the_bones():
    sk = io.load(RIG).skeleton
    # Spine 0.1 above Hips, Head 0.4 above Spine along the bone, Arm 0.35 up and 0.2 out: lengths in metres
    assert np.linalg.norm(sk.offsets[1:], axis=1) == pytest.approx([0.1, 0.4, np.hypot(0.2, 0.35)], abs=1e-6)


@pytest.mark.parametrize("suffix", [".bvh", ".usda", ".glb"])
def test_convert_fbx_through_the_cli(capsys, tmp_path, suffix):
    out = tmp_path / f"rig{suffix}"
    code, _, err = run(capsys, "convert", RIG, out)
    assert code == 0, err
    back, src = io.load(out), io.load(RIG)
    assert back.num_frames == 20 and back.skeleton.names == NAMES
    # the file's numbers (metres here) stay; USD and glTF record the units, BVH does not (read back as cm)
    assert np.abs(back.world_positions() - src.world_positions()).max() < 1e-5
    assert back.skeleton.meters_per_unit == (0.01 if suffix == ".bvh" else pytest.approx(1.0))


def test_info_complete_and_stdin(capsys, tmp_path, monkeypatch):
    code, out, err = run(capsys, "info", RIG, "--json")
    assert code == 0, err
    assert '"frames": 20' in out.replace(" ", "").replace('"frames":20', '"frames": 20')
    code, _, err = run(capsys, "complete", RIG, "-o", tmp_path / "filled.usda", "--method", "cubic",
                       "--keys", "0,10,19")
    assert code == 0, err
    assert io.load(tmp_path / "filled.usda").num_frames == 20
    assert io.sniff(RIG.read_bytes()) == "fbx"


def test_writing_fbx_is_refused(capsys, tmp_path):
    with pytest.raises(UsageError, match=r"FBX is read-only in keyfill; write one of bvh, .*gltf$"):
        io.save(io.load(RIG), tmp_path / "out.fbx")
    code, _, err = run(capsys, "convert", RIG, tmp_path / "out.fbx")
    line = one_error_line(err)
    assert code == 2 and "out.fbx: FBX is read-only in keyfill; write one of bvh" in line
    code, _, err = run(capsys, "convert", RIG, "-", "--format", "fbx")
    assert code == 2 and "standard output: FBX is read-only" in one_error_line(err)
    assert list(tmp_path.iterdir()) == []


def test_a_batch_of_fbx_needs_an_output_format_before_any_work(capsys, tmp_path):
    """A batch keeps each input's suffix unless --format: for .fbx inputs that is refused up front, not file by
    file at write time."""
    src = tmp_path / "in"
    src.mkdir()
    (src / "rig.fbx").write_bytes(RIG.read_bytes())
    out = tmp_path / "out"
    code, _, err = run(capsys, "convert", src, "-o", f"{out}/")
    assert code == 2 and "rig.fbx: keyfill does not write .fbx; give --format (one of bvh" in one_error_line(err)
    code, _, err = run(capsys, "complete", src, "-o", f"{out}/", "--format", "fbx", "--key-every", "5")
    assert code == 2 and "--format fbx: keyfill reads FBX but does not write it" in one_error_line(err)
    assert not out.exists()
    assert run(capsys, "convert", src, "-o", f"{out}/", "--format", "usda")[0] == 0
    assert (out / "rig.usda").is_file()


def bad_files(tmp_path: Path) -> dict[str, Path]:
    data = RIG.read_bytes()
    files = {"truncated": data[: len(data) // 3], "header only": data[:27], "text": b"hello, not an FBX file\n",
             "empty": b"", "obj text": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
             "garbage": bytes(range(256)) * 8}
    out = {}
    for name, content in files.items():
        p = tmp_path / (name.replace(" ", "_") + ".fbx")
        p.write_bytes(content)
        out[name] = p
    out["no animation"] = DATA / "fbx_no_anim.fbx"
    out["no skeleton"] = DATA / "fbx_mesh_only.fbx"
    return out


def test_bad_files_are_one_error_line_each(capsys, tmp_path):
    files = bad_files(tmp_path)
    for name, path in files.items():
        with pytest.raises(FormatError) as e:
            io.load(path)
        assert str(e.value).startswith(f"{path}: "), name
        out = tmp_path / "out" / f"{path.stem}.bvh"
        code, _, err = run(capsys, "convert", path, out)
        line = one_error_line(err)
        assert code == 1 and line.startswith(f"keyfill: error: {path}: "), (name, err)
        assert not out.exists()
    assert "no animation" in str(pytest.raises(FormatError, io.load, files["no animation"]).value)
    assert "no skeleton" in str(pytest.raises(FormatError, io.load, files["no skeleton"]).value)


def test_a_real_process_exits_cleanly(tmp_path):
    """The ufbx binding mishandles references (see keyfill/io/fbx.py); a crash would show only at exit."""
    bad = bad_files(tmp_path)["truncated"]
    script = ("from keyfill import io\n"
              f"for i in range(20):\n    io.load({str(RIG)!r}); io.load({str(SKINNED)!r})\n"
              "import gc; gc.collect()\n"
              f"try:\n    io.load({str(bad)!r})\nexcept Exception as e:\n    kept = e\n"
              f"try:\n    io.load({str(DATA / 'fbx_no_anim.fbx')!r})\nexcept Exception as e:\n    kept2 = e\n"
              "gc.collect(); print('done')\n")
    proc = subprocess.run([sys.executable, "-c", script], check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout == "done\n", proc.stderr
    proc = subprocess.run([sys.executable, "-m", "keyfill.cli.main", "convert", str(RIG),
                           str(tmp_path / "r.bvh")], check=False, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr


def test_without_the_extra_one_line_says_what_to_install(capsys, tmp_path, monkeypatch):
    real = builtins.__import__

    def no_ufbx(name, *args, **kwargs):
        if name == "ufbx" or name.startswith("ufbx."):
            raise ModuleNotFoundError("No module named 'ufbx'", name="ufbx")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_ufbx)
    monkeypatch.delitem(sys.modules, "ufbx", raising=False)
    with pytest.raises(UsageError, match=r"pip install 'keyfill\[fbx\]'$"):
        io.load(RIG)
    code, _, err = run(capsys, "convert", RIG, tmp_path / "rig.bvh")
    line = one_error_line(err)
    assert code == 2 and "pip install 'keyfill[fbx]'" in line and str(RIG) in line
    assert not (tmp_path / "rig.bvh").exists()


def test_read_time():
    import time

    start = time.perf_counter()
    for _ in range(5):
        io.load(SKINNED)
    assert (time.perf_counter() - start) / 5 < 1.0  # about 5 ms here


# --- Blender (optional: pytest -m interop) -----------------------------------

@pytest.mark.interop
@pytest.mark.parametrize("path", [RIG, SKINNED, ZUP], ids=lambda p: p.stem)
def test_blender_imports_the_same_world_positions(path, tmp_path):
    sys.path.insert(0, str(Path(__file__).parent / "interop"))
    from blender_check import blender_missing, blender_world_positions

    why = blender_missing()
    if why:
        pytest.skip(why)
    m = io.load(path)
    sk = m.skeleton
    copy = tmp_path / path.name  # Blender's result is written beside the file
    copy.write_bytes(path.read_bytes())
    result = blender_world_positions(copy, sk.meters_per_unit)
    assert result["frames"] == m.num_frames
    blender = np.asarray(result["positions"])[:, [result["bones"].index(n) for n in sk.names]]
    world = m.world_positions() * sk.meters_per_unit
    if sk.up_axis == "Y":  # Blender imports a Y-up file turned Z-up: (x, y, z) -> (x, -z, y)
        world = np.stack([world[..., 0], -world[..., 2], world[..., 1]], axis=-1)
    height = float(np.ptp(world[0, :, 2]))  # frame 0 is the rest pose (0.5 m from Hips to Head)
    worst = np.linalg.norm(blender - world, axis=-1).max()
    print(f"{path.name}: Blender deviates by {worst:.3g} m, {worst / height:.2g} of the height")
    assert worst < 1e-5 * height
