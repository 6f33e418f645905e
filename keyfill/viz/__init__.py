"""Pictures of motions: animation curves (``keyfill plot``) and stick figures (``keyfill preview``).

* :mod:`keyfill.viz.curves`: one panel per animation variable (BVH channel as
  Euler angles in the file's own order, a world position, or the hopping
  lamp's six variables), several files overlaid, keys as open circles.
* :mod:`keyfill.viz.stick`: stick figures seen by a fixed orthographic
  camera; keys ghosted, joint trails ("motion curves"), a ground line or
  grid. Renders a GIF, a filmstrip PNG or a trail still.
* :mod:`keyfill.viz.scene`: what a stick figure shows and from where: world
  points and bones from forward kinematics, the views' cameras, the ground.
* :mod:`keyfill.viz.gif`: GIF writing with exact frame timing.
* :mod:`keyfill.viz.palette`: one shared palette per picture with exact colour
  mapping (GIF frames, and small PNGs).
* :mod:`keyfill.viz.style`: colours and deterministic figure saving.

Everything draws with matplotlib's Agg renderer through ``Figure`` objects and
never imports ``pyplot``, so no global backend is selected and nothing needs a
display. This module itself imports only numpy; matplotlib and Pillow load
with the submodules.
"""

from __future__ import annotations

import numpy as np

from keyfill.errors import DataError, UsageError

#: output suffix -> what the commands write there
PLOT_SUFFIXES = (".png", ".svg", ".pdf")
PREVIEW_SUFFIXES = (".gif", ".png")


def frame_range(text: str | None, num_frames: int, label: str = "the motion") -> np.ndarray:
    """Frame indices selected by ``text`` ``"A:B"``, the ``frames`` parameter of the picture functions
    (Python slice rules: A to B-1).

    Either end may be left out (``:30``, ``10:``); negative numbers count from
    the end. ``None`` selects every frame. Raises :class:`UsageError` for
    malformed text and for a range that selects no frame; it names the parameter ``frames``.
    """
    if num_frames == 0:
        raise DataError(f"{label} has no frames")
    if text is None:
        return np.arange(num_frames)
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a, b = (int(p) if p.strip() else None for p in parts)
    except ValueError:
        raise UsageError(f"frames takes A:B (frames A to B-1, either may be left out), got {text!r}",
                         params="frames") from None
    idx = np.arange(num_frames)[slice(a, b)]
    if len(idx) == 0:
        raise UsageError(f"frames {text} selects no frame of {label} (frames 0-{num_frames - 1})", params="frames")
    return idx


def unit_label(meters_per_unit: float) -> str:
    """A short name for a length unit given in meters (``0.01`` -> ``"cm"``)."""
    names = {1.0: "m", 0.01: "cm", 0.001: "mm", 0.0254: "in", 0.3048: "ft"}
    for size, name in names.items():
        if abs(meters_per_unit - size) <= 1e-9 * size:
            return name
    return f"units of {meters_per_unit:g} m"


def check_suffix(path: str, allowed: tuple[str, ...], param: str = "output") -> str:
    """The lower-case suffix of ``path``; a :class:`UsageError` (naming the parameter ``param``) unless it is
    one of ``allowed``."""
    from pathlib import Path

    suffix = Path(path).suffix.lower()
    if suffix not in allowed:
        raise UsageError(
            f"{param} {path}: unsupported picture type {suffix or '(no suffix)'!r}; "
            f"expected {', '.join(allowed)}", params=param
        )
    return suffix
