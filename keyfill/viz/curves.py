"""Animation curves: one panel per animation variable, files overlaid, keys circled.

What a panel shows (Zhang & van de Panne 2018, Figures 5 and 8-13):

* a BVH channel, named ``JOINT.CHANNEL`` (``Hips.Zrotation``): rotation
  channels as Euler angles in degrees in the joint's own order (made
  continuous over time, as the BVH writer does), position channels in the
  file's units. Position channels that never leave the joint's rest OFFSET
  carry no animation and are left out;
* with ``positions=True``, world positions ``JOINT.x``, ``JOINT.y``, ``JOINT.z``
  from forward kinematics, in the file's units;
* for the hopping lamp (:mod:`keyfill.characters.lamp`), its six animation
  variables by their own names, angles in degrees.

The x axis is the frame number in the file (a ``--frames`` range keeps the
original numbering); keys (``Motion.keys``) are open circles on each file's curve.
With ``contacts=True`` each file's foot contacts are bands under the curves
(:mod:`keyfill.viz.contacts`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill.characters import lamp
from keyfill.errors import DataError, UsageError
from keyfill.motion import POSITION_CHANNELS, Motion
from keyfill.viz import PLOT_SUFFIXES, check_suffix, frame_range, unit_label

#: with more candidate panels than this and no --joints/--channels, only the
#: first moving joint is shown (a human has 60-130 channels)
MAX_DEFAULT_PANELS = 12
#: refuse figures with more panels than this (unreadable and slow)
MAX_PANELS = 64


@dataclass(frozen=True)
class Curves:
    """The animation variables of one motion.

    Attributes:
        names: ``P`` panel names (``"Hips.Zrotation"``, ``"Hips.x"``, or a lamp variable).
        units: ``P`` y-axis units (``"deg"``, ``"cm"``, ...).
        joints: per variable, the joint it belongs to (``None`` for lamp variables).
        kinds: per variable, the name without the joint (``"Zrotation"``, ``"x"``).
        values: ``(F, P)`` values over the frames.
        animated: ``(P,)`` bool; False for position channels that stay at the rest offset.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    joints: tuple[str | None, ...]
    kinds: tuple[str, ...]
    values: np.ndarray
    animated: np.ndarray


def channel_curves(motion: Motion) -> Curves:
    """Every BVH channel of ``motion`` over time, in the skeleton's channel order."""
    sk = motion.skeleton
    F = motion.num_frames
    orders = sk.euler_orders
    angles = motion.euler_angles()  # continuous curves, as the BVH writer writes them
    length = unit_label(sk.meters_per_unit)
    scale = max(1.0, float(np.abs(sk.offsets).max(initial=0.0)))
    names, units, joints, kinds, columns, animated = [], [], [], [], [], []
    for j, chans in enumerate(sk.channels):
        a = angles[:, j]
        for c in chans:
            axis = "XYZ".index(c[0])
            if c in POSITION_CHANNELS:
                v = motion.positions[:, j, axis]
                moving = bool(np.abs(v - sk.offsets[j, axis]).max(initial=0.0) > 1e-6 * scale)
                columns.append(v)
                units.append(length)
                animated.append(moving)
            else:
                columns.append(np.rad2deg(a[:, orders[j].index(c[0])]))
                units.append("deg")
                animated.append(True)
            names.append(f"{sk.names[j]}.{c}")
            joints.append(sk.names[j])
            kinds.append(c)
    values = np.stack(columns, axis=1) if columns else np.zeros((F, 0))
    return Curves(tuple(names), tuple(units), tuple(joints), tuple(kinds), values, np.array(animated, dtype=bool))


def position_curves(motion: Motion) -> Curves:
    """World positions ``JOINT.x/.y/.z`` of every joint, in the file's units."""
    sk = motion.skeleton
    world = motion.world_positions()
    length = unit_label(sk.meters_per_unit)
    names = tuple(f"{n}.{a}" for n in sk.names for a in "xyz")
    return Curves(
        names=names,
        units=(length,) * len(names),
        joints=tuple(n for n in sk.names for _ in "xyz"),
        kinds=tuple(a for _ in sk.names for a in "xyz"),
        values=world.reshape(motion.num_frames, -1),
        animated=np.ones(len(names), dtype=bool),
    )


