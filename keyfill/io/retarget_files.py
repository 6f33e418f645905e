"""Retargeting files: a clip onto another character's skeleton (``keyfill retarget IN --to RIG -o OUT``).

The *target rig file* ``RIG`` is any motion file keyfill reads (BVH, USD, glTF); only its skeleton is used:
joint names and hierarchy, rest offsets, channel layout, Euler orders, end sites, units and up axis. Its
frames are not: the reference T-pose of each rig is computed from its rest offsets
(:func:`keyfill.characters.retarget.make_rig`), so a rig file in an A-pose, with an animation or with no
frames at all gives the same result as its bare skeleton. The roles of both skeletons are found by
:func:`keyfill.characters.humanoid.map_roles`; ``rig_map`` / ``to_rig_map`` (TOML files, see
:func:`keyfill.characters.humanoid.read_rig_map`) give the ones it cannot find in the input / the rig.

The output is on the rig's skeleton (its channel layout, Euler orders and units; the hips' path scaled by the
ratio of the hip heights, the up axis turned), with the input's frame rate, frame count and keys. A glTF
output retargeted onto a glTF rig keeps the rig's meshes and materials (:func:`keyfill.io.save`'s ``source``).

:func:`retarget_file` does one file; :func:`retarget_chunk` is the job of the batch form
(``keyfill retarget IN... --to RIG -o OUTDIR/``, planned and run by :mod:`keyfill.io.batch`). Errors name the
file to blame and, for role problems, the parameter (``rig_map`` for the input, ``to_rig_map`` for the rig).
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass

from keyfill import io
from keyfill.characters.humanoid import read_rig_map
from keyfill.characters.retarget import Rig, make_rig, retarget
from keyfill.errors import DataError, FormatError, KeyfillError
from keyfill.io.batch import failure
from keyfill.io.batch_record import Item
from keyfill.motion import Motion, Skeleton


@dataclass(frozen=True)
class RetargetSpec:
    """What every file of a batch retarget shares (sent to the workers): the target rig file ``rig`` and the
    rig maps of the inputs (``rig_map``) and of the rig (``to_rig_map``), as paths (None: roles by the mapper)."""

    rig: str
    rig_map: str | None = None
    to_rig_map: str | None = None

    def recipe(self) -> dict:
        """What shapes every output, for the output folder's record: the rig and rig maps by their SHA-256."""
        from keyfill.io.batch_record import file_sha256, input_sha256

        return {"command": "retarget", "rig": input_sha256(self.rig),
                "rig_map": None if self.rig_map is None else file_sha256(self.rig_map),
                "to_rig_map": None if self.to_rig_map is None else file_sha256(self.to_rig_map)}


def rig_of(skeleton: Skeleton, rig_map: str | None, label: str, param: str = "rig_map") -> Rig:
    """The :class:`~keyfill.characters.retarget.Rig` of ``skeleton`` with the rig map file ``rig_map`` (or
    None). Errors name the file ``label`` and, where the roles are to blame, the parameter ``param``."""
    given = read_rig_map(rig_map) if rig_map is not None else None
    try:
        return make_rig(skeleton, rig_map=given, label=label)
    except KeyfillError as e:
        message, params = str(e), tuple(e.params)
        if not message.startswith((label, "rig_map")):
            message = f"{label}: {message}"
        if param != "rig_map" and "rig_map" in params:  # the rig's map is another parameter than the input's
            message = re.sub(r"(?<![\w-])rig_map(?!\w)", param, message)
            params = tuple(param if p == "rig_map" else p for p in params)
        raise type(e)(message, params=params) from None


def load_target(rig: str, to_rig_map: str | None = None) -> Rig:
    """The target rig of the rig file ``rig`` (its skeleton only, see the module docstring)."""
    return rig_of(io.load(rig).skeleton, to_rig_map, str(rig), param="to_rig_map")


def retarget_motion(motion: Motion, source: Rig, target: Rig) -> tuple[Motion, dict]:
    """``motion`` (on ``source``'s skeleton) on ``target``'s, and a JSON-ready report of it."""
    if motion.num_frames == 0:
        raise DataError("the motion has no frames to retarget")
    out = retarget(motion, source, target)
    info = {"frames": out.num_frames, "fps": out.fps, "joints": out.num_joints,
            "hip_scale": target.hip_height / source.hip_height, "source_rig": source.roles.to_json()}
    return out, info


def retarget_file(src: str, rig: str, dst: str, rig_map: str | None = None, to_rig_map: str | None = None,
                  in_format: str | None = None, format: str | None = None) -> dict:
    """Retarget the motion file ``src`` onto the skeleton of the rig file ``rig`` and write ``dst`` atomically
    (``"-"``: standard input / output with ``in_format`` / ``format``). Returns the report: ``input``,
    ``output``, ``rig``, ``frames``, ``fps``, ``joints``, ``hip_scale`` (target over source hip height),
    ``source_rig`` and ``target_rig`` (role -> joint name)."""
    target = load_target(rig, to_rig_map)
    label = "stdin" if src == "-" else str(src)
    motion = io.load(src, in_format)
    out, info = retarget_motion(motion, rig_of(motion.skeleton, rig_map, label), target)
    io.save(out, dst, format, source=rig)
    return {"input": src, "output": dst, "rig": rig, **info, "target_rig": target.roles.to_json()}


def retarget_chunk(chunk: list[Item], spec: RetargetSpec) -> list[dict | None]:
    """Job function of ``keyfill retarget IN... --to RIG -o OUTDIR/``: retarget each input onto the rig, write
    its output (items not marked ``write`` are left alone). The rig is read once per chunk, and the rig of each
    input skeleton once."""
    try:
        target = load_target(spec.rig, spec.to_rig_map)
    except (KeyfillError, OSError) as e:
        return [failure(it, e if isinstance(e, KeyfillError) else FormatError(str(e))) if it.write else None
                for it in chunk]
    rigs: dict[str, Rig] = {}
    out: list[dict | None] = []
    for it in chunk:
        if not it.write:
            out.append(None)
            continue
        try:
            motion = io.load(it.src)
            key = json.dumps(motion.skeleton.to_json(), sort_keys=True)
            if key not in rigs:
                rigs[key] = rig_of(motion.skeleton, spec.rig_map, it.src)
            moved, info = retarget_motion(motion, rigs[key], target)
            io.save(moved, it.dst, source=spec.rig)
            out.append({"input": it.src, "output": it.dst, "status": "done", **info})
        except (KeyfillError, OSError) as e:
            out.append(failure(it, e if isinstance(e, KeyfillError) else FormatError(str(e))))
    return out
