"""Animated GIFs from rendered frames: one shared palette, exact timing, Pillow's encoder.

GIF delays are whole centiseconds, so a 30 fps motion cannot use one delay
for every frame. :func:`delays_ms` alternates delays so that frame ``k`` of the
GIF starts at ``round(100 k step / fps)`` centiseconds: the animation keeps the
motion's speed to within 10 ms at any point. Browsers treat delays under 2 cs
as 10 cs, so :func:`gif_step` thins the frames of motions faster than 50 fps.

All frames share one :class:`keyfill.viz.palette.Palette` built from a few
sample frames and are mapped to it exactly, without dithering; Pillow then
stores each frame as the rectangle that changed since the previous one.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
from PIL import Image

from keyfill.errors import UsageError

#: fastest frame rate that GIF viewers play correctly (delays of 2 cs)
MAX_GIF_FPS = 50.0
#: the longest delay a GIF frame can hold (a 16-bit count of centiseconds)
MAX_DELAY_CS = 65_535


def gif_step(fps: float, step: int = 1) -> int:
    """The frame step to use: ``step``, raised until ``fps / step`` is at most 50."""
    return max(int(step), math.ceil(fps / MAX_GIF_FPS - 1e-9))


def delays_ms(num_frames: int, fps: float, step: int = 1) -> list[int]:
    """Per-frame delays (multiples of 10 ms) for ``num_frames`` GIF frames that show
    every ``step``-th frame of a motion at ``fps``; the last frame holds one frame time.

    A :class:`UsageError` when one shown frame would last longer than a GIF delay can (655.35 s)."""
    if 100.0 * step / fps > MAX_DELAY_CS:
        raise UsageError(f"a GIF frame lasts at most {MAX_DELAY_CS / 100:g} s; one of {step} motion frame(s) at "
                         f"{fps:g} frames per second would last {step / fps:g} s (give a higher fps or a smaller "
                         "step)", params=("fps", "step"))
    times_cs = np.round(100.0 * step * np.arange(num_frames + 1) / fps).astype(np.int64)
    return [int(d) * 10 for d in np.maximum(np.diff(times_cs), 1)]


def write_gif(frames: Iterable[Image.Image], path: str | Path, delays: Sequence[int]) -> None:
    """Write palette ``frames`` (mode "P", one palette) as a looping GIF with ``delays`` in ms."""
    frames = list(frames)
    if len(delays) != len(frames):
        raise ValueError(f"{len(delays)} delays for {len(frames)} frames")
    frames[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=frames[1:],
        duration=list(delays),
        loop=0,
        disposal=1,
        optimize=True,
    )