def lamp_curves(motion: Motion) -> Curves | None:
    """The hopping lamp's six animation variables (angles in degrees), or None for other motions."""
    if not lamp.is_lamp(motion.skeleton):
        return None
    values = np.asarray(lamp.to_variables(motion), dtype=np.float64).reshape(motion.num_frames, -1)
    names = tuple(v.name for v in lamp.VARIABLES)
    units = tuple("deg" if v.unit == "rad" else v.unit for v in lamp.VARIABLES)
    if len(names) != values.shape[1]:
        raise DataError(f"the lamp encoder gives {values.shape[1]} values for {len(names)} variables")
    for p, v in enumerate(lamp.VARIABLES):
        if v.unit == "rad":
            values[:, p] = np.rad2deg(values[:, p])
    return Curves(
        names=names,
        units=units,
        joints=(None,) * len(names),
        kinds=names,
        values=values,
        animated=np.ones(len(names), dtype=bool),
    )


def curves_of(motion: Motion, positions: bool = False, lamp: bool = True) -> Curves:
    """The curves ``plot`` shows for ``motion``: lamp variables, channels or world positions."""
    if positions:
        return position_curves(motion)
    if lamp:
        c = lamp_curves(motion)
        if c is not None:
            return c
    return channel_curves(motion)


def _split_list(items: Sequence[str] | None) -> list[str]:
    """``["a,b", "c"]`` -> ``["a", "b", "c"]`` (options may repeat and hold commas)."""
    out: list[str] = []
    for item in items or ():
        out.extend(t.strip() for t in item.split(",") if t.strip())
    return out


def select_panels(curves: Curves, motion: Motion, joints=None, channels=None) -> list[int]:
    """Indices into ``curves`` of the panels to draw, in file order.

    ``joints``: joint names (UsageError listing the skeleton's joints for an
    unknown one). ``channels``: panel names or their last part (``Zrotation``,
    ``x``), case-insensitive (UsageError listing the valid ones). Without
    either, all variables, or only those of the first joint that rotates when
    there are more than :data:`MAX_DEFAULT_PANELS`.
    """
    joints, channels = _split_list(joints), _split_list(channels)
    cand = [i for i in range(len(curves.names)) if curves.animated[i]]
    if joints:
        for name in joints:
            motion.skeleton.index(name)  # UsageError that lists the joints
        cand = [i for i in cand if curves.joints[i] in joints]
        if not cand:
            raise UsageError(f"joint {', '.join(joints)} has no animated channels; try positions", params="positions")
    if channels:
        full = {curves.names[i].lower() for i in cand}
        kinds = {curves.kinds[i].lower() for i in cand}
        for item in channels:
            if item.lower() not in full | kinds:
                raise UsageError(f"unknown channel {item!r}; {_valid_channels(curves, cand)}")
        wanted = {c.lower() for c in channels}
        cand = [i for i in cand if curves.names[i].lower() in wanted or curves.kinds[i].lower() in wanted]
    elif not joints and len(cand) > MAX_DEFAULT_PANELS:
        first = _first_moving_joint(curves, cand)
        cand = [i for i in cand if curves.joints[i] == first]
    if not cand:
        raise DataError("nothing to plot: no channel of this motion is animated; try positions", params="positions")
    if len(cand) > MAX_PANELS:
        raise UsageError(f"{len(cand)} panels is too many for one figure (at most {MAX_PANELS}); "
                         "choose fewer with joints or channels", params=("joints", "channels"))
    return cand


