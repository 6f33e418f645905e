"""``keyfill edit-tangents``: reshape the motion between keys by optimising Bezier tangents.

Also holds what ``keyfill pose`` shares with it: the output options, the
run of an edit file and the report line.
"""

from __future__ import annotations

import click

from keyfill import io
from keyfill.cli.common import emit_json, say


def describe(report) -> str:
    """One human line for an edit report."""
    where = f"edit {report.edit}: "
    if report.kind == "timing":
        return where + f"timing at frame {report.time:g}: {report.optimised_tangents} tangents rescaled"
    verb = "reached" if report.reached else "did NOT reach"
    text = (
        f"{report.joint} at frame {report.time:g} {verb} its target (distance {report.distance:.3g}) "
        f"in {report.iterations} iteration(s), {report.optimised_tangents or report.optimised_controls} "
        f"{'tangents' if report.optimised_tangents else 'key values'}, {report.solve_ms:.1f} ms"
    )
    if report.worst_pin_violation is not None:
        text += f"; pins within {report.worst_pin_violation:.2g}"
    if report.worst_contact_violation is not None:
        text += f"; contacts within {report.worst_contact_violation:.2g}"
    if report.worst_limit_margin is not None:
        text += f"; limit margin {report.worst_limit_margin:.3g} ({report.worst_limit_control})"
    return where + text


def output_options(f):
    """``-o``, ``--solver``, ``--best-effort`` and ``--json``, shared with ``keyfill pose``."""
    f = click.option("--json", "as_json", is_flag=True, help="Print a per-edit report as JSON on stdout.")(f)
    f = click.option(
        "--best-effort",
        is_flag=True,
        help="Keep the closest result of an edit that cannot reach its target instead of failing.",
    )(f)
    f = click.option("--force", is_flag=True, help="Allow -o to be CURVES itself (overwrite the input), or a read-only file.")(f)
    f = click.option(
        "--solver",
        default="daqp",
        show_default=True,
        help="QP backend: any solver installed for qpsolvers (daqp, quadprog, piqp, ...).",
    )(f)
    return click.option(
        "-o",
        "--output",
        "dst",
        required=True,
        type=click.Path(dir_okay=False),
        help=f"Output: a curves file ({', '.join(io.suffixes('usd'))}) or the baked motion "
             f"({', '.join(s for s in io.SUFFIXES if s not in io.suffixes('usd'))}).",
    )(f)


def run_edits(mode, curves_path, edit_path, dst, solver, best_effort, as_json, frame=None, force=False) -> None:
    """Read the curves, apply the edit file (``mode`` "tangents" or "pose"), write and report."""
    from keyfill.files import refuse_overwriting_input
    from keyfill.io.batch_record import refuse_read_only

    refuse_overwriting_input(dst, [curves_path, edit_path], force)
    refuse_read_only(dst, force)
    from keyfill.edit import edits, solve
    from keyfill.edit.qp import check_solver
    from keyfill.errors import InfeasibleError
    from keyfill.io import usd_curves as curvefile

    check_solver(solver)
    curves = curvefile.read(curves_path)
    edit_file = edits.load(edit_path, curves, mode=mode, frame=frame)
    apply = solve.edit_tangents if mode == "tangents" else solve.pose
    try:
        result, reports = apply(curves, edit_file, solver=solver, best_effort=best_effort)
    except InfeasibleError as e:
        raise InfeasibleError(f"{e}; nothing written (--best-effort keeps the closest result)",
                              params=e.params) from None
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


@click.command("edit-tangents")
@click.argument("curves_path", metavar="CURVES", type=click.Path(dir_okay=False))
@click.option(
    "--edit",
    "edit_path",
    required=True,
    type=click.Path(dir_okay=False),
    help="Edit file (TOML): points to move, pins, contacts, limits, stiffness, timing edits.",
)
@output_options
def edit_tangents(curves_path, edit_path, dst, force, solver, best_effort, as_json):
    """Move points of the character between keys by changing only curve tangents.

    CURVES is a keyfill curves file (make one with `keyfill convert dense.bvh
    curves.usda --curves --keys 0,12,30`). Each edit of the TOML file drags a
    point (joint + offset) at a frame between two keys toward a target while
    pins, contacts, joint limits and stiffness hold (Ciccone et al. 2019).
    Key times and values never change and no key is added. An edit that
    cannot reach its target exits 1 naming the constraints in the way and
    writes nothing, unless --best-effort. See docs/editing.md for the format.

    \b
    Examples:
      keyfill edit-tangents walk.usda --edit reach.toml -o walk_edited.usda
      keyfill edit-tangents walk.usda --edit reach.toml -o walk_edited.bvh --json
    """
    run_edits("tangents", curves_path, edit_path, dst, solver, best_effort, as_json, force=force)
