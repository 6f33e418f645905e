"""Tangent-space editing of Bezier animation curves (Ciccone, Oztireli & Sumner 2019).

The curves themselves are a core data type, :mod:`keyfill.curves` (per-control
Bezier keys and tangents, exact evaluation, baking to a Motion) and their USD
files are :mod:`keyfill.io.usd_curves`.

* :mod:`keyfill.edit.fit`: curves through the keys of a dense motion;
* :mod:`keyfill.edit.rig`: states of points and their Jacobians with respect to the controls;
* :mod:`keyfill.edit.edits`: edit files (TOML);
* :mod:`keyfill.edit.solve`: ``edit_tangents`` and ``pose``, the public API;
* :mod:`keyfill.edit.session`: what the edits of a file share (settings, working curves, reports);
* :mod:`keyfill.edit.reduction`: the paper's reduction: optimised controls, variables, samples;
* :mod:`keyfill.edit.bounds`: bounds of tangents (Eqs. 7-9) and key values (Eq. 13);
* :mod:`keyfill.edit.iteration`: the QP iteration shared by move edits and poses;
* :mod:`keyfill.edit.qp`: the quadratic programs (Eqs. 10 and 13) through qpsolvers;
* :mod:`keyfill.edit.move`, :mod:`keyfill.edit.timing`, :mod:`keyfill.edit.keypose`:
  move edits, timing edits (Eq. 12), key poses (Eq. 13);
* :mod:`keyfill.edit.checks`: dense checks of pins, contacts and limits.

The walkthrough is docs/editing.md.
"""