def _valid_channels(curves: Curves, cand: list[int]) -> str:
    kinds = list(dict.fromkeys(curves.kinds[i] for i in cand))
    if len(cand) <= 30:
        return f"valid: {', '.join(curves.names[i] for i in cand)} (or one of {', '.join(kinds)} for every joint)"
    joints = list(dict.fromkeys(curves.joints[i] for i in cand))
    return f"valid: {', '.join(kinds)}, or JOINT.CHANNEL with a joint among {', '.join(joints)}"


def _first_moving_joint(curves: Curves, cand: list[int]) -> str:
    """The first joint (in file order) that rotates over time, else the first that moves at all.

    (Bandai's static ``joint_Root`` only slides; its child ``Hips`` is the pelvis.)
    """
    v = curves.values
    moving = [i for i in cand if len(v) and np.ptp(v[:, i]) > 1e-9]
    rotating = [i for i in moving if curves.units[i] == "deg"]
    return curves.joints[(rotating or moving or cand)[0]]


@dataclass(frozen=True)
class PlotInfo:
    """What :func:`plot` drew (for ``--json``)."""

    output: str
    panels: tuple[str, ...]
    labels: tuple[str, ...]
    frames: tuple[int, int]
    #: per file with ``contacts=True``: foot joint name -> contact intervals ``[first, last]`` (inclusive)
    contacts: tuple[dict[str, list[list[int]]], ...] = ()

    def as_dict(self) -> dict:
        first, last = self.frames  # docs/json.md: frames a count, frame_range the first and last (inclusive)
        # the legend names are ``labels`` (as --labels): ``files`` is a batch's per-file outcomes everywhere else
        d = {"output": self.output, "panels": list(self.panels), "labels": list(self.labels),
             "frames": last - first + 1, "frame_range": [first, last]}
        if self.contacts:
            d["contacts"] = [{"label": label, "joints": joints} for label, joints in zip(self.labels, self.contacts)]
        return d


def plot(
    motions: Sequence[Motion],
    labels: Sequence[str],
    output: str | Path,
    *,
    joints: Sequence[str] | None = None,
    channels: Sequence[str] | None = None,
    frames: str | None = None,
    positions: bool = False,
    contacts: bool = False,
    rig_map: dict | None = None,
    ground: float | None = None,
) -> PlotInfo:
    """Draw the animation curves of ``motions`` overlaid and write ``output`` (.png, .svg, .pdf).

    Panels come from the first motion (see :func:`select_panels`); every other
    motion must have the same variables. Lamps show their six variables
    unless ``joints`` or ``positions`` ask for channels or world positions.
    ``frames`` is ``"A:B"`` (see :func:`keyfill.viz.frame_range`).
    ``contacts``: a band of foot contacts per file under the curves
    (:func:`keyfill.viz.contacts.contact_bands`, with ``rig_map`` and
    ``ground``; a skeleton without legs is a :class:`DataError`). The file is
    written atomically.
    """
    from keyfill.files import atomic_output
    from keyfill.viz import style

    fmt = check_suffix(str(output), PLOT_SUFFIXES).lstrip(".")
    with style.style():
        fig, info = _draw(motions, labels, str(output), joints=joints, channels=channels, frames=frames,
                          positions=positions, contacts=contacts, rig_map=rig_map, ground=ground)
        with atomic_output(output) as tmp:
            style.save_figure(fig, tmp, fmt)
    return info


def figure(motions: Sequence[Motion], labels: Sequence[str], **options):
    """``(matplotlib Figure, PlotInfo)``: what :func:`plot` draws (same ``options``), without writing a file.
    Contact bands are the axes whose ``get_label()`` is ``"contacts: LABEL"``."""
    from keyfill.viz import style

    with style.style():
        return _draw(motions, labels, "", **options)


