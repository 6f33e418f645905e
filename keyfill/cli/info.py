"""``keyfill info``: what a motion file holds."""

from __future__ import annotations

import click
import numpy as np

from keyfill.cli.common import FORMAT_CHOICE, emit_json


def describe(motion, path: str) -> dict:
    """A JSON-ready summary of ``motion``: skeleton, timing, keys, bounding box."""
    sk = motion.skeleton
    world = motion.world_positions() if motion.num_frames else np.zeros((0, sk.num_joints, 3))
    box = None
    if motion.num_frames:
        box = {"min": world.min(axis=(0, 1)).tolist(), "max": world.max(axis=(0, 1)).tolist()}
    return {
        "file": path,
        "frames": motion.num_frames,
        "fps": motion.fps,
        "duration_s": motion.duration,
        "num_joints": sk.num_joints,
        "num_channels": sk.num_channels,
        "meters_per_unit": sk.meters_per_unit,
        "up_axis": sk.up_axis,
        "joints": [
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
@click.option("--format", "fmt", type=FORMAT_CHOICE, help="Input format (needed when FILE is '-').")
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
def info(file, fmt, representative, rig, rig_map, as_json):
    """Show what a motion file (BVH, USD or glTF) holds.

    Skeleton (joints, channels, Euler orders), frame count, frame rate,
    duration, keys and the world-space bounding box.

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
      cat walk.bvh | keyfill info - --format bvh
      keyfill info salsa.bvh --representative 8 --json | jq .representative_frames
      keyfill info character.bvh --rig
      keyfill info character.bvh --rig-map character.toml --json | jq .rig
    """
    from keyfill import io

    motion = io.load(file, fmt)
    d = describe(motion, file)
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
               f"{d['num_joints']} joints, {d['num_channels']} channels")
    click.echo(f"units: {d['meters_per_unit']:g} m, up axis {d['up_axis']}")
    keys = d["keys"]
    click.echo(f"keys: {', '.join(map(str, keys)) if keys is not None else 'none recorded'}")
    if representative is not None:
        click.echo(f"representative frames: {', '.join(map(str, d['representative_frames']))}")
    if d["bounding_box"]:
        lo, hi = d["bounding_box"]["min"], d["bounding_box"]["max"]
        click.echo("bounding box: " + " ".join(f"{a}[{l:.4g}, {h:.4g}]" for a, l, h in zip("xyz", lo, hi)))
    parents = {j["name"]: j["parent"] for j in d["joints"]}

    def depth(name):
        return 0 if parents[name] is None else 1 + depth(parents[name])

    rows = [("  " * depth(j["name"]) + j["name"], j["euler_order"], " ".join(j["channels"]) or "-") for j in d["joints"]]
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
