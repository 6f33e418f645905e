"""``keyfill library``: build and inspect motion libraries (``complete --method match``), and give a model
folder the pose index of its corpus (the guard's)."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, progress, say
from keyfill.cli.main import SuggestingGroup


@click.group(cls=SuggestingGroup)
def library():
    """Motion libraries: real motion that --method match fills gaps from.

    \b
    Examples:
      keyfill library build bandai2/data --exclude '*_normal_*' -o bandai2-lib
      keyfill library info bandai2-lib
      keyfill complete walk.bvh --key-every 60 --method match --library bandai2-lib -o walk_matched.bvh
      keyfill library index my-transformer bandai2/data --exclude '*_normal_*'
    """


@library.command()
@click.argument("clips", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("-o", "--output", "out", required=True, type=click.Path(file_okay=False),
              help="The library folder to write; an existing library is updated (only new or changed clips are "
                   "read) and then holds exactly the clips given.")
@click.option("--include", multiple=True, metavar="GLOB", help="Take only clips whose file name matches one of these.")
@click.option("--exclude", multiple=True, metavar="GLOB", help="Leave out clips whose file name matches (e.g. a "
              "style kept for testing).")
@click.option("--every", type=int, default=1, show_default=True, metavar="N",
              help="Take every N-th of the clips (sorted by path): a smaller library.")
@click.option("--fps", type=float, help="The library's frame rate [default: the first clip's]; clips at other "
              "rates are resampled.")
@click.option("--precision", type=click.Choice(["single", "half"]), default="single", show_default=True,
              help="Store rotations and pose features as 32-bit or 16-bit floats (half the size).")
@click.option("--rig-map", type=click.Path(exists=True, dir_okay=False), metavar="FILE.toml",
              help="Humanoid roles of clips whose rig the mapper does not resolve (docs/retarget.md).")
@click.option("--workers", type=int, metavar="N", help="Local worker processes [default: one per core].")
@click.option("--scheduler", metavar="ADDRESS", help="Read the clips on a Dask cluster, e.g. tcp://host:8786.")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def build(clips, out, include, exclude, every, fps, precision, rig_map, workers, scheduler, as_json):
    """Build a motion library from CLIPS (files or folders of any format keyfill reads).

    The first clip's skeleton is the library's (it must be a humanoid); clips
    of other humanoid rigs are retargeted onto it, other frame rates
    resampled. Each frame is stored with its pose features in memory-mapped
    arrays (docs/match.md); the manifest names every clip by the SHA-256 of
    its bytes, so a re-run reads only new or changed clips.

    \b
    Examples:
      keyfill library build clips/ -o mylib
      keyfill library build bandai2/data --exclude '*_normal_*' --every 3 --precision half -o small-lib
    """
    from keyfill.learn.library.store import build as build_library

    rig = None
    if rig_map is not None:
        from keyfill.characters.humanoid import read_rig_map

        rig = read_rig_map(rig_map)
    with progress(total=None, desc="clips", unit="clip") as bar:
        def advance(done, total):
            bar.total = total
            bar.update(1)

        report = build_library(clips, out, include=include, exclude=exclude, every=every, rig_map=rig, fps=fps,
                               precision=precision, workers=workers, scheduler=scheduler, progress=advance)
    if as_json:
        emit_json(report)
        return
    skipped = f", {len(report['skipped'])} too short to use" if report["skipped"] else ""
    say(f"wrote {out}: {report['clips']} clips, {report['frames']} frames ({report['added']} read, "
        f"{report['reused']} kept, {report['removed']} removed{skipped})")


@library.command()
@click.argument("lib", type=click.Path(exists=True, file_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON on stdout.")
def info(lib, as_json):
    """Describe the motion library LIB: clips, frames, skeleton, size.

    \b
    Example:
      keyfill library info bandai2-lib
    """
    from keyfill.learn.library.store import load

    summary = load(lib).info()
    if as_json:
        emit_json(summary)
        return
    click.echo(f"{summary['library']}: {summary['clips']} clips, {summary['frames']} frames "
               f"({summary['seconds'] / 60:.1f} min at {summary['fps']:g} fps), {summary['joints']} joints "
               f"(top {summary['skeleton_top']}, hips {summary['hips']}), {summary['precision']} precision, "
               f"spread {100 * summary['spread_m']:.2f} cm, {summary['bytes'] / 2**20:.1f} MiB")


@library.command()
@click.argument("model", type=click.Path(exists=True, file_okay=False))
@click.argument("clips", nargs=-1, required=True, type=click.Path(exists=True))
@click.option("--include", multiple=True, metavar="GLOB", help="Take only clips whose file name matches one of these.")
@click.option("--exclude", multiple=True, metavar="GLOB", help="Leave out clips whose file name matches.")
@click.option("--json", "as_json", is_flag=True, help="Print a summary as JSON on stdout.")
def index(model, clips, include, exclude, as_json):
    """Write the pose index of MODEL's training clips into MODEL (pose_index.npz).

    The guard of 'keyfill complete' compares every gap's keys and output with
    the poses a model knows; 'keyfill train' writes the index of a new
    model itself. Give the clips (and the --include/--exclude) the model was
    trained on.

    \b
    Example:
      keyfill library index models/my-transformer bandai2/data --exclude '*_normal_*'
    """
    from keyfill.learn.library.guard import model_pose_index

    written = model_pose_index(model, clips, include, exclude)
    if as_json:
        emit_json({"model": model, "pose_index": str(written["path"]), "poses": written["poses"],
                   "spread_m": written["spread_m"]})
        return
    say(f"wrote {written['path']}: {written['poses']} poses, spread {100 * written['spread_m']:.2f} cm")