def _draw(motions, labels, output: str, *, joints=None, channels=None, frames=None, positions=False,
          contacts=False, rig_map=None, ground=None):
    from keyfill.viz import style

    if len(labels) != len(motions):
        raise UsageError(f"{len(labels)} labels for {len(motions)} files")
    use_lamp = (not joints and not positions
                and all(lamp.is_lamp(m.skeleton) for m in motions))
    series = []  # (label, frame numbers (F,), values (F, P), key indices into the frames)
    for n, (motion, label) in enumerate(zip(motions, labels)):
        idx = frame_range(frames, motion.num_frames, label)
        cut = motion.frames(slice(int(idx[0]), int(idx[-1]) + 1))
        curves = curves_of(cut, positions=positions, lamp=use_lamp)
        if n == 0:
            cols = select_panels(curves, cut, joints, channels)
            names = tuple(curves.names[i] for i in cols)
            panel_joints = [curves.joints[i] for i in cols]
            units = tuple(curves.units[i] for i in cols)
        else:
            lookup = {name: i for i, name in enumerate(curves.names)}
            missing = [name for name in names if name not in lookup]
            if missing:
                raise DataError(f"{label}: has no {missing[0]} (it is in {labels[0]}); plot files of one skeleton")
            cols = [lookup[name] for name in names]
        keys = cut.keys.frames if cut.keys is not None else np.zeros(0, dtype=np.int64)
        series.append((label, idx, curves.values[:, cols], keys))
    bands = []
    if contacts:
        from keyfill.viz.contacts import contact_bands

        bands = [contact_bands(m, label, s[1], rig_map=rig_map, ground=ground)
                 for m, label, s in zip(motions, labels, series)]

    P = len(names)
    cells = _layout(panel_joints)
    nrows = max(r for r, _ in cells) + 1
    ncols = max(c for _, c in cells) + 1
    fig, axes = _figure(style, nrows, ncols, bands)
    used = set(cells)
    for r in range(nrows):
        for c in range(ncols):
            if (r, c) not in used:
                axes[r, c].set_axis_off()
    for p in range(P):
        row, col = cells[p]
        ax = axes[row, col]
        for n, (_, x, values, keys) in enumerate(series):
            color = style.FILE_COLORS[n % len(style.FILE_COLORS)]
            ax.plot(x, values[:, p], color=color, lw=1.3, zorder=2 + n)
            if len(keys):
                ax.plot(x[keys], values[keys, p], ls="none", marker="o", ms=5.5, mew=1.3, mfc="none",
                        mec=color, zorder=10 + n)
        _flat_limits(ax, [values[:, p] for _, _, values, _ in series], units[p])
        ax.set_title(names[p], loc="left", color=style.TEXT_COLOR)
        ax.set_ylabel(units[p])
        ax.grid(True, color=style.AXIS_GRID_COLOR, lw=0.6)
        ax.margins(x=0.01, y=0.1)
        if (row + 1, col) not in used:
            ax.tick_params(labelbottom=True)
    if bands:
        _draw_bands(fig, axes, bands, style)
    fig.supxlabel("frame", fontsize=8, y=0.16 / fig.get_figheight())  # 0.16 in above the bottom
    handles = _legend_handles(series, style)
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, 1.0), ncols=min(len(handles), 6),
               frameon=False)
    first = [int(s[1][0]) for s in series]
    last = [int(s[1][-1]) for s in series]
    info = PlotInfo(output, names, tuple(labels), (min(first), max(last)), tuple(b.intervals() for b in bands))
    return fig, info


#: fixed figure layout in inches (a layout engine would cost half the drawing time)
_PANEL_HEIGHT, _ROW_GAP, _TOP, _BOTTOM = 1.05, 0.42, 0.5, 0.55
_PANEL_WIDTH = {1: 6.4, 2: 4.7, 3: 3.7, 4: 3.1}  # inches, by the number of columns (_layout: at most 4)
_LEFT, _RIGHT, _COLUMN_GAP = 0.75, 0.2, 0.85


#: with contact bands: the space between the curves' frame numbers and the first band, and between bands
_BANDS_GAP, _BAND_GAP = 0.3, 0.12


def _bands_height(bands) -> float:
    from keyfill.viz.contacts import band_height

    if not bands:
        return 0.0
    return _BANDS_GAP + sum(band_height(b) for b in bands) + (len(bands) - 1) * _BAND_GAP


