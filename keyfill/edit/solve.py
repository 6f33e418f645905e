"""Tangent-space optimisation (Ciccone, Oztireli & Sumner 2019): the public API of edit files.

:func:`edit_tangents` applies the edits of an edit file in order:

* a *move* edit drags a point of the skeleton at a time between two keys
  toward a target by changing only the tangents of that segment (key times
  and values never change, no key is added): :mod:`keyfill.edit.move`, with
  the paper's reduction (:mod:`keyfill.edit.reduction`), the tangent bounds
  of Eqs. 7-9 (:mod:`keyfill.edit.bounds`) and the QP iteration of section
  3.3 (:mod:`keyfill.edit.iteration`, the QPs in :mod:`keyfill.edit.qp`);
* a *timing* edit applies Eq. 12 (:mod:`keyfill.edit.timing`).

:func:`pose` is the static case of Eq. 13 (:mod:`keyfill.edit.keypose`): it
changes the values at one key (the tangents stay) with pins held at that key.

What the edits of a file share (settings, tolerances, limits, the working
curves) is :mod:`keyfill.edit.session`; the dense checks after each edit,
:mod:`keyfill.edit.checks`. Defaults: ``epsilon = 1e-4`` and ``tolerance =
1e-3`` times the character's size (the extent of its rest pose), in the
file's units.
"""

from __future__ import annotations

from keyfill.curves import Curves
from keyfill.edit import qp as QP
from keyfill.edit.checks import check_contacts
from keyfill.edit.edits import EditFile, Manipulation, TimingEdit
from keyfill.edit.keypose import pose_key
from keyfill.edit.move import move
from keyfill.edit.session import EditReport, Session, Settings, character_size
from keyfill.edit.timing import timing

#: the settings of an edit unless others are given (frozen, so one instance serves every call)
DEFAULT_SETTINGS = Settings()

__all__ = ["EditReport", "Settings", "character_size", "edit_tangents", "pose"]


def edit_tangents(
    curves: Curves,
    edit_file: EditFile,
    solver: str = QP.DEFAULT_SOLVER,
    best_effort: bool = False,
    settings: Settings = DEFAULT_SETTINGS,
) -> tuple[Curves, list[EditReport]]:
    """Apply the edits of ``edit_file`` in order; returns the new curves and one report per edit.

    Raises :class:`~keyfill.errors.InfeasibleError` for an edit that cannot
    reach its target (unless ``best_effort``: then the closest result that
    keeps every constraint is kept and its report says ``reached = False``).
    """
    session = Session(curves, edit_file, solver, best_effort, settings)
    check_contacts(
        session,
        list(edit_file.contacts) + [c for e in edit_file.edits if isinstance(e, Manipulation) for c in e.contacts],
    )
    reports = []
    for edit in edit_file.edits:
        reports.append(timing(session, edit) if isinstance(edit, TimingEdit) else move(session, edit))
    return session.work.result(), reports


def pose(
    curves: Curves,
    edit_file: EditFile,
    solver: str = QP.DEFAULT_SOLVER,
    best_effort: bool = False,
    settings: Settings = DEFAULT_SETTINGS,
) -> tuple[Curves, list[EditReport]]:
    """Change key poses (Eq. 13): each edit moves its point at its key frame; tangents stay."""
    session = Session(curves, edit_file, solver, best_effort, settings)
    reports = [pose_key(session, edit) for edit in edit_file.edits]
    return session.work.result(), reports
