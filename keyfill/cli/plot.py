"""``keyfill plot``: animation curves of one or more motion files."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, in_format_option, keys_options, load_labelled, say


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False, allow_dash=True))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Picture to write: .png, .svg or .pdf.")
@click.option("--joints", multiple=True, metavar="NAMES",
              help="Joints whose channels to show, comma-separated or repeated (default: all channels when "
                   "there are at most 12, else the first joint that rotates).")
@click.option("--channels", multiple=True, metavar="NAMES",
              help="Panels to show: JOINT.CHANNEL names (Hips.Zrotation, Hips.y with --positions, a lamp "
                   "variable) or a channel for every chosen joint (Zrotation, Xposition, y).")
@click.option("--frames", metavar="A:B", help="Frames A to B-1 (Python slice; 10:, :30 and -50: work too).")
@click.option("--positions", is_flag=True, help="Plot world positions JOINT.x/.y/.z (forward kinematics) "
                                                "instead of the file's channels.")
@click.option("--contacts", is_flag=True,
              help="Draw each file's foot contacts in bands under the curves: one row per foot joint (ankle, "
                   "toe; left, then right), shaded where it touches the ground (the rule of --feet lock, "
                   "docs/feet.md; the ground from the file's keys). Needs a skeleton with legs.")
@click.option("--rig-map", type=click.Path(exists=True, dir_okay=False), metavar="FILE.toml",
              help="With --contacts: the humanoid roles the mapper cannot find, as lines role = \"JointName\" "
                   "(docs/retarget.md), e.g. foot_l = \"LeftAnkle\".")
@click.option("--ground", type=float, metavar="HEIGHT",
              help="With --contacts: the ground's height along the up axis, in the files' units (default: "
                   "the lowest foot at each file's keys, else over all its frames).")
@click.option("--labels", metavar="NAMES",
              help="Legend names for the files, comma-separated, in order (default: the file names).")
@keys_options
@in_format_option
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def plot(files, output, joints, channels, frames, positions, contacts, rig_map, ground, labels, keys_text, key_every,
         in_fmt, as_json):
    """Draw the animation curves of FILES, overlaid, one panel per variable.

    Each panel is one animation variable over the frames: a BVH channel as
    the file stores it (rotations as Euler angles in degrees in the joint's
    own order, positions in the file's units), a world position with
    --positions, or, for the hopping lamp, one of its six variables. Every
    file gets its own colour and a legend entry; keys (recorded in the file,
    or given with --keys / --key-every) are open circles on the curves.
    --contacts adds, under the curves, a band per file of where each foot
    joint is on the ground, so locked feet (complete --feet lock) can be
    seen against raw ones.

    \b
    Examples:
      keyfill plot examples/lamp/truth.usda -o lamp.png
      keyfill plot truth.usda cubic.usda arnn.usda --labels truth,cubic,arnn -o compare.svg
      keyfill plot walk.bvh --joints Hips,LowerLeg_L --channels Xrotation -o knee.pdf
      keyfill plot walk.bvh --positions --joints Hand_L --frames 0:120 -o hand.png
      keyfill plot raw.usda locked.usda --labels raw,locked --contacts --positions --joints Toes_L --channels y -o feet.png
    """
    from keyfill.characters.humanoid import read_rig_map
    from keyfill.viz import PLOT_SUFFIXES, check_suffix
    from keyfill.viz.curves import plot as draw

    check_suffix(output, PLOT_SUFFIXES)
    if not contacts and (rig_map is not None or ground is not None):
        raise click.UsageError(f"{'--rig-map' if rig_map is not None else '--ground'} needs --contacts")
    rig_map = read_rig_map(rig_map) if rig_map is not None else None
    motions, names = load_labelled(files, labels, in_fmt, keys_text, key_every)
    info = draw(motions, names, output, joints=joints, channels=channels, frames=frames, positions=positions,
                contacts=contacts, rig_map=rig_map, ground=ground)
    if as_json:
        emit_json({"input": list(files), **info.as_dict()})
    else:
        bands = f" and the foot contacts of {len(files)} file(s)" if contacts else ""
        say(f"wrote {output}: {len(info.panels)} panels ({', '.join(info.panels)}) of {len(files)} file(s){bands}")
