"""Where keyfill runs: in Blender's own Python when it imports there, else a configured ``keyfill`` executable.

In process, the armature's keys go to :func:`keyfill.learn.registry.complete` as a keyfill ``Motion``
(:mod:`.convert`), with no file in between. Through the executable (the preferences' path, or ``keyfill``
on ``PATH``), they go as a BVH file in a temporary folder (written and read back here, in the layout
:mod:`.convert` gives: translations where bones move, rotations in the Euler orders Blender's BVH exporter
writes, the angles it would write), with ``keyfill complete --keys``. Either way keyfill gets what it would
read from Blender's BVH export of the keys: the same quaternions (signs included) and the frame rate its BVH
reader gives (:func:`frame_rate`).
"""

from __future__ import annotations

import importlib.util
import math
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import convert


class BackendError(RuntimeError):
    """keyfill failed or cannot be found (the message is one line for Blender's report)."""


@dataclass(frozen=True)
class Settings:
    """What ``keyfill complete`` is asked: the CLI's options and defaults."""

    method: str = "cubic"
    model: str = ""
    seed: int = 0
    feet: str = "DEFAULT"  # DEFAULT (the method's own), LOCK, FREE
    guard: str = "DEFAULT"  # DEFAULT (fallback), FALLBACK, WARN, OFF
    rig_map: dict | None = None


def add_python_path(folder: str) -> None:
    """Put ``folder`` (a site-packages with keyfill, from the preferences) on ``sys.path`` once."""
    if folder and os.path.isdir(folder) and folder not in sys.path:
        sys.path.append(folder)


def importable() -> bool:
    """Whether keyfill imports in this Python."""
    return importlib.util.find_spec("keyfill") is not None


def choose(mode: str, executable: str, python_path: str = "") -> str:
    """``"python"`` or ``"executable"``: where to run, by the preference ``mode`` (AUTO, PYTHON, EXECUTABLE)."""
    add_python_path(python_path)
    if mode == "PYTHON" or (mode == "AUTO" and importable()):
        if not importable():
            raise BackendError("keyfill does not import in Blender's Python; install it there (see docs/blender.md) "
                               "or choose the executable in the add-on's preferences")
        return "python"
    if not find_executable(executable):
        if mode == "EXECUTABLE":  # the user chose the executable: say what is wrong with it alone
            raise BackendError(f"keyfill: the executable {executable or 'keyfill'!r} chosen is not an executable file "
                               "here; set its path in the add-on's preferences")
        raise BackendError(f"keyfill is neither importable in Blender's Python nor an executable here "
                           f"({executable or 'keyfill'!r}); set its path in the add-on's preferences")
    return "executable"


def find_executable(executable: str) -> str | None:
    exe = executable or "keyfill"
    return exe if os.path.isfile(exe) and os.access(exe, os.X_OK) else shutil.which(exe)


