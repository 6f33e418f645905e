"""``keyfill complete``: fill in the frames between keys."""

from __future__ import annotations

import click

from keyfill.cli.common import (FORMAT_CHOICE, apply_partial_keys, emit_json, keys_options, output_format,
                                partial_keys_options, resolve_keys, say)
from keyfill.learn.registry import METHODS


@click.command()
@click.argument("src", type=click.Path(dir_okay=False, allow_dash=True))
@click.option("-o", "--output", "dst", required=True, type=click.Path(dir_okay=False, allow_dash=True),
              help="Output file (.bvh, .usda, .usdc, .usd) or '-' with --format.")
@keys_options
@partial_keys_options
@click.option("--method", type=click.Choice(sorted(METHODS)), default="cubic", show_default=True,
              help="In-betweening method.")
@click.option("--model", type=click.Path(exists=True), help="Model folder for a learned method (default: the model shipped for it, if any).")
@click.option("--exact-keys/--no-exact-keys", default=True, show_default=True,
              help="Make frames at keys equal the input keys exactly (learned methods correct smoothly).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for methods with randomness.")
@click.option("--device", default="cpu", show_default=True, help="Torch device for learned methods.")
@click.option("--dna", metavar="FILE[:FRAMES]",
              help="Motion DNA (gan models trained with --dna): the representative frames of FILE, or the listed "
                   "frames of it (e.g. salsa.bvh:12,80,140), steer the style of the in-betweens. Without it the "
                   "poses are drawn from the model's own bank by --seed.")
@click.option("--dna-count", type=int, metavar="K",
              help="How many representative frames of the DNA file (or the bank) to use (default: one per 3 s of "
                   "the gaps between keys).")
@click.option("--format", "fmt", type=FORMAT_CHOICE, help="Output format (needed when the output is '-').")
@click.option("--in-format", "in_fmt", type=FORMAT_CHOICE, help="Input format (needed when SRC is '-').")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def complete(src, dst, keys_text, key_every, key_joints, key_positions, key_plane, method, model, exact_keys, seed, device,
             dna, dna_count, fmt, in_fmt, as_json):
    """Fill in the frames between the keys of SRC and write the result.

    Keys come from --keys or --key-every, or else from the file itself (the
    authored time samples of a sparse USD file). Only the key frames of SRC
    are read; every other frame is generated. Frames at keys come out
    identical to the input keys.

    Partial keys give only some joints (--key-joints), only positions
    (--key-positions) or 2-D positions in a view plane (--key-plane); methods
    that accept them say so below (the others refuse). Exact keys then fix only
    what the keys give.

    \b
    Methods:
    {methods}

    \b
    Examples:
      keyfill complete keys.usda -o filled.usda
      keyfill complete walk.bvh --keys 0,12,30 --method linear -o walk_lerp.bvh
      keyfill complete walk.bvh --key-every 10 -o - --format bvh | keyfill info - --format bvh
      keyfill complete path.bvh --keys 0,200,400 --key-joints Hips --key-positions --method gan --model m -o out.bvh
      keyfill complete walk.bvh --keys 0,300,600 --method gan --model m --dna salsa.bvh --dna-count 4 -o salsa_walk.bvh
    """
    from keyfill import io
    from keyfill.learn.completion import CompleteOptions
    from keyfill.learn.registry import complete as run

    motion = io.load(src, in_fmt)
    keys = apply_partial_keys(motion, resolve_keys(motion, keys_text, key_every), key_joints, key_positions,
                              key_plane)
    options = CompleteOptions(model=model, exact_keys=exact_keys, seed=seed, device=device, dna=dna,
                              dna_count=dna_count)
    result = run(motion, keys, method, options)
    io.save(result.motion, dst, output_format(dst, fmt))
    if as_json:
        emit_json({"input": src, "output": dst, **result.info})
    elif dst != "-":
        say(f"wrote {dst}: {motion.num_frames} frames completed from {len(keys)} keys with {method}")


complete.help = complete.help.replace(  # the docstring's indentation, so click's dedent keeps the block
    "    {methods}", "\n".join(f"      {m.name:<12} {m.summary}{' (accepts partial keys)' if m.partial_keys else ''}" for m in METHODS.values()))
