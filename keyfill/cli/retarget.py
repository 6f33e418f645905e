"""``keyfill retarget``: a clip onto another character's skeleton."""

from __future__ import annotations

import click

from keyfill import io
from keyfill.cli.common import (
    FORMAT_CHOICE,
    batch_options,
    emit_json,
    in_format_option,
    input_format,
    output_format,
    run_batch,
    say,
)

_MAP = "TOML lines role = \"JointName\", e.g. hand_l = \"L_Wrist\"; spine = [...] for the chain"


@click.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(allow_dash=True), metavar="IN...")
@click.option("--to", "rig", required=True, type=click.Path(dir_okay=False), metavar="RIG",
              help="The target rig: any motion file keyfill reads (BVH, USD, glTF); its skeleton is the output's. "
                   "Its frames are not used (the reference T-pose comes from its rest offsets).")
@click.option("-o", "--output", "dst", required=True, type=click.Path(allow_dash=True),
              help=f"Output file ({', '.join(io.SUFFIXES)}) or '-' with --format; for several inputs, a folder "
                   "(OUTDIR/).")
@click.option("--rig-map", type=click.Path(exists=True, dir_okay=False), metavar="FILE.toml",
              help=f"Roles the mapper does not find in IN's skeleton ({_MAP}).")
@click.option("--to-rig-map", type=click.Path(exists=True, dir_okay=False), metavar="FILE.toml",
              help=f"Roles the mapper does not find in RIG's skeleton ({_MAP}).")
@click.option("--format", "fmt", type=FORMAT_CHOICE,
              help="Output format (needed when the output is '-'; with -o OUTDIR/, the outputs' suffix).")
@in_format_option
@batch_options
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def retarget(inputs, rig, dst, rig_map, to_rig_map, fmt, in_fmt, workers, scheduler, connect_timeout, force,
             batch_size, as_json):
    """Retarget the motion of IN onto the skeleton of another humanoid character, RIG.

    Both skeletons get their humanoid roles (hips, spine chain, neck, head,
    per side clavicle, upper arm, forearm, hand, thigh, shin, foot, toe) from
    their joint names and hierarchy; 'keyfill info FILE --rig' shows them,
    and --rig-map / --to-rig-map give those the mapper cannot find. Each
    rig's reference T-pose is computed from its rest offsets, so RIG's own
    frames (an A-pose, an animation) play no part. Every mapped joint takes
    IN's world rotation relative to IN's T-pose; spine and neck chains of
    different lengths are spread over each other; the hips' path is scaled
    by the ratio of the hip heights, which converts units too, and turned
    to RIG's up axis. Joints with no role (fingers, twist bones) keep RIG's
    reference pose.

    The output has RIG's skeleton, channel layout, Euler orders, units and
    up axis, and IN's frame rate, frame count and keys. A glTF output onto
    a glTF RIG keeps RIG's meshes. See docs/retarget.md.

    Many files: 'keyfill retarget IN... --to RIG -o OUTDIR/' works like
    'keyfill convert': inputs are files, folders and globs, each output gets
    the input's relative name (--format sets the suffix), outputs the
    folder's record says were made the same way are skipped and the others
    redone (docs/batch.md; --force redoes all), a bad input is reported
    on its own line and the others go on (exit code 1), and --workers or
    --scheduler spread the work.

    \b
    Examples:
      keyfill retarget mixamo_walk.bvh --to cmu_rig.bvh -o cmu_walk.bvh
      keyfill retarget walk.bvh --to character.glb -o character_walk.glb     (keeps the meshes)
      keyfill retarget walk.bvh --to robot.usda --to-rig-map robot.toml -o robot_walk.usda
      keyfill retarget clips/ --to cmu_rig.bvh -o cmu_clips/ --workers 2
      keyfill retarget 'takes/*.bvh' --to hero.bvh -o hero/ --format usda --json
    """
    from keyfill.errors import UsageError
    from keyfill.io.batch import is_batch
    from keyfill.io.retarget_files import RetargetSpec, load_target, retarget_file

    if rig == "-":
        raise UsageError("--to names a rig file; standard input can only be IN")
    if is_batch(inputs, dst):
        if dst == "-" or in_fmt is not None:
            raise UsageError("a batch reads files by their suffixes and writes into a folder (-o OUTDIR/); "
                             "'-' and --in-format take one file")
        spec = RetargetSpec(rig, rig_map, to_rig_map)

        def check():  # the rig and both rig maps, once, before any input is read
            load_target(rig, to_rig_map)
            if rig_map is not None:
                from keyfill.characters.humanoid import read_rig_map

                read_rig_map(rig_map)

        return run_batch(inputs, dst, fmt, "keyfill.io.retarget_files:retarget_chunk", spec, workers, scheduler,
                         connect_timeout, force, batch_size, as_json, "retargeted", check=check)
    if len(inputs) != 1:
        raise UsageError("several inputs need an output folder: -o OUTDIR/")
    src = inputs[0]
    from keyfill.files import refuse_overwriting_input
    from keyfill.io.batch_record import refuse_read_only

    refuse_overwriting_input(dst, [src, rig], force)
    refuse_read_only(dst, force)
    report = retarget_file(src, rig, dst, rig_map, to_rig_map, input_format(src, in_fmt), output_format(dst, fmt))
    if as_json:
        emit_json(report)
    elif dst != "-":
        say(f"wrote {dst}: {report['frames']} frames at {report['fps']:g} fps on the {report['joints']} joints of "
            f"{rig}")
