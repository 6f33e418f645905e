"""``keyfill info``: what a motion file holds."""

from __future__ import annotations

import click
import numpy as np

from keyfill.cli.common import FORMAT_CHOICE, emit_json, in_format_option, meters_per_unit_option, up_axis_option

#: frames whose world positions :func:`describe` holds at once (its memory stays small for any length)
BOX_BLOCK = 4096


def describe(motion, path: str, fmt: str | None = None, units_assumed: bool = False,
             axis_assumed: bool = False) -> dict:
    """A JSON-ready summary of ``motion``: skeleton, timing, keys, bounding box (docs/json.md).

    ``fmt``: the format the file was read as; ``units_assumed``: its format records no units (BVH) and none
    were given, so ``meters_per_unit`` is keyfill's assumption (centimetres), not the file's word;
    ``axis_assumed``: the same for ``up_axis`` (Y).
    """
    sk = motion.skeleton
    box = None
    if motion.num_frames:
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for a in range(0, motion.num_frames, BOX_BLOCK):  # the world positions of a block of frames at a time
            world = motion.frames(slice(a, a + BOX_BLOCK)).world_positions()
            lo, hi = np.minimum(lo, world.min(axis=(0, 1))), np.maximum(hi, world.max(axis=(0, 1)))
        box = {"min": lo.tolist(), "max": hi.tolist()}
    return {
        "input": path,
        "output": None,
        "format": fmt,
        "frames": motion.num_frames,
        "fps": motion.fps,
        "duration_s": motion.duration,
        "joints": sk.num_joints,
        "channels": sk.num_channels,
        "meters_per_unit": sk.meters_per_unit,
        "units_assumed": units_assumed,
        "up_axis": sk.up_axis,
        "up_axis_assumed": axis_assumed,
        "hierarchy": [
            {
                "name": sk.names[j],
                "parent": sk.names[sk.parents[j]] if sk.parents[j] >= 0 else None,
                "channels": list(sk.channels[j]),
                "euler_order": sk.euler_orders[j],
                "offset": sk.offsets[j].tolist(),
            }
            for j in range(sk.num_joints)
        ],
        "keys": motion.keys.to_list() if motion.keys is not None else None,
        "bounding_box": box,
    }


@click.command()
@click.argument("file", type=click.Path(dir_okay=False, allow_dash=True))
@in_format_option
@click.option("--format", "fmt", type=FORMAT_CHOICE, hidden=True, help="Old name of --in-format.")
@meters_per_unit_option
@up_axis_option
@click.option("--representative", type=int, metavar="N",
              help="Also list the N representative frames (largest joint-rotation change; the frames a Motion DNA "
                   "takes from this file, see docs/gan.md).")
@click.option("--rig", is_flag=True,
              help="Also show the humanoid roles of the skeleton (which joint is the hips, each hand, ...) and which "
                   "shipped human models fit it, directly or through retargeting (docs/retarget.md).")
@click.option("--rig-map", type=click.Path(exists=True, dir_okay=False), metavar="FILE.toml",
              help='Give roles the mapper does not find, as TOML lines role = "JointName" (e.g. hand_l = "L_Wrist"; '
                   "spine = [...] for the chain); implies --rig.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON on stdout.")
