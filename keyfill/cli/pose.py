"""``keyfill pose``: change a key pose by moving points (the static case of tangent-space editing)."""

from __future__ import annotations

import click

from keyfill.cli.edit_tangents import output_options, run_edits


@click.command()
@click.argument("curves_path", metavar="CURVES", type=click.Path(dir_okay=False))
@click.option(
    "--edit",
    "edit_path",
    required=True,
    type=click.Path(dir_okay=False),
    help="Edit file (TOML): points to move, pins, limits, stiffness (same format as edit-tangents).",
)
@click.option(
    "--frame", type=float, metavar="F", help="The key to change, for edits that name no frame (must be a key)."
)
@output_options
def pose(curves_path, edit_path, frame, dst, force, solver, best_effort, as_json):
    """Change the key pose at frame F so that points reach their targets.

    The static case of tangent-space editing (Eq. 13 of Ciccone et al.
    2019): the key values at F change, pins stay where they are at F (a
    contact through F holds like a pin), joint limits and stiffness hold;
    tangents and the other keys stay as they are. An edit that cannot reach
    its target exits 1 naming the constraints in the way and writes nothing,
    unless --best-effort.

    \b
    Examples:
      keyfill pose walk.usda --edit plant_foot.toml --frame 20 -o walk_planted.usda
    """
    run_edits("pose", curves_path, edit_path, dst, solver, best_effort, as_json, frame=frame, force=force)
