"""``keyfill complete``: fill in the frames between keys."""

from __future__ import annotations

import click

from keyfill import io
from keyfill.cli.common import (
    FORMAT_CHOICE,
    Choice,
    apply_partial_keys,
    batch_options,
    bvh_layout_option,
    emit_json,
    in_format_option,
    input_format,
    keys_options,
    output_format,
    partial_keys_options,
    resolve_keys,
    run_batch,
    say,
    up_axis_option,
    usd_layer_option,
)
from keyfill.errors import UsageError
from keyfill.learn.registry import ALIASES, METHODS


@click.command()
@click.argument("inputs", nargs=-1, required=True, type=click.Path(allow_dash=True), metavar="IN...")
@click.option("-o", "--output", "dst", required=True, type=click.Path(allow_dash=True),
              help=f"Output file ({', '.join(io.SUFFIXES)}) or '-' with --format; for several inputs, a folder "
                   "(OUTDIR/).")
@keys_options
@partial_keys_options
@click.option("--method", type=Choice(sorted([*METHODS, *ALIASES])),
              help="In-betweening method [default: the kind of the --model folder or graph, else cubic].")
@click.option("--model", type=click.Path(exists=True),
              help="Model folder for a learned method (default: the model shipped for it, if any), or a graph file "
                   "(.onnx) written by 'keyfill export'.")
@click.option("--exact-keys/--no-exact-keys", default=True, show_default=True,
              help="Make frames at keys equal the input keys exactly (learned methods correct smoothly).")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed for methods with randomness: match and a gan model on a matched base take another good "
                   "stretch of their library per seed (0: the best); the shipped spline-base gan only draws its "
                   "Motion DNA from its bank by it, which moves its in-betweens by millimetres (docs/gan.md).")
@click.option("--device", default="cpu", show_default=True, help="Torch device for learned methods.")
@click.option("--dna", metavar="FILE[:FRAMES]",
              help="Motion DNA (gan models trained with --dna): the representative frames of FILE, or the listed "
                   "frames of it (e.g. salsa.bvh:12,80,140), steer the style of the in-betweens; a gan model on a "
                   "matched base also searches its library for stretches near the DNA's poses and among the DNA's "
                   "own. Without it the poses are drawn from the model's own bank by --seed.")
@click.option("--dna-count", type=int, metavar="K",
              help="How many representative frames of the DNA file (or the bank) to use (default: one per 3 s of "
                   "the gaps between keys).")
@click.option("--rig-map", type=click.Path(exists=True, dir_okay=False), metavar="FILE.toml",
              help='Humanoid roles the mapper does not find in IN\'s skeleton, as TOML lines role = "JointName" '
                   "(e.g. hand_l = \"L_Wrist\"); for the methods whose human models serve any humanoid rig "
                   "through retargeting (see 'keyfill info IN --rig' and docs/retarget.md).")
@click.option("--feet", type=click.Choice(["lock", "free"]),
              help="lock: hold each foot still while it touches the ground (legs solved with two-bone IK, keys "
                   "exact; docs/feet.md); free: the method's output as it is [default: lock for --method match and a gan "
                   "on a matched base, whose steps are real motion; free for the others].")
@click.option("--ground", type=float, metavar="HEIGHT",
              help="Height of the ground along the up axis, in IN's units, for --feet (default: the lowest foot "
                   "at the keys).")
@click.option("--library", type=click.Path(exists=True, file_okay=False), metavar="LIB",
              help="Motion library for --method match, or for a gan model on a matched base (keyfill library "
                   "build) [default: the shipped library of the Bandai-Namco skeleton, models/bandai, CC BY-NC 4.0; "
                   "for a gan, the one its model names].")
@click.option("--guard", type=click.Choice(["fallback", "warn", "off"]),
              help="What the human methods (transformer, gan, match) do with gaps whose keys or output are unlike "
                   "anything their model or library knows (docs/match.md): fallback (the default) fills them with "
                   "cubic and says so on stderr, warn only says so, off does not check. --json lists each gap's "
                   "score.")
@click.option("--runtime", type=click.Choice(["auto", "torch", "onnx"]), default="auto", show_default=True,
              help="Run a learned model with torch or its exported ONNX graph (onnxruntime, no torch import; see "
                   "'keyfill export'); auto: the graph when onnxruntime is installed and the model folder holds "
                   "one.")
