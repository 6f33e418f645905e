"""Corpus clips as what the GAN's networks see: root paths and root-relative joint positions (numpy).

* ``relative (T, J, 3)``: joint positions relative to the root in world axes
  (forward kinematics of the local rotations with the root at the origin and
  the constant bone offsets); row 0 is zero. The paper's ``T^joints``.
* ``root (T, 3)``: the root's world position.

Both in metres (file units times ``meters_per_unit``). Turning a clip about
the up axis (:func:`turn`) turns both, which is how training draws headings.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, field

import numpy as np

from keyfill.kinematics import fk
from keyfill.learn.windows import horizontal_axes


def relative_positions(quats: np.ndarray, offsets: np.ndarray, parents) -> np.ndarray:
    """``(..., J, 3)`` root-relative world-axis joint positions of local ``quats (..., J, 4)``."""
    off = np.array(offsets, dtype=np.float64)
    off[0] = 0.0
    return fk(quats, np.broadcast_to(off, quats.shape[:-1] + (3,)), parents)[1]


def turn(points: np.ndarray, angle, up_axis: str = "Y") -> np.ndarray:
    """``points (..., 3)`` rotated by ``angle`` radians about the up axis (broadcast over leading dims).

    For ``up_axis`` Y a positive angle takes +Z towards +X (a right-handed turn about +Y).
    """
    a, b = horizontal_axes(up_axis)
    if up_axis == "Y":
        a, b = b, a  # about +Y: (z, x) rotates like (x, y) about +Z
    c, s = np.cos(angle), np.sin(angle)
    out = np.array(points, dtype=np.float64, copy=True)
    pa, pb = points[..., a], points[..., b]
    out[..., a] = c * pa - s * pb
    out[..., b] = s * pa + c * pb
    return out


@dataclass(frozen=True, eq=False)
class ClipPool:
    """The clips of a corpus ready for sampling (everything in metres).

    Attributes:
        relative: per clip ``(T_c, J, 3)`` float32 root-relative positions.
        root: per clip ``(T_c, 3)`` float64 root positions.
        fps: frames per second.
        up_axis: ``"Y"`` or ``"Z"``.
        contacts: per clip ``(T_c, n)`` bool foot contact labels (:mod:`keyfill.learn.gan.labels`), or
            empty when not needed.
        foot_joints: ``(n,)`` the joints of the contact columns.
        groups: ``(C,)`` content group per clip (draws balanced by content), or None (every clip alike).
        quats: per clip ``(T_c, J, 4)`` float32 local rotations (for a spline base,
            :mod:`keyfill.learn.gan.spline_base`), or empty when not needed.
        parents: ``(J,)`` the skeleton's parent indices (-1 at the root; for stretched sketch keys,
            ``GanConfig.sketch_stretch``), or None.
        matched: per clip its rows of a matched set (a base ``"match"``,
            :func:`keyfill.learn.gan.matched_set.load_rows`), or empty when not needed.
    """

    relative: tuple[np.ndarray, ...]
    root: tuple[np.ndarray, ...]
    fps: float
    up_axis: str
    contacts: tuple[np.ndarray, ...] = ()
    foot_joints: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    groups: np.ndarray | None = None
    quats: tuple[np.ndarray, ...] = ()
    parents: np.ndarray | None = None
    matched: tuple = ()

    def __len__(self) -> int:
        return len(self.root)

    @functools.cached_property
    def lengths(self) -> np.ndarray:
        """``(C,)`` frames per clip (computed once: the sampling asks for it several times a window)."""
        out = np.array([len(r) for r in self.root], dtype=np.int64)
        out.setflags(write=False)
        return out

    def draw(self, rng: np.random.Generator, usable: np.ndarray | None = None) -> int:
        """A random clip (of ``usable`` indices, default all): with ``groups``, a random content first, then
        a random clip of it, so every content is drawn as often; else uniformly."""
        usable = np.arange(len(self)) if usable is None else np.asarray(usable)
        if self.groups is None:
            return int(rng.choice(usable))
        g = self.groups[usable]
        content = rng.choice(np.unique(g))
        return int(rng.choice(usable[g == content]))


def clip_pool(corpus, clips=None, labels: bool = False, rotations: bool = False, matched: tuple = ()) -> ClipPool:
    """The :class:`ClipPool` of the clips ``clips`` (indices; all when None) of a :class:`~keyfill.learn.corpus.Corpus`;
    ``labels``: with foot contacts and content groups (:mod:`keyfill.learn.gan.labels`); ``rotations``: with
    the local rotations; ``matched``: the clips' rows of a matched set
    (:func:`keyfill.learn.gan.matched_set.load_rows`)."""
    s = corpus.skeleton
    m = s.meters_per_unit
    clips = list(range(len(corpus))) if clips is None else [int(i) for i in clips]
    if not clips:
        return ClipPool((), (), float(corpus.fps), s.up_axis)
    # one forward kinematics pass over all frames of the chosen clips (per clip costs a numpy call per joint each)
    frames = np.concatenate([np.arange(corpus.starts[i], corpus.starts[i + 1]) for i in clips])
    rel_all = relative_positions(corpus.quats[frames], s.offsets * m, s.parents).astype(np.float32)
    bounds = np.concatenate([[0], np.cumsum([corpus.starts[i + 1] - corpus.starts[i] for i in clips])])
    rel = tuple(rel_all[a:b] for a, b in itertools.pairwise(bounds))
    root = tuple(np.asarray(corpus.root[corpus.starts[i] : corpus.starts[i + 1]], dtype=np.float64) * m for i in clips)
    quats = tuple(np.asarray(corpus.quats[corpus.starts[i] : corpus.starts[i + 1]], dtype=np.float32)
                  for i in clips) if rotations else ()
    if not labels:
        return ClipPool(rel, root, float(corpus.fps), s.up_axis, quats=quats, parents=s.parents, matched=matched)
    from keyfill.learn.gan.labels import clip_contacts, content_groups

    contacts, joints = clip_contacts(corpus, clips)
    return ClipPool(rel, root, float(corpus.fps), s.up_axis, contacts, joints, content_groups(corpus, clips), quats,
                    s.parents, matched)
