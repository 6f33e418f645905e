"""Animated GIFs from rendered frames: one shared palette, exact timing, Pillow's encoder.

GIF delays are whole centiseconds, so a 30 fps motion cannot use one delay
for every frame. :func:`delays_ms` alternates delays so that frame ``k`` of the
GIF starts at ``round(100 k step / fps)`` centiseconds: the animation keeps the
motion's speed to within 10 ms at any point. Browsers treat delays under 2 cs
as 10 cs, so :func:`gif_step` thins the frames of motions faster than 50 fps.

All frames share one :class:`Palette` built from a few sample frames (the
pictures hold a handful of flat colours and their antialiased blends with
white) and are mapped to it exactly, without dithering; Pillow then stores
each frame as the rectangle that changed since the previous one.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
from PIL import Image

#: fastest frame rate that GIF viewers play correctly (delays of 2 cs)
MAX_GIF_FPS = 50.0
#: colours in the shared palette
PALETTE_SIZE = 128


def gif_step(fps: float, step: int = 1) -> int:
    """The frame step to use: ``step``, raised until ``fps / step`` is at most 50."""
    return max(int(step), math.ceil(fps / MAX_GIF_FPS - 1e-9))


def delays_ms(num_frames: int, fps: float, step: int = 1) -> list[int]:
    """Per-frame delays (multiples of 10 ms) for ``num_frames`` GIF frames that show
    every ``step``-th frame of a motion at ``fps``; the last frame holds one frame time."""
    times_cs = np.round(100.0 * step * np.arange(num_frames + 1) / fps).astype(np.int64)
    return [int(d) * 10 for d in np.maximum(np.diff(times_cs), 1)]


class Palette:
    """A shared palette of the ``colors`` most frequent exact colours of some sample images
    (after the ``required`` ones), and an exact nearest-colour mapping of images onto it.

    Pictures of lines on white consist of a few flat colours and their
    antialiased blends; keeping the most frequent colours exactly (white, the
    line colours, the common blend levels) keeps flat areas exact, where a
    median cut would average white with its neighbours. Pillow's own mapping
    onto a given palette works on a coarse colour cache and is not exact, so
    the mapping is done here: a lookup table over all 2**24 colours, filled
    for each colour the first time it is seen.

    Images are ``(H, W, 4)`` RGBA or ``(H, W, 3)`` RGB uint8 arrays, or PIL images.
    """

    def __init__(self, samples: Sequence, colors: int = PALETTE_SIZE, required: Sequence[tuple[int, int, int]] = ()):
        packed = np.concatenate([_packed(im).reshape(-1) for im in samples])
        values, counts = np.unique(packed, return_counts=True)
        by_count = values[np.argsort(-counts, kind="stable")]
        must = list(dict.fromkeys(r | (g << 8) | (b << 16) for r, g, b in required))
        taken = set(must)
        top = must + [int(v) for v in by_count if int(v) not in taken][: max(colors - len(must), 0)]
        self.rgb = _unpacked(np.array(top, dtype=np.int64))  # (N, 3) uint8
        self._flat = self.rgb.reshape(-1).tolist()
        self._lut = np.full(1 << 24, -1, dtype=np.int16)

    def apply(self, image) -> Image.Image:
        """``image`` as a "P" image on this palette, each pixel its nearest colour."""
        packed = _packed(image)
        index = self._lut[packed]
        missing = index < 0
        if missing.any():
            new = np.unique(packed[missing])
            diff = _unpacked(new)[:, None, :].astype(np.int32) - self.rgb[None].astype(np.int32)
            self._lut[new] = np.argmin((diff * diff).sum(axis=-1), axis=1)
            index = self._lut[packed]
        out = Image.fromarray(index.astype(np.uint8))  # mode "L"; putpalette makes it "P"
        out.putpalette(self._flat)
        return out


def _packed(image) -> np.ndarray:
    """``(H, W)`` int colours ``r | g << 8 | b << 16`` (an RGBA array is read as 32-bit words)."""
    a = np.asarray(image)
    if isinstance(image, Image.Image) and image.mode not in ("RGB", "RGBA"):
        a = np.asarray(image.convert("RGB"))
    if a.shape[-1] == 4 and a.flags.c_contiguous:
        return (a.view("<u4")[..., 0] & 0xFFFFFF).astype(np.intp)
    a = a.astype(np.intp)
    return a[..., 0] | (a[..., 1] << 8) | (a[..., 2] << 16)


def _unpacked(packed: np.ndarray) -> np.ndarray:
    return np.stack([packed & 255, (packed >> 8) & 255, (packed >> 16) & 255], axis=-1).astype(np.uint8)


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
