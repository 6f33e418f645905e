"""Tangent-space editing of Bezier animation curves (Ciccone, Oztireli & Sumner 2019).

The curves themselves are a core data type, :mod:`keyfill.curves` (per-control
Bezier keys and tangents, exact evaluation, baking to a Motion) and their USD
files are :mod:`keyfill.io.usd_curves`.

* :mod:`keyfill.edit.fit`: curves through the keys of a dense motion;
* :mod:`keyfill.edit.rig`: states of points and their Jacobians with respect to the controls;
* :mod:`keyfill.edit.edits`: edit files (TOML);
* :mod:`keyfill.edit.qp`: the quadratic programs (Eqs. 10 and 13) through qpsolvers;
* :mod:`keyfill.edit.solve`: ``edit_tangents`` and ``pose``.

The walkthrough is docs/editing.md.
"""