def _rig_map_file(rig_map: dict, folder: str) -> str:
    path = Path(folder) / "rig_map.toml"
    lines = []
    for role, bones in rig_map.items():
        value = "[" + ", ".join(_toml_str(b) for b in bones) + "]" if isinstance(bones, list) else _toml_str(bones)
        lines.append(f"{role} = {value}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return str(path)


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def complete(rig: convert.Rig, basis_rot, basis_loc, moving, fps: float, keys, settings: Settings, where: str,
             executable: str = "", orders=None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Complete the basis arrays between ``keys`` (frame indices into them); returns the Blender basis
    ``(rotations, locations)`` at every frame and keyfill's report. ``orders``: each bone's keyfill Euler order
    as Blender's BVH exporter writes it (:func:`.action.bvh_orders`; default XYZ)."""
    with tempfile.TemporaryDirectory(prefix="keyfill-blender-") as tmp:
        rig_map = _rig_map_file(settings.rig_map, tmp) if settings.rig_map else None
        if where == "python":
            return _in_process(rig, basis_rot, basis_loc, moving, fps, keys, settings, rig_map, orders)
        return _through_executable(rig, basis_rot, basis_loc, moving, fps, keys, settings, rig_map, executable, tmp,
                                   orders)


def _in_process(rig, basis_rot, basis_loc, moving, fps, keys, settings, rig_map, orders=None):
    from keyfill.errors import KeyfillError
    from keyfill.learn.completion import CompleteOptions
    from keyfill.learn.registry import complete
    from keyfill.motion import Keys

    try:
        motion = convert.to_motion(rig, basis_rot, basis_loc, fps, moving=moving, orders=orders)
        options = CompleteOptions(model=settings.model or None, seed=settings.seed,
                                  feet=None if settings.feet == "DEFAULT" else settings.feet.lower(),
                                  guard=None if settings.guard == "DEFAULT" else settings.guard.lower(),
                                  rig_map=rig_map)
        result = complete(motion, Keys(np.asarray(keys)), settings.method, options)
    except KeyfillError as e:
        raise BackendError(f"keyfill: {e}") from None
    rot, loc = convert.from_motion(rig, result.motion)
    return rot, loc, dict(result.info or {})


def _through_executable(rig, basis_rot, basis_loc, moving, fps, keys, settings, rig_map, executable, tmp,
                        orders=None):
    exe = find_executable(executable)
    if exe is None:
        raise BackendError(f"no keyfill executable {executable or 'keyfill'!r}")
    src, dst = Path(tmp) / "keys.bvh", Path(tmp) / "filled.bvh"
    rot, pos = convert.to_keyfill(rig, basis_rot, basis_loc)
    chans = convert.channels(rig, np.asarray(moving, bool), orders)
    write_bvh(src, rig, chans, rot, pos, fps)
    cmd = [exe, "complete", str(src), "-o", str(dst), "--method", settings.method, "--seed", str(settings.seed),
           "--keys", ",".join(str(int(k)) for k in keys), "--bvh-layout", "source"]
    if settings.model:
        cmd += ["--model", settings.model]
    if settings.feet != "DEFAULT":
        cmd += ["--feet", settings.feet.lower()]
    if settings.guard != "DEFAULT":
        cmd += ["--guard", settings.guard.lower()]
    if rig_map:
        cmd += ["--rig-map", rig_map]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        lines = [ln for ln in proc.stderr.splitlines() if ln.strip()] or [f"exit code {proc.returncode}"]
        raise BackendError(lines[-1])
    out_rot, out_pos = read_bvh(dst, rig)
    brot, bloc = convert.to_blender(rig, out_rot, out_pos)
    return brot, bloc, {"executable": exe}


# --- the BVH of the executable fallback (our own layout only) ----------------------------------------------

def write_bvh(path: Path, rig: convert.Rig, chans, rot: np.ndarray, pos: np.ndarray, fps: float) -> None:
    """keyfill local ``rot``/``pos`` as BVH with channel lists ``chans`` (:func:`.convert.channels`): the angles
    :func:`.convert.euler_angles` gives in each joint's order, so keyfill reads back the quaternions
    :func:`.convert.bvh_hemisphere` gives in process (signs included)."""
    lines = ["HIERARCHY"]
    children = {j: [k for k in range(rig.num_bones) if rig.parents[k] == j] for j in range(rig.num_bones)}

    def joint(j, depth):
        pad = "\t" * depth
        lines.append(f"{pad}{'ROOT' if rig.parents[j] < 0 else 'JOINT'} {rig.names[j]}")
        lines.append(pad + "{")
        lines.append(pad + "\tOFFSET " + " ".join(repr(float(v)) for v in rig.offsets[j]))
        lines.append(pad + f"\tCHANNELS {len(chans[j])} " + " ".join(chans[j]))
        for k in children[j]:
            joint(k, depth + 1)
        if not children[j]:
            lines.append(pad + "\tEnd Site\n" + pad + "\t{\n" + pad + "\t\tOFFSET 0 0 0\n" + pad + "\t}")
        lines.append(pad + "}")

    for j in range(rig.num_bones):
        if rig.parents[j] < 0:
            joint(j, 0)
    ang = np.stack([np.degrees(convert.euler_angles(rot[:, j], "".join(c[0] for c in chans[j][-3:])))
                    for j in range(rig.num_bones)], axis=1)
    lines += ["MOTION", f"Frames: {rot.shape[0]}", f"Frame Time: {1.0 / fps!r}"]
    for f in range(rot.shape[0]):
        row = []
        for j in range(rig.num_bones):
            if len(chans[j]) == 6:
                row += [repr(float(v)) for v in pos[f, j]]
            row += [repr(float(v)) for v in ang[f, j]]
        lines.append(" ".join(row))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def read_bvh(path: Path, rig: convert.Rig) -> tuple[np.ndarray, np.ndarray]:
    """keyfill local ``(rotations, positions)`` of a BVH keyfill wrote in our layout, bones in ``rig``'s order."""
    tokens = path.read_text(encoding="utf-8").split()
    names, chans, i = [], [], 0
    while tokens[i] != "MOTION":
        if tokens[i] in ("ROOT", "JOINT"):
            names.append(tokens[i + 1])
        elif tokens[i] == "CHANNELS":
            n = int(tokens[i + 1])
            chans.append(tokens[i + 2: i + 2 + n])
            i += 1 + n
        i += 1
    frames = int(tokens[i + 2])
    values = np.array(tokens[i + 6:], dtype=np.float64).reshape(frames, -1)
    J = len(names)
    rot, pos = np.zeros((frames, J, 4)), np.zeros((frames, J, 3))
    rot[..., 0] = 1
    col = 0
    for j in range(J):
        r = rig.names.index(names[j])
        pos[:, j] = rig.offsets[r]
        for ch in chans[j]:
            axis = "XYZ".index(ch[0])
            if ch.endswith("position"):
                pos[:, j, axis] = values[:, col]
            else:
                half = np.radians(values[:, col]) / 2
                q = np.zeros((frames, 4))
                q[:, 0], q[:, 1 + axis] = np.cos(half), np.sin(half)
                rot[:, j] = convert.quat_mul(rot[:, j], q)
            col += 1
    order = [names.index(n) for n in rig.names]
    return rot[:, order], pos[:, order]


def frame_rate(scene) -> float:
    """The scene's frames per second as keyfill's BVH reader would read them from Blender's export: snapped to a
    whole rate when the frame time is within 5e-7 s of ``1/n`` (Blender's BVH importer leaves ``fps_base`` at
    0.999999 for a 30 fps file, 30.00003 fps; keyfill would then take the rate for another than its model's and
    resample the keys through its rig bridge)."""
    fps = scene.render.fps / scene.render.fps_base
    if not (math.isfinite(fps) and fps > 0):
        raise BackendError("the scene's frame rate is not positive")
    whole = round(fps)
    if whole > 0 and abs(1.0 / fps - 1.0 / whole) < 5e-7:
        return float(whole)
    return fps
