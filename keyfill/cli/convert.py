"""``keyfill convert``: between the formats of :data:`keyfill.io.FORMATS` (BVH, USD, glTF)."""

from __future__ import annotations

import click

from keyfill.cli.common import (
    FORMAT_CHOICE,
    batch_options,
    bvh_layout_option,
    emit_json,
    in_format_option,
    input_format,
    keys_options,
    meters_per_unit_option,
    output_format,
    resolve_keys,
    run_batch,
    say,
    up_axis_option,
    usd_layer_option,
)


@click.command()
@click.argument("paths", nargs=-1, required=True, type=click.Path(allow_dash=True), metavar="SRC [DST]")
@click.option("-o", "--output", "outdir", type=click.Path(file_okay=False),
              help="Output folder: every SRC (files, folders, globs) is converted into it.")
@click.option("--format", "fmt", type=FORMAT_CHOICE,
              help="Output format (needed when DST is '-'; with -o, the outputs' suffix).")
@in_format_option
@meters_per_unit_option
@up_axis_option
@bvh_layout_option
@usd_layer_option
@click.option("--curves", is_flag=True,
              help="Fit editable Bezier curves through the keys and write a curves file (USD only).")
@keys_options
@batch_options
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def convert(paths, outdir, fmt, in_fmt, meters_per_unit, up_axis, bvh_layout, usd_layer, curves, keys_text, key_every,
            workers, scheduler, connect_timeout, force, batch_size, as_json):
    """Convert a motion file between BVH, USD (.usda, .usdc, .usd, .usdz) and glTF (.glb, .gltf); FBX (.fbx,
    pip install 'keyfill[fbx]') is read, not written.

    Formats come from the suffixes; '-' reads standard input or writes
    standard output (then give --in-format / --format). BVH -> USD -> BVH and
    BVH -> glTF -> BVH keep the joint names, channel layouts (--bvh-layout
    source for one that is not full), Euler orders and End Sites; glTF -> glTF
    keeps the meshes and materials of SRC, and USD -> USD (.usda, .usdc, .usd,
    .usdz) the whole stage of SRC (meshes, materials, skinning, names) with its
    joint samples replaced, or with --usd-layer over writes a small layer of
    the new samples over SRC. From glTF to another format, a note on stderr
    names the meshes and materials left behind. A BVH
    written from USD or glTF gets the layout every reader takes unless the
    file records a full BVH layout (--bvh-layout; docs/formats.md). The output
    is written atomically: on any error no file appears (docs/formats.md).

    With --curves, DST becomes a curves file for `keyfill edit-tangents`:
    Bezier curves through the keys (--keys, --key-every, or the file's own),
    exact at the keys and least-squares in between. Reading a curves file
    bakes its curves, so converting it to BVH gives the motion it describes.

    Many files: `keyfill convert SRC... -o OUTDIR/ --format FMT` converts
    every SRC (files, folders recursively, globs) to OUTDIR with the same
    relative names, skips only outputs its record says were made the same
    way (from the same input bytes; docs/batch.md) and redoes the others
    (--force redoes all), reports a bad input on its own line and goes on (exit code 1),
    and runs on --workers local processes or a Dask --scheduler.

    \b
    Examples:
      keyfill convert walk.bvh walk.usda
      keyfill convert walk.usdc walk.bvh
      keyfill convert walk.bvh walk.glb
      keyfill convert walk.bvh walk_curves.usda --curves --keys 0,10,20,30
      cat walk.bvh | keyfill convert - - --format usda > walk.usda
      keyfill convert capture.bvh capture.usda --meters-per-unit 0.0254     (inches: metersPerUnit 0.0254)
      keyfill convert blender_export.bvh shot.usda --up-axis Z               (upAxis Z)
      keyfill convert edge_layout.bvh for_blender.bvh --bvh-layout full      (3 rotation channels per joint)
      keyfill convert shot.usdc shot.usdz                                   (a package, with its textures)
      keyfill convert shot.usda shot_anim.usda --usd-layer over              (a layer over shot.usda)
      keyfill convert mocap/ -o usd/ --format usdc --workers 2
    """
    from keyfill import io
    from keyfill.errors import UsageError
    from keyfill.io import usd_stage

    if outdir is not None:
        if curves or keys_text is not None or key_every is not None or in_fmt is not None \
                or meters_per_unit is not None or up_axis is not None:
            raise UsageError("-o OUTDIR converts motion files by their suffixes; --curves, --keys, --key-every, "
                             "--in-format, --meters-per-unit and --up-axis take one SRC and DST")
        if usd_layer is not None:
            raise UsageError("--usd-layer takes one input file and one output, not a batch")
        if bvh_layout is not None and fmt is not None:
            io.check_bvh_layout(bvh_layout, fmt)
        return run_batch(paths, outdir, fmt, "keyfill.io.batch:convert_chunk", bvh_layout, workers, scheduler,
                         connect_timeout, force, batch_size, as_json, "converted")
    if len(paths) == 1:
        raise click.UsageError("Missing argument 'DST' (or, for many files, -o OUTDIR/)")
    if len(paths) != 2:
        raise click.UsageError(f"got {len(paths)} paths: give SRC DST, or SRC... -o OUTDIR/")
    src, dst = paths
    from keyfill.files import refuse_overwriting_input
    from keyfill.io.batch_record import refuse_read_only

    if not curves:  # a misnamed output is refused before any work (--curves checks its own below)
        fmt = output_format(dst, fmt)
        if bvh_layout is not None:
            io.check_bvh_layout(bvh_layout, io.format_of(dst, fmt))
        usd_stage.check_option(usd_layer, io.format_of(dst, fmt), src)
    elif usd_layer is not None:
        raise UsageError("--usd-layer chooses what a USD output keeps of a USD input; --curves writes a curves file")
    elif bvh_layout is not None:
        raise UsageError("--bvh-layout lays out BVH outputs; --curves writes a USD curves file")
    refuse_overwriting_input(dst, [src], force)
    refuse_read_only(dst, force)

    template = None if curves else usd_stage.template_for(src, io.format_of(dst, fmt), usd_layer)
    motion = io.load(src, input_format(src, in_fmt), meters_per_unit, up_axis)
    if curves:
        from keyfill.edit.fit import fit
        from keyfill.io import usd_curves as curvefile

        if dst == "-" or io.FORMATS[io.format_of(dst, fmt)].family != "usd":
            raise UsageError(f"--curves writes a USD curves file: give DST a {io.listing(io.suffixes('usd'))} name")
        keys = resolve_keys(motion, keys_text, key_every)
        curvefile.save(fit(motion, keys), dst)
    elif keys_text is not None or key_every is not None:
        raise UsageError("--keys and --key-every choose the keys of --curves; add --curves")
    else:
        layer = {} if usd_layer is None else {"usd_layer": usd_layer}
        io.save(motion, dst, fmt, source=src, bvh_layout=bvh_layout, template=template, **layer)
    if as_json and dst != "-":
        emit_json({"input": src, "output": dst, "frames": motion.num_frames, "joints": motion.num_joints})
    elif dst != "-":
        say(f"wrote {dst} ({motion.num_frames} frames, {motion.num_joints} joints)")
