"""``keyfill convert``: between BVH and USD."""

from __future__ import annotations

import click

from keyfill.cli.common import FORMAT_CHOICE, emit_json, keys_options, output_format, resolve_keys, say


@click.command()
@click.argument("src", type=click.Path(dir_okay=False, allow_dash=True))
@click.argument("dst", type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--format", "fmt", type=FORMAT_CHOICE, help="Output format (needed when DST is '-').")
@click.option("--in-format", "in_fmt", type=FORMAT_CHOICE, help="Input format (needed when SRC is '-').")
@click.option("--curves", is_flag=True,
              help="Fit editable Bezier curves through the keys and write a curves file (USD only).")
@keys_options
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def convert(src, dst, fmt, in_fmt, curves, keys_text, key_every, as_json):
    """Convert a motion file between BVH and USD (.usda, .usdc, .usd).

    Formats come from the suffixes; '-' reads standard input or writes
    standard output (then give --in-format / --format). BVH -> USD -> BVH keeps
    the joint names, channel layouts, Euler orders and End Sites. The output is
    written atomically: on any error no file appears.

    With --curves, DST becomes a curves file for `keyfill edit-tangents`:
    Bezier curves through the keys (--keys, --key-every, or the file's own),
    exact at the keys and least-squares in between. Reading a curves file
    bakes its curves, so converting it to BVH gives the motion it describes.

    \b
    Examples:
      keyfill convert walk.bvh walk.usda
      keyfill convert walk.usdc walk.bvh
      keyfill convert walk.bvh walk_curves.usda --curves --keys 0,10,20,30
      cat walk.bvh | keyfill convert - - --in-format bvh --format usda > walk.usda
    """
    from keyfill import io
    from keyfill.errors import UsageError

    motion = io.load(src, in_fmt)
    if curves:
        from keyfill.edit.fit import fit
        from keyfill.io import usd_curves as curvefile

        if dst == "-" or io.format_of(dst, fmt) == "bvh":
            raise UsageError("--curves writes a USD curves file: give DST a .usda, .usdc or .usd name")
        keys = resolve_keys(motion, keys_text, key_every)
        curvefile.save(fit(motion, keys), dst)
    elif keys_text is not None or key_every is not None:
        raise UsageError("--keys and --key-every choose the keys of --curves; add --curves")
    else:
        io.save(motion, dst, output_format(dst, fmt))
    if as_json and dst != "-":
        emit_json({"input": src, "output": dst, "frames": motion.num_frames, "joints": motion.num_joints})
    elif dst != "-":
        say(f"wrote {dst} ({motion.num_frames} frames, {motion.num_joints} joints)")
