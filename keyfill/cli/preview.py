"""``keyfill preview``: stick-figure pictures of motion files."""

from __future__ import annotations

import re

import click

from keyfill.cli.common import emit_json, in_format_option, keys_options, load_labelled, progress, say


def _size(ctx, param, value):
    if value is None:
        return None
    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", value)
    if not m:
        raise click.BadParameter(f"expected WIDTHxHEIGHT in pixels, like 480x360; got {value!r}")
    return int(m.group(1)), int(m.group(2))


@click.command()
@click.argument("files", nargs=-1, required=True, type=click.Path(dir_okay=False, allow_dash=True))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False),
              help="Picture to write: .gif (animation) or .png (filmstrip, or a still with --trail).")
@click.option("--view", type=click.Choice(["side", "front", "top", "3d"]), default="side", show_default=True,
              help="Camera: side (travel runs left to right), front, top, or 3d (oblique from above).")
@click.option("--frames", metavar="A:B", help="Frames A to B-1 (Python slice; 10:, :30 and -50: work too).")
@click.option("--step", type=int, metavar="N",
              help="Show every N-th frame (GIF: keeps the speed; PNG filmstrip: default is 8 even frames).")
@click.option("--trail", multiple=True, metavar="JOINT",
              help="Draw this joint's world path with a dot per frame and the keys circled; repeatable. "
                   "With a .png output: one still of the whole trail and the ghosted key poses.")
@click.option("--fps", type=float, help="GIF playback rate in frames per second (default: the file's).")
@click.option("--size", callback=_size, metavar="WxH",
              help="Picture size in pixels (for a filmstrip: one frame). Default: fitted to the motion, no side under "
                   "300 px.")
@click.option("--labels", metavar="NAMES", help="Names for the files, comma-separated (default: file names).")
@keys_options
@in_format_option
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def preview(files, output, view, frames, step, trail, fps, size, labels, keys_text, key_every, in_fmt, as_json):
    """Draw stick figures of FILES (overlaid, one colour each) from a fixed camera.

    A .gif plays the motion at its frame rate; a .png is a filmstrip of
    evenly spaced frames, or, with --trail, a single still of the joint's
    whole path ("motion curve", a dot per frame) over the ghosted key poses.
    Keys (recorded in the first file, or given with --keys / --key-every) are
    ghosted in pink: in animations and filmstrips the keys on either side of
    the current frame. The camera framing is fixed from the whole motion, so
    poses do not jump; the ground is a grid in the top and 3d views, a line
    in the side and front views and for planar figures such as the lamp.

    \b
    Examples:
      keyfill preview walk.bvh -o walk.gif
      keyfill preview walk.bvh --view 3d --key-every 10 -o walk_strip.png
      keyfill preview before.usda after.usda --labels before,after --trail Hand_L -o hand_path.png
      keyfill preview examples/lamp/truth.usda --trail head -o lamp.gif --fps 15
    """
    from keyfill.viz import PREVIEW_SUFFIXES, check_suffix
    from keyfill.viz.stick import preview as draw

    check_suffix(output, PREVIEW_SUFFIXES)
    motions, names = load_labelled(files, labels, in_fmt, keys_text, key_every)
    info = draw(motions, names, output, view=view, frames=frames, step=step, trail=trail, fps=fps, size=size,
                progress=progress)
    if as_json:
        emit_json({"input": list(files), **info.as_dict()})
    else:
        what = {"gif": f"{len(info.frames)}-frame GIF at {info.fps:g} fps" if info.fps else "",
                "filmstrip": f"filmstrip of {len(info.frames)} frames",
                "still": f"still of the {', '.join(trail)} trail"}[info.kind]
        size = f"{info.size[0]}x{info.size[1]} px"
        if info.kind == "filmstrip":
            size += f" (each frame {info.frame_size[0]}x{info.frame_size[1]} px)"
        say(f"wrote {output}: {what}, {size}, {view} view")
