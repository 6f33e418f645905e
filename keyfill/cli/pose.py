"""``keyfill pose``: change a key pose by moving points (the static case of tangent-space editing)."""

from __future__ import annotations

import click

from keyfill.cli.common import emit_json, say


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
@click.option(
    "-o",
    "--output",
    "dst",
    required=True,
    type=click.Path(dir_okay=False),
    help="Output: a curves file (.usda, .usdc, .usd) or the baked motion (.bvh).",
)
@click.option(
    "--solver",
    default="daqp",
    show_default=True,
    help="QP backend: any solver installed for qpsolvers (daqp, quadprog, piqp, ...).",
)
@click.option(
    "--best-effort",
    is_flag=True,
    help="Keep the closest result of an edit that cannot reach its target instead of failing.",
)
@click.option("--json", "as_json", is_flag=True, help="Print a per-edit report as JSON on stdout.")
def pose(curves_path, edit_path, frame, dst, solver, best_effort, as_json):
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
    from keyfill.cli.edit_tangents import describe
    from keyfill.edit import curvefile, edits, solve
    from keyfill.edit.qp import check_solver
    from keyfill.errors import InfeasibleError

    check_solver(solver)
    curves = curvefile.read(curves_path)
    edit_file = edits.load(edit_path, curves, mode="pose", frame=frame)
    try:
        result, reports = solve.pose(curves, edit_file, solver=solver, best_effort=best_effort)
    except InfeasibleError as e:
        raise InfeasibleError(f"{e}; nothing written (--best-effort keeps the closest result)") from None
    curvefile.save(result, dst)
    if as_json:
        emit_json(
            {
                "input": curves_path,
                "edit_file": edit_path,
                "output": dst,
                "solver": solver,
                "edits": [r.as_dict() for r in reports],
            }
        )
    for r in reports:
        say(describe(r))
    say(f"wrote {dst}")