@click.option("--format", "fmt", type=FORMAT_CHOICE, help="Output format (needed when the output is '-').")
@in_format_option
@up_axis_option
@bvh_layout_option
@usd_layer_option
@batch_options
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def complete(inputs, dst, keys_text, key_every, key_joints, key_positions, key_plane, method, model, exact_keys, seed,
             device, dna, dna_count, rig_map, feet, ground, library, guard, runtime, fmt, in_fmt, up_axis, bvh_layout,
             usd_layer, workers, scheduler, connect_timeout, force, batch_size, as_json):
    """Fill in the frames between the keys of IN and write the result.

    Keys come from --keys or --key-every, or else from the file itself (the
    authored time samples of a sparse USD file). Only the key frames of IN
    are read; every other frame is generated. Frames at keys come out
    identical to the input keys.

    Batch: with several inputs (files, folders, globs) or -o OUTDIR/, each
    input gets an output of the same relative name in OUTDIR (--format sets
    the suffix). A learned method loads its model once per process and
    completes up to --batch-size files in one batch; --workers N spreads the
    batches over local processes and --scheduler over a Dask cluster (the
    outputs are the same bytes either way). OUTDIR/.keyfill-outputs.json
    records how each output was made (the input's content, method, model,
    keys, seed and options; docs/batch.md): a re-run skips only outputs made
    the same way and redoes the others (--json counts them as redone), so an
    interrupted batch resumes and a changed option leaves nothing stale;
    --force redoes all. No output may be one of the inputs (through links
    too) unless --force. A bad input is reported with its reason and the others go on; the exit
    code is then 1, and --json lists every input's outcome.

    Partial keys give only some joints (--key-joints), only positions
    (--key-positions) or 2-D positions in a view plane (--key-plane); methods
    that accept them say so below (the others refuse). Exact keys then fix only
    what the keys give.

    With an exported graph (keyfill export), --runtime onnx or auto runs
    the model through onnxruntime and imports no torch (docs/onnx.md).

    The shipped human models (transformer, gan; CC BY-NC 4.0, their own
    distribution: pip install ./models/bandai from a keyfill checkout)
    complete any humanoid rig at any frame rate: the keys are retargeted onto the model's skeleton and
    frame rate, completed, and retargeted back; the output keeps IN's
    skeleton, channels and fps (docs/retarget.md). --rig-map names the roles
    the mapper cannot find ('keyfill info IN --rig' shows the mapping).

    \b
    Methods:
    {methods}

    \b
    Examples:
      keyfill complete keys.usda -o filled.usda
      keyfill complete walk.bvh --keys 0,12,30 --method linear -o walk_lerp.bvh
      keyfill complete walk.bvh --key-every 10 -o - --format bvh | keyfill info -
      keyfill complete character.glb --key-every 10 -o filled.glb       (keeps the meshes of character.glb)
      keyfill complete shot.usda -o filled.usda                         (keeps the stage of shot.usda)
      keyfill complete shot.usda --usd-layer over -o shot_anim.usda     (only the animation, over shot.usda)
      keyfill complete hops/ --method arnn -o filled/ --workers 2
      keyfill complete 'clips/*.bvh' --key-every 10 -o filled/ --format usda --scheduler tcp://10.0.0.5:8786
      keyfill complete keys.usda --method arnn --model lamp-arnn.onnx -o filled.usda
      keyfill complete examples/human/keys.usda --method gan --seed 3 -o walk.usda     (the shipped human model)
      keyfill complete examples/human/keys_15.usda --method transformer -o walk.usda   (the shipped human transformer)
      keyfill complete path.bvh --keys 0,200,400 --key-joints Hips --key-positions --method gan -o out.bvh
      keyfill complete walk.bvh --keys 0,300,600 --method gan --dna salsa.bvh --dna-count 4 -o salsa_walk.bvh
      keyfill complete mixamo.bvh --key-every 10 --method transformer -o out.bvh     (retargeted to the model)
      keyfill complete robot.bvh --key-every 10 --method transformer --rig-map robot.toml -o out.bvh
      keyfill complete walk.bvh --key-every 60 --method match -o walk_matched.bvh   (real steps, shipped library)
      keyfill complete take.bvh --key-every 60 --method match --library mylib --seed 2 -o take_2.bvh
      keyfill complete sit.bvh --key-every 15 --method transformer --guard warn -o sit.bvh
      keyfill complete walk.bvh --key-every 30 --method cubic --feet lock -o walk_planted.bvh
      keyfill complete walk.bvh --key-every 30 --method transformer --feet free -o walk_raw.bvh
    """
    from keyfill.io import usd_stage
    from keyfill.io.batch import is_batch
    from keyfill.learn.completion import CompleteOptions
    from keyfill.learn.registry import complete as run
    from keyfill.learn.registry import kind_of

    if method is None:  # a model names its own method
        method = kind_of(model) if model is not None else "cubic"

    options = CompleteOptions(model=model, exact_keys=exact_keys, seed=seed, device=device, runtime=runtime, dna=dna,
                              dna_count=dna_count, rig_map=rig_map, feet=feet, ground=ground,
                              library=library, guard=guard)
    if rig_map is not None:  # a damaged rig map is refused before any file is read
        from keyfill.characters.humanoid import read_rig_map

        read_rig_map(rig_map)
    if is_batch(inputs, dst):
        from keyfill.learn.batch import CompleteSpec

        if dst == "-" or in_fmt is not None or up_axis is not None:
            raise UsageError("a batch reads files by their suffixes and writes into a folder (-o OUTDIR/); "
                             "'-', --in-format and --up-axis take one file")
        if usd_layer is not None:
            raise UsageError("--usd-layer takes one input file and one output, not a batch")
        if key_joints or key_positions or key_plane:
            raise UsageError("partial keys (--key-joints, --key-positions, --key-plane) take one file at a time")

        if bvh_layout is not None and fmt is not None:
            io.check_bvh_layout(bvh_layout, fmt)
        spec = CompleteSpec(method, options, keys_text, key_every, bvh_layout=bvh_layout)
        return run_batch(inputs, dst, fmt, "keyfill.learn.batch:complete_chunk", spec, workers, scheduler,
                         connect_timeout, force, batch_size, as_json, "completed", check=lambda: check_method(spec))
    if len(inputs) != 1:
        raise UsageError("several inputs need an output folder: -o OUTDIR/")
    src = inputs[0]
    from keyfill.files import refuse_overwriting_input
    from keyfill.io.batch_record import refuse_read_only

    dna_files = [] if dna is None else [dna, dna.rpartition(":")[0]]  # FILE or FILE:FRAMES
    fmt = output_format(dst, fmt)  # a misnamed output is refused before any work
    if bvh_layout is not None:
        io.check_bvh_layout(bvh_layout, io.format_of(dst, fmt))
    usd_stage.check_option(usd_layer, io.format_of(dst, fmt), src)
    refuse_overwriting_input(dst, [src, *dna_files], force)
    refuse_read_only(dst, force)
    template = usd_stage.template_for(src, io.format_of(dst, fmt), usd_layer)  # before the motion is read
    motion = io.load(src, input_format(src, in_fmt), up_axis=up_axis)
    keys = apply_partial_keys(motion, resolve_keys(motion, keys_text, key_every), key_joints, key_positions,
                              key_plane)
    result = run(motion, keys, method, options)
    frames = motion.num_frames
    del motion  # the input's arrays are not needed to write the result (a long take: half the memory)
    io.save(result.motion, dst, fmt, source=src, bvh_layout=bvh_layout, template=template,
            **({} if usd_layer is None else {"usd_layer": usd_layer}))
    say_guard(src, result.info)
    if as_json:
        emit_json({"input": src, "output": dst, **result.info})
    elif dst != "-":
        say(f"wrote {dst}: {frames} frames completed from {len(keys)} keys with {method}")


def say_guard(src: str, info: dict) -> None:
    """One stderr line when the guard found gaps unlike anything the model knows (docs/match.md)."""
    block = info.get("guard")
    if block and block["unfamiliar"]:
        what = "filled by cubic" if block["mode"] == "fallback" else "kept (--guard warn)"
        say(f"keyfill: {src}: {block['unfamiliar']} of {block['gaps_scored']} gaps unlike anything "
            f"{block['index']} knows: {what}")


def check_method(spec) -> None:
    """Before any file is read: the method, model and runtime of a batch can work (no weights are loaded)."""
    from keyfill.learn.onnx import select
    from keyfill.learn.registry import checked_options, get

    m = get(spec.method)
    options = checked_options(m, spec.options)
    select(m, options.model, options.runtime)  # a missing or foreign graph: refused before any work


complete.help = complete.help.replace(  # the docstring's indentation, so click's dedent keeps the block
    "    {methods}", "\n".join(f"      {m.name:<12} {m.summary}{' (accepts partial keys)' if m.partial_keys else ''}"
              for m in METHODS.values()))
