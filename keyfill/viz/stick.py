"""Stick figures of motions: animated GIF, filmstrip PNG, or a still with joint trails.

What is drawn and from where (world points and bones, the views' cameras,
the ground) is :mod:`keyfill.viz.scene`. Left limbs are drawn lighter than
the rest, so crossing legs stay readable in a side view.

The framing is fixed for the whole output, from the bounding box of every
frame (and the ground below it), so poses never jump. The ground is a grid,
or a line in the side and front views and for planar figures (the hopping
lamp). Keys (``Motion.keys``) are ghosted poses in pink: in animations and filmstrips the
keys just before and after the current frame, in a trail still all keys.
A trail ("motion curve", Ciccone et al. 2019) is a joint's world path with a
dot per frame, so spacing shows timing, and the keys circled.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from keyfill.errors import DataError, UsageError
from keyfill.limits import check_count, check_fps, max_frames
from keyfill.motion import Motion
from keyfill.viz import PREVIEW_SUFFIXES, check_suffix, frame_range
from keyfill.viz.scene import VIEWS, figure_points, ground_segments, is_planar, make_camera, travel_axis, up_index

#: default picture sizes in pixels: the long side of a GIF and a still, the height of a filmstrip frame
GIF_SIDE, STILL_SIDE, STRIP_HEIGHT = 480, 720, 300
#: the shortest side of a default-sized picture (a wide motion gets a wider picture, not a lower one)
MIN_SIDE = 300
#: a filmstrip or GIF follows the figures when framing every frame at once would draw them under this share of
#: the picture's height (:class:`StickRenderer`'s ``follow``)
FOLLOW_BELOW = 1 / 3
#: frames in a filmstrip without --step, and per filmstrip row
STRIP_FRAMES, STRIP_COLUMNS = 8, 8
#: most frames a GIF may have (Pillow holds them all in memory)
MAX_GIF_FRAMES = 5000


@dataclass(frozen=True)
class PreviewInfo:
    """What :func:`preview` wrote (for ``--json``)."""

    output: str
    kind: str  # "gif", "filmstrip" or "still"
    view: str
    frames: tuple[int, ...]  # frame numbers shown (file numbering)
    size: tuple[int, int]  # (width, height) pixels of the file written (a filmstrip: the whole sheet)
    fps: float | None  # GIF playback rate
    frame_size: tuple[int, int] | None = None  # (width, height) pixels of one frame (of a filmstrip: one cell)

    def as_dict(self) -> dict:
        # docs/json.md: frames a count, frames_drawn the frame numbers shown
        return {"output": self.output, "kind": self.kind, "view": self.view, "frames": len(self.frames),
                "frames_drawn": list(self.frames), "size": list(self.size),
                "frame_size": list(self.frame_size or self.size), "fps": self.fps}


class StickRenderer:
    """Draws the poses of one or more motions at chosen frames into RGB images.

    One Agg figure is built once. Its static layer (ground, trails, legend) is
    drawn once and cached; each frame restores it and draws only the poses,
    the ghosted keys, the trails' current points and the frame label.

    Args:
        motions: the motions, already cut to the frames to show; the first
            one's ``keys`` are the ones ghosted.
        labels: legend names (shown when there are several motions).
        view: one of :data:`VIEWS`.
        size: ``(width, height)`` pixels, or None to fit the motion.
        default_side: without ``size``: the long side in pixels, or (negative)
            minus the height.
        trail: joint names whose world paths to draw.
        first_frame: file frame number of frame 0 (for the labels).
        legend_keys: add a pink "keys" entry to the legend.
        follow: frame each picture around the figures of its frame (a camera that follows them sideways) when
            framing every frame at once would draw them under :data:`FOLLOW_BELOW` of the picture's height (a
            10 m walk in a 600 x 300 frame); the scale stays the same in every picture.
    """

    def __init__(self, motions: Sequence[Motion], labels: Sequence[str], view: str, size: tuple[int, int] | None,
                 default_side: int, trail: Sequence[str] = (), first_frame: int = 0, legend_keys: bool = False,
                 follow: bool = False):
        from keyfill.viz import style

        self.style = style
        self.first_frame = first_frame
        self.figs = [figure_points(m) for m in motions]
        first = self.figs[0]
        up_axis = motions[0].skeleton.up_axis
        h = travel_axis(first.points, first.used, up_axis)
        self.camera = make_camera(view, h, up_axis)
        drawn = np.concatenate([f.points[:, f.used].reshape(-1, 3) for f in self.figs])
        # The ground: a line where a grid would collapse to one (level views) or for
        # planar figures (the lamp), else a grid.
        u = np.zeros(3)
        u[up_index(up_axis)] = 1.0
        if abs(self.camera.up @ u) > 1 - 1e-9:
            along = self.camera.right
        elif all(is_planar(f.points, f.used) for f in self.figs):
            along = h
        else:
            along = None
        ground, level = ground_segments(drawn, up_axis, along)
        self.ground, self.ground_is_grid = ground, along is None
        # Framing: every drawn point of every frame, and its foot on the ground.
        feet = drawn.copy()
        feet[:, up_index(up_axis)] = level
        xy = self.camera.project(np.concatenate([drawn, feet]))
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        self.size, view_lo, view_hi = _frame(lo, hi, size, default_side)
        self.centers = None  # per frame, the x of the picture's centre when the camera follows
        if follow and (hi[1] - lo[1]) < FOLLOW_BELOW * (view_hi[1] - view_lo[1]):
            self.centers, width = self._follow()
            width = max(width, 0.8 * float(hi[1] - lo[1]))  # room for a stride, the frame label and the legend
            box_lo, box_hi = np.array([-width / 2, lo[1]]), np.array([width / 2, hi[1]])
            self.size, view_lo, view_hi = _frame(box_lo, box_hi, size, default_side)
        lo, hi = view_lo, view_hi
        self.half_width = (hi[0] - lo[0]) / 2
        self.keys = motions[0].keys.frames if motions[0].keys is not None else np.zeros(0, dtype=np.int64)
        trails = [(n, m.skeleton.index(name)) for n, m in enumerate(motions) for name in trail]
        legend = [(label, style.FILE_COLORS[n % len(style.FILE_COLORS)]) for n, label in enumerate(labels)]
        legend = legend if len(motions) > 1 else []
        if legend_keys and len(self.keys):
            legend.append(("keys", style.KEY_COLOR))
        with style.style():
            self._build(lo, hi, ground, trails, [m.keys for m in motions], legend)

    def _follow(self) -> tuple[np.ndarray, float]:
        """``(per-frame centre x (T,), the width of the figures' widest frame)``, on the screen's x axis."""
        T = max(len(f.points) for f in self.figs)
        boxes_lo, boxes_hi = np.full(T, np.inf), np.full(T, -np.inf)
        for f in self.figs:
            xy = self.camera.project(f.points[:, f.used].reshape(-1, 3)).reshape(len(f.points), -1, 2)[..., 0]
            n = len(f.points)
            boxes_lo[:n] = np.minimum(boxes_lo[:n], xy.min(axis=1))
            boxes_hi[:n] = np.maximum(boxes_hi[:n], xy.max(axis=1))
            if n < T:  # a shorter motion holds its last pose
                boxes_lo[n:] = np.minimum(boxes_lo[n:], xy[-1].min())
                boxes_hi[n:] = np.maximum(boxes_hi[n:], xy[-1].max())
        return (boxes_lo + boxes_hi) / 2, float((boxes_hi - boxes_lo).max())

    def _build(self, lo, hi, ground, trails, keys, legend):
        from matplotlib.collections import LineCollection
        from matplotlib.transforms import offset_copy

        st = self.style
        W, H = self.size
        s = math.sqrt(min(W, H) / 360.0)  # line and font scale
        lw = 2.4 * s
        fig = st.new_figure(W / 100, H / 100, dpi=100)
        ax = fig.add_axes((0, 0, 1, 1))
        ax.set_axis_off()
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        self.fig, self.ax = fig, ax
        ground_color = st.GRID_COLOR if self.ground_is_grid else st.GROUND_COLOR
        ax.add_collection(LineCollection(self.camera.project(ground), colors=ground_color,
                                         linewidths=max(0.8 * s, 0.75), zorder=0))
        self.ghost = ax.add_collection(LineCollection([], colors=st.KEY_COLOR, alpha=0.35, linewidths=0.85 * lw,
                                                      capstyle="round", joinstyle="round", zorder=3, animated=True))
        self.poses, self.colors = [], []
        for n, f in enumerate(self.figs):
            color = st.FILE_COLORS[n % len(st.FILE_COLORS)]
            if len(f.bones):
                colors = [st.lighten(color, 0.45) if side < 0 else color for side in f.sides]
                artist = ax.add_collection(LineCollection([], colors=colors, linewidths=lw, capstyle="round",
                                                          joinstyle="round", zorder=5, animated=True))
            else:  # no bones (a single joint): dots
                colors = color
                artist = ax.plot([], [], ls="none", marker="o", ms=1.5 * lw, color=color, zorder=5,
                                 animated=True)[0]
            self.poses.append(artist)
            self.colors.append(colors)
        self.trail_dots = []
        for n, j in trails:
            color = st.FILE_COLORS[n % len(st.FILE_COLORS)]
            path = self.camera.project(self.figs[n].points[:, j])
            ax.plot(path[:, 0], path[:, 1], color=color, lw=1.1 * s, alpha=0.8, zorder=2)
            ax.plot(path[:, 0], path[:, 1], ls="none", marker="o", ms=2.2 * s, color=color, zorder=2)
            if keys[n] is not None and len(keys[n]):
                ax.plot(path[keys[n].frames, 0], path[keys[n].frames, 1], ls="none", marker="o", ms=6.5 * s,
                        mfc="none", mec=st.KEY_COLOR, mew=1.4 * s, zorder=6)
            dot = ax.plot([], [], ls="none", marker="o", ms=4.5 * s, color=color, mec="white", mew=0.8 * s,
                          zorder=7, animated=True)[0]
            self.trail_dots.append((dot, path))
        font = 8 * s
        for i, (text, color) in enumerate(legend):
            where = offset_copy(ax.transAxes, fig=fig, x=0, y=-1.5 * font * i, units="points")
            ax.text(0.985, 0.975, text, transform=where, ha="right", va="top", color=color, fontsize=font)
        self.text = ax.text(0.015, 0.975, "", transform=ax.transAxes, ha="left", va="top", color=st.TEXT_COLOR,
                            fontsize=font, animated=True)
        fig.canvas.draw()
        self.background = fig.canvas.copy_from_bbox(fig.bbox)

    def _screen(self, n: int, t: int) -> np.ndarray:
        """Screen segments ``(B, 2, 2)`` of motion ``n``'s pose at frame ``t`` (or its points without bones)."""
        f = self.figs[n]
        xy = self.camera.project(f.points[min(t, len(f.points) - 1)])
        return xy[f.bones] if len(f.bones) else xy[f.used]

    def render(self, t: int | None, ghosts: Sequence[int] = (), label: str | None = None) -> np.ndarray:
        """The picture at frame ``t`` (None: no pose) as an ``(H, W, 4)`` uint8 RGBA array.

        ``ghosts``: frames whose poses of the first motion are drawn ghosted;
        ``label``: text for the top-left corner (pink at a key). The artists'
        fonts and styles were fixed when they were made, so no rc context is
        needed here.
        """
        st = self.style
        at_key = t is not None and t in self.keys
        canvas = self.fig.canvas
        if self.centers is not None and t is not None:  # the camera follows: the static layer moves with it
            c = float(self.centers[min(t, len(self.centers) - 1)])
            self.ax.set_xlim(c - self.half_width, c + self.half_width)
            canvas.draw()
        else:
            canvas.restore_region(self.background)
        if len(self.figs[0].bones):
            self.ghost.set_segments([seg for g in ghosts for seg in self._screen(0, int(g))])
            self.ax.draw_artist(self.ghost)
        if t is not None:
            for n, artist in enumerate(self.poses):
                xy = self._screen(n, t)
                if len(self.figs[n].bones):
                    artist.set_segments(xy)
                    artist.set_color(st.KEY_COLOR if n == 0 and at_key else self.colors[n])
                else:
                    artist.set_data(xy[:, 0], xy[:, 1])
                self.ax.draw_artist(artist)
            for dot, path in self.trail_dots:
                p = path[min(t, len(path) - 1)]
                dot.set_data([p[0]], [p[1]])
                self.ax.draw_artist(dot)
        if label:
            self.text.set_text(label)
            self.text.set_color(st.KEY_COLOR if at_key else st.TEXT_COLOR)
            self.ax.draw_artist(self.text)
        return np.array(canvas.buffer_rgba())

    def palette_colors(self) -> list[tuple[int, int, int]]:
        """The flat colours of the pictures (white, text, ground, files, keys, ghosts) as 0-255 RGB."""
        from matplotlib.colors import to_rgb

        st = self.style
        key = np.array(to_rgb(st.KEY_COLOR))
        flat = [(1.0, 1.0, 1.0), to_rgb(st.TEXT_COLOR), to_rgb(st.GROUND_COLOR), to_rgb(st.GRID_COLOR), tuple(key),
                tuple(0.35 * key + 0.65), to_rgb(st.FRAME_COLOR)]
        for colors in self.colors:
            flat += [to_rgb(c) for c in ([colors] if isinstance(colors, str) else colors)]
        return [tuple(round(255 * v) for v in c) for c in dict.fromkeys(flat)]

    def frame_label(self, t: int) -> str:
        """``"frame 12"`` in the file's numbering, ``"frame 12  key"`` at a key."""
        f = self.first_frame + t
        return f"frame {f}  key" if t in self.keys else f"frame {f}"

    def bracketing_keys(self, t: int) -> list[int]:
        """The last key before ``t`` and the first after it (those that exist)."""
        before = self.keys[self.keys < t]
        after = self.keys[self.keys > t]
        return [int(k) for k in (before[-1:].tolist() + after[:1].tolist())]


def _default_size(aspect: float, side: int) -> tuple[int, int]:
    """A size whose long side is ``side``, grown to no side under ``MIN_SIDE`` (or, for side < 0, whose height is
    -side) for ``aspect`` = w/h."""
    if side < 0:
        h = -side
        w = min(max(h * aspect, h * 0.5), h * 2.0)
    else:
        if aspect >= 1:
            w, h = side, side / min(aspect, 3.0)
        else:
            w, h = side * max(aspect, 1 / 3.0), side
        grow = max(1.0, MIN_SIDE / min(w, h))  # readable: a wide motion gets a wider picture, no side under MIN_SIDE
        w, h = w * grow, h * grow
    return round(w / 2) * 2, round(h / 2) * 2


def strip_frames(length: int, keys, count: int = STRIP_FRAMES) -> list[int]:
    """The frames of a filmstrip of ``length`` frames: ``count`` evenly spaced ones, or with ``keys`` the keys
    (``count`` of them evenly chosen when there are more), then the middle of the widest gap between shown
    frames (the first and last frame count as shown) until there are ``count``."""
    keys = sorted({int(k) for k in keys if 0 <= k < length})
    if not keys:
        return sorted(set(np.round(np.linspace(0, length - 1, min(count, length))).astype(int).tolist()))
    if len(keys) > count:
        keys = [keys[i] for i in np.round(np.linspace(0, len(keys) - 1, count)).astype(int)]
    shown = set(keys)
    while len(shown) < min(count, length):
        edges = sorted(shown | {0, length - 1})
        best = None  # (gap, frame to add)
        for a, b in itertools.pairwise(edges):
            pick = a if a not in shown else b if b not in shown else (a + b) // 2 if b - a >= 2 else None
            if pick is not None and (best is None or b - a > best[0]):
                best = (b - a, pick)
        if best is None:
            break
        shown.add(best[1])
    return sorted(shown)


def _frame(lo: np.ndarray, hi: np.ndarray, size: tuple[int, int] | None,
           default_side: int) -> tuple[tuple[int, int], np.ndarray, np.ndarray]:
    """``(size, view lo, view hi)`` of a picture showing the screen box ``lo``-``hi``: margins, room for the
    frame label, the size (``size``, or :func:`_default_size` of the box's aspect) and the box grown to it."""
    span = max(float((hi - lo).max()), 1e-9)
    lo, hi = lo - 0.06 * span, hi + 0.06 * span
    hi[1] += 0.08 * span  # room for the frame label
    size = size or _default_size((hi[0] - lo[0]) / (hi[1] - lo[1]), default_side)
    lo, hi = _fit(lo, hi, size[0] / size[1])
    return size, lo, hi


def _fit(lo: np.ndarray, hi: np.ndarray, aspect: float) -> tuple[np.ndarray, np.ndarray]:
    """Grow the box ``lo``-``hi`` about its centre to width / height = ``aspect`` (equal axis scales)."""
    c = (lo + hi) / 2
    w, h = hi - lo
    if w / h < aspect:
        w = h * aspect
    else:
        h = w / aspect
    return c - np.array([w, h]) / 2, c + np.array([w, h]) / 2


def preview(
    motions: Sequence[Motion],
    labels: Sequence[str],
    output: str | Path,
    *,
    view: str = "side",
    frames: str | None = None,
    step: int | None = None,
    trail: Sequence[str] = (),
    fps: float | None = None,
    size: tuple[int, int] | None = None,
    progress=None,
) -> PreviewInfo:
    """Render stick figures of ``motions`` (overlaid, each in its colour) to ``output``.

    * ``.gif``: an animation of every ``step``-th frame at ``fps`` (default:
      the first motion's rate);
    * ``.png`` without ``trail``: a filmstrip of evenly spaced frames (every
      ``step``-th, or 8 frames), ``size`` being the size of one frame;
    * ``.png`` with ``trail``: one still with the trails of those joints over
      all frames and the ghosted key poses (first and last frame when the
      first motion has no keys).

    ``frames`` is ``"A:B"`` (see :func:`keyfill.viz.frame_range`), ``size``
    ``(width, height)`` pixels. ``progress`` wraps the frame loop (e.g. a
    tqdm factory). The output is written atomically.
    """
    from PIL import Image

    from keyfill.files import atomic_output
    from keyfill.viz import gif
    from keyfill.viz.palette import Palette

    suffix = check_suffix(str(output), PREVIEW_SUFFIXES)
    if view not in VIEWS:
        raise UsageError(f"unknown view {view!r}; expected one of {', '.join(VIEWS)}")
    if step is not None:
        check_count("step", step, max_frames())
    if fps is not None and check_fps(fps):
        raise UsageError(f"fps: {check_fps(fps)}", params="fps")
    if size is not None and not all(16 <= v <= 8192 for v in size):
        raise UsageError(f"size {size[0]}x{size[1]}: each side must be 16 to 8192 pixels", params="size")
    if len(labels) != len(motions):
        raise UsageError(f"{len(labels)} labels for {len(motions)} files")
    first = motions[0].skeleton
    for m, label in zip(motions[1:], labels[1:]):
        if m.skeleton.up_axis != first.up_axis:
            raise DataError(f"{label}: its up axis is {m.skeleton.up_axis}, that of {labels[0]} is {first.up_axis}")
    cut = []
    shown_first = None
    for m, label in zip(motions, labels):
        idx = frame_range(frames, m.num_frames, label)
        shown_first = int(idx[0]) if shown_first is None else shown_first
        cut.append(m.frames(slice(int(idx[0]), int(idx[-1]) + 1)))
    for name in trail:
        for m in cut:
            m.skeleton.index(name)  # UsageError listing the joints
    length = max(m.num_frames for m in cut)
    if suffix == ".gif":
        kind = "gif"
        rate = fps or cut[0].fps
        stride = gif.gif_step(rate, step or 1)
        ts = list(range(0, length, stride))
        if len(ts) > MAX_GIF_FRAMES:
            raise UsageError(f"{len(ts)} GIF images is too many (at most {MAX_GIF_FRAMES}); use step or frames",
                             params=("step", "frames"))
        delays = gif.delays_ms(len(ts), rate, stride)  # before rendering: refuses what a GIF cannot time
    else:
        kind = "still" if trail else "filmstrip"
    side = {"gif": GIF_SIDE, "still": STILL_SIDE, "filmstrip": -STRIP_HEIGHT}[kind]
    r = StickRenderer(cut, labels, view, size, side, trail, first_frame=shown_first, legend_keys=kind == "still",
                      follow=kind != "still")
    wrap = progress or (lambda it, **kw: it)

    with atomic_output(output) as tmp:
        if kind == "gif":
            samples = sorted({ts[0], ts[len(ts) // 2], ts[-1]} | {int(k) for k in r.keys[:1]})
            palette = Palette([r.render(t, r.bracketing_keys(t), r.frame_label(t)) for t in samples],
                                  required=r.palette_colors())
            images = [palette.apply(r.render(t, r.bracketing_keys(t), r.frame_label(t)))
                      for t in wrap(ts, desc="frames", unit="frame")]
            gif.write_gif(images, tmp, delays)
            shown, out_fps = ts, rate / stride
        elif kind == "filmstrip":
            shown = list(range(0, length, step)) if step is not None else strip_frames(length, r.keys)
            cells = [Image.fromarray(r.render(t, r.bracketing_keys(t), r.frame_label(t))[..., :3])
                     for t in wrap(shown, desc="frames")]
            _montage(cells, STRIP_COLUMNS, r.palette_colors()).save(tmp, format="PNG", optimize=True)
            out_fps, frame_size = None, tuple(cells[0].size)
        else:
            ghosts = r.keys.tolist() if len(r.keys) else sorted({0, cut[0].num_frames - 1})
            last = shown_first + max(m.num_frames for m in cut) - 1
            image = r.render(None, ghosts, f"{', '.join(trail)} path, frames {shown_first}-{last}")
            Palette([image], 256, r.palette_colors()).apply(image).save(tmp, format="PNG", optimize=True)
            shown, out_fps = ghosts, None
        with Image.open(tmp) as written:  # the size reported is that of the file, read back from its header
            written_size = tuple(written.size)
    return PreviewInfo(str(output), kind, view, tuple(shown_first + int(t) for t in shown), written_size, out_fps,
                       frame_size=frame_size if kind == "filmstrip" else written_size)


def _montage(cells, columns: int, colors):
    """Cells (PIL images of one size) in rows of ``columns``, 4 px apart, each framed in light grey,
    as a palette image that keeps ``colors`` exact."""
    from PIL import Image, ImageDraw

    from keyfill.viz import style
    from keyfill.viz.palette import Palette

    w, h = cells[0].size
    gap = 4
    cols = min(columns, len(cells))
    rows = -(-len(cells) // cols)
    sheet = Image.new("RGB", (cols * w + (cols + 1) * gap, rows * h + (rows + 1) * gap), "white")
    draw = ImageDraw.Draw(sheet)
    for i, cell in enumerate(cells):
        x = gap + (i % cols) * (w + gap)
        y = gap + (i // cols) * (h + gap)
        sheet.paste(cell, (x, y))
        draw.rectangle((x - 1, y - 1, x + w, y + h), outline=style.FRAME_COLOR)
    return Palette([sheet], 256, colors).apply(sheet)