def info(file, in_fmt, fmt, meters_per_unit, up_axis, representative, rig, rig_map, as_json):
    """Show what a motion file (BVH, USD or glTF) holds.

    Skeleton (joints, channels, Euler orders), frame count, frame rate,
    duration, units, up axis, keys and the world-space bounding box. BVH
    files record no units and no up axis: they are reported as centimetres
    and Y-up assumed, unless --meters-per-unit and --up-axis state them.

    With --rig: the humanoid role of each joint (hips, spine chain, neck,
    head, per side clavicle, upper arm, forearm, hand, thigh, shin, foot,
    toe) and, for each method with a shipped human model (transformer, gan),
    whether the model serves this skeleton as its own, through retargeting
    (keyfill complete then retargets the keys onto the model's skeleton and
    back), or not and why. A skeleton the mapper cannot resolve is an error
    that names the roles it could not find; give them with --rig-map.

    \b
    Examples:
      keyfill info walk.bvh
      keyfill info keys.usda --json | jq .keys
      cat walk.bvh | keyfill info -                      (the format from the first bytes)
      keyfill info capture.bvh --meters-per-unit 0.0254     (a file in inches)
      keyfill info blender_export.bvh --up-axis Z           (Blender's BVH export is Z-up)
      keyfill info salsa.bvh --representative 8 --json | jq .representative_frames
      keyfill info character.bvh --rig
      keyfill info character.bvh --rig-map character.toml --json | jq .rig
    """
    from keyfill import io

    if in_fmt is not None and fmt is not None and in_fmt != fmt:
        raise click.UsageError("--format is the old name of --in-format; give one")
    motion, read_as = io.load_format(file, in_fmt or fmt, meters_per_unit, up_axis)
    d = describe(motion, file, read_as, units_assumed=not io.FORMATS[read_as].units and meters_per_unit is None,
                 axis_assumed=not io.FORMATS[read_as].axes and up_axis is None)
    if representative is not None:
        from keyfill.learn.representative import representative_frames

        d["representative_frames"] = representative_frames(motion, representative).tolist()
    roles = None
    if rig or rig_map is not None:
        from keyfill.characters.humanoid import read_rig_map
        from keyfill.learn.registry import humanoid_fit

        roles, d["models"] = humanoid_fit(motion, read_rig_map(rig_map) if rig_map is not None else None,
                                          label="stdin" if file == "-" else file)
        d["rig"] = roles.to_json()
    if as_json:
        emit_json(d)
        return
    click.echo(f"{file}: {d['frames']} frames at {d['fps']:g} fps ({d['duration_s']:.3f} s), "
               f"{d['joints']} joints, {d['channels']} channels")
    if d["units_assumed"]:
        units = f"cm assumed; {read_as.upper()} does not say (--meters-per-unit states them)"
    else:
        units = f"{d['meters_per_unit']:g} m"
    axis = f"{d['up_axis']}" + (f" assumed; {read_as.upper()} does not say (--up-axis states it)"
                                 if d["up_axis_assumed"] else "")
    click.echo(f"units: {units}; up axis {axis}")
    keys = d["keys"]
    click.echo(f"keys: {', '.join(map(str, keys)) if keys is not None else 'none recorded'}")
    if representative is not None:
        click.echo(f"representative frames: {', '.join(map(str, d['representative_frames']))}")
    if d["bounding_box"]:
        lo, hi = d["bounding_box"]["min"], d["bounding_box"]["max"]
        click.echo("bounding box: " + " ".join(f"{a}[{l:.4g}, {h:.4g}]" for a, l, h in zip("xyz", lo, hi)))
    depth = [0] * motion.skeleton.num_joints  # parents come first: one pass, any depth
    for j, p in enumerate(motion.skeleton.parents):
        depth[j] = 0 if p < 0 else depth[p] + 1
    rows = [("  " * depth[i] + j["name"], j["euler_order"], " ".join(j["channels"]) or "-")
            for i, j in enumerate(d["hierarchy"])]
    width = max(len(r[0]) for r in rows)
    for name, order, chans in rows:
        click.echo(f"  {name:<{width}}  {order}  {chans}")
    if roles is not None:
        click.echo("humanoid roles:")
        for line in roles.describe():
            click.echo(f"  {line}")
        click.echo("shipped human models:")
        for name, m in d["models"].items():
            click.echo(f"  {name}{_model_words(m, d['fps'])}")


def _model_words(m: dict, fps: float) -> str:
    """`` (bandai2-gan, 30 fps): through retargeting, resampled from 120 fps`` for ``info --rig``."""
    where = f" ({m['model']}, {m['model_fps']:g} fps)" if "model_fps" in m else f" ({m['model']})" if m["model"] else ""
    if m["fits"] == "no":
        return f"{where}: no: {m['reason']}"
    text = "its own skeleton" if m["fits"] == "own skeleton" else "through retargeting"
    if m.get("resampled"):
        text += f", resampled from {fps:g} fps"
    return f"{where}: {text}"