def _figure(style, nrows: int, ncols: int, bands=()):
    """A figure with ``nrows`` x ``ncols`` panels sharing the x axis, laid out in fixed inches, with room for
    the contact ``bands`` below them."""
    width = _LEFT + ncols * _PANEL_WIDTH[ncols] + (ncols - 1) * _COLUMN_GAP + _RIGHT
    below = _BOTTOM + _bands_height(bands)
    height = _TOP + nrows * _PANEL_HEIGHT + (nrows - 1) * _ROW_GAP + below
    fig = style.new_figure(width, height)
    axes = fig.subplots(nrows, ncols, sharex=True, squeeze=False, gridspec_kw={
        "left": _LEFT / width, "right": 1 - _RIGHT / width,
        "top": 1 - _TOP / height, "bottom": below / height,
        "hspace": _ROW_GAP / _PANEL_HEIGHT, "wspace": _COLUMN_GAP / _PANEL_WIDTH[ncols],
    })
    return fig, axes


def _draw_bands(fig, axes, bands, style) -> None:
    """Each file's contact bands under the panels, under every column (so a frame lies under the same frame
    of the curves above it), the title and joint names in the first column, the frame numbers under the last
    file's. The first column's axes are labelled ``contacts: LABEL``, the others ``contacts: LABEL, column C``."""
    from keyfill.viz.contacts import BAND_ROW, BAND_TITLE, draw_bands

    height = fig.get_figheight()
    top = _BOTTOM + _bands_height(bands) - _BANDS_GAP  # inches above the bottom
    for n, b in enumerate(bands):
        rows = len(b.joints) * BAND_ROW
        top -= BAND_TITLE
        for c in range(axes.shape[1]):
            box = axes[0, c].get_position()
            name = f"contacts: {b.label}" if c == 0 else f"contacts: {b.label}, column {c + 1}"
            ax = fig.add_axes((box.x0, (top - rows) / height, box.width, rows / height), sharex=axes[0, c],
                              label=name)
            draw_bands(ax, b, style.FILE_COLORS[n % len(style.FILE_COLORS)], style, names=c == 0)
            ax.tick_params(axis="x", labelbottom=n == len(bands) - 1)
        top -= rows + _BAND_GAP


def _layout(joints: list[str | None]) -> list[tuple[int, int]]:
    """(row, column) of each panel: one column per joint for 2 to 4 joints of up to 8 panels
    (some with 2 or more), else panels down the columns (1 column up to 6 panels, 2 up to 16, else 3)."""
    groups = list(dict.fromkeys(joints))
    sizes = [joints.count(g) for g in groups]
    if 1 < len(groups) <= 4 and 2 <= max(sizes) <= 8 and None not in groups:
        seen = {g: 0 for g in groups}
        cells = []
        for g in joints:
            cells.append((seen[g], groups.index(g)))
            seen[g] += 1
        return cells
    P = len(joints)
    ncols = 1 if P <= 6 else 2 if P <= 16 else 3
    nrows = -(-P // ncols)
    return [(p % nrows, p // nrows) for p in range(P)]


def _flat_limits(ax, curves: list[np.ndarray], unit: str) -> None:
    """Give a panel whose curves are constant up to float noise (1e-4 degrees, or a relative
    1e-6) a y range of +-1 around them, instead of magnifying the noise."""
    v = np.concatenate(curves)
    tol = 1e-4 if unit == "deg" else 1e-6 * max(1.0, float(np.abs(v).max()))
    if np.ptp(v) <= tol:
        mid = float(np.round(v.mean(), 3))
        ax.set_ylim(mid - 1.0, mid + 1.0)


def _legend_handles(series, style) -> list:
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], color=style.FILE_COLORS[n % len(style.FILE_COLORS)], lw=1.6, label=label)
        for n, (label, *_rest) in enumerate(series)
    ]
    if any(len(s[3]) for s in series):
        handles.append(Line2D([], [], ls="none", marker="o", ms=5.5, mew=1.3, mfc="none", mec="#555555",
                              label="keys"))
    return handles
