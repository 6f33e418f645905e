"""Foot contact bands: under ``keyfill plot``'s curves, where each foot joint touches the ground.

One band set per file, one row per foot joint (:func:`keyfill.characters.feet.contact_joints`: ankle and toe,
left then right), shaded in the file's colour on the frames where
:func:`keyfill.characters.feet.contacts` says the joint is in contact. The labels are those of the whole
motion (the ground from the file's keys, or ``ground``), then cut to the frames shown, so a frame range does
not move the ground. A contact from frame ``a`` to frame ``b`` (inclusive) is shaded from ``a - 0.5`` to
``b + 0.5``: each frame is a cell one frame wide, centred on its number on the curves' x axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.errors import DataError
from keyfill.motion import Motion


@dataclass(frozen=True)
class ContactBands:
    """The foot contacts of one file over the frames shown.

    Attributes:
        label: the file's legend name.
        joints: ``n`` foot joint names, top row first.
        roles: their roles (``foot_l``, ``toe_l``, ``foot_r``, ``toe_r``).
        frames: ``(F,)`` the frame numbers shown (the file's numbering).
        labels: ``(F, n)`` bool, in contact.
    """

    label: str
    joints: tuple[str, ...]
    roles: tuple[str, ...]
    frames: np.ndarray
    labels: np.ndarray

    def intervals(self) -> dict[str, list[list[int]]]:
        """Per joint name, its contact intervals ``[first, last]`` (inclusive, the file's frame numbers)."""
        out = {}
        for k, name in enumerate(self.joints):
            edges = np.diff(np.pad(self.labels[:, k].astype(np.int8), 1))
            starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
            out[name] = [[int(self.frames[a]), int(self.frames[b])] for a, b in zip(starts, ends)]
        return out


def contact_bands(motion: Motion, label: str, frames: np.ndarray, rig_map: dict | None = None,
                  ground: float | None = None) -> ContactBands:
    """The :class:`ContactBands` of ``motion`` (``label``: its name in errors and the figure) on the frame
    indices ``frames``. The rig comes from :func:`keyfill.characters.retarget.make_rig` (``rig_map`` names
    roles the mapper cannot find); a skeleton without legs is a :class:`DataError` that names the missing
    roles."""
    from keyfill.characters import feet
    from keyfill.characters.retarget import make_rig

    try:
        rig = make_rig(motion.skeleton, rig_map=rig_map, label=label)
        cols = feet.contact_joints(rig)
    except DataError as e:
        raise DataError(f"contacts needs a skeleton with legs: {e}", params=("contacts",) + tuple(e.params)) from None
    labels = feet.contacts(motion, rig, ground=ground, keys=motion.keys)
    names = motion.skeleton.names
    return ContactBands(label, tuple(names[j] for _, j in cols), tuple(r for r, _ in cols),
                        np.asarray(frames), labels[np.asarray(frames)])


#: band layout in inches: one row per foot joint, a title line above each file's band
BAND_ROW, BAND_TITLE = 0.17, 0.3


def band_height(bands: ContactBands) -> float:
    """The height in inches of one file's band (title and rows)."""
    return BAND_TITLE + len(bands.joints) * BAND_ROW


def draw_bands(ax, bands: ContactBands, color: str, style, names: bool = True) -> None:
    """Draw ``bands`` on ``ax``: row ``k`` (top: the first joint) at ``y = n - 1 - k``, each contact interval
    one :class:`matplotlib.patches.Rectangle` of ``color`` (its ``gid`` the joint name), a faint line along
    each row; with ``names``, the joint names as y tick labels and the title above."""
    from matplotlib.patches import Rectangle

    n = len(bands.joints)
    for k, (name, spans) in enumerate(bands.intervals().items()):
        y = n - 1 - k
        ax.axhline(y, color=style.AXIS_GRID_COLOR, lw=0.8, zorder=1)
        for a, b in spans:
            ax.add_patch(Rectangle((a - 0.5, y - 0.36), b - a + 1, 0.72, facecolor=color, edgecolor="none",
                                   alpha=0.85, zorder=2, gid=name))
    ax.set_ylim(-0.6, n - 0.4)
    ax.set_yticks(range(n), list(reversed(bands.joints)))
    ax.tick_params(axis="y", length=0, labelsize=7, labelleft=names)
    for side in ("left", "right", "top"):
        ax.spines[side].set_visible(False)
    if names:
        ax.set_title(f"{bands.label}: foot contacts", loc="left", color=style.TEXT_COLOR, fontsize=8)
