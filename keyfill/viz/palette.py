"""A shared 256-colour (or smaller) palette for keyfill's pictures, with exact colour mapping.

GIFs need a palette, and PNGs of line drawings are about three times smaller
with one. keyfill's pictures hold a few flat colours (white, lines, keys,
ground, text) and their antialiased blends, so a palette of the flat colours
plus the most frequent others loses almost nothing.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from PIL import Image

#: colours in a GIF's shared palette
PALETTE_SIZE = 128


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
