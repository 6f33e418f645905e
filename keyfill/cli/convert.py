"""``keyfill convert``: between BVH and USD."""

from __future__ import annotations

import click

from keyfill.cli.common import FORMAT_CHOICE, emit_json, output_format, say


@click.command()
@click.argument("src", type=click.Path(dir_okay=False, allow_dash=True))
@click.argument("dst", type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--format", "fmt", type=FORMAT_CHOICE, help="Output format (needed when DST is '-').")
@click.option("--in-format", "in_fmt", type=FORMAT_CHOICE, help="Input format (needed when SRC is '-').")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def convert(src, dst, fmt, in_fmt, as_json):
    """Convert a motion file between BVH and USD (.usda, .usdc, .usd).

    Formats come from the suffixes; '-' reads standard input or writes
    standard output (then give --in-format / --format). BVH -> USD -> BVH keeps
    the joint names, channel layouts, Euler orders and End Sites. The output is
    written atomically: on any error no file appears.

    \b
    Examples:
      keyfill convert walk.bvh walk.usda
      keyfill convert walk.usdc walk.bvh
      cat walk.bvh | keyfill convert - - --in-format bvh --format usda > walk.usda
    """
    from keyfill import io

    motion = io.load(src, in_fmt)
    io.save(motion, dst, output_format(dst, fmt))
    if as_json and dst != "-":
        emit_json({"input": src, "output": dst, "frames": motion.num_frames, "joints": motion.num_joints})
    elif dst != "-":
        say(f"wrote {dst} ({motion.num_frames} frames, {motion.num_joints} joints)")
