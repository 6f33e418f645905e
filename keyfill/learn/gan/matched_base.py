"""The matched base (``GanConfig.base`` ``"match"``, issue 45): the generator corrects the in-between that
``--method match`` gives through the keys, not an interpolation.

A stretch of real motion already has steps, contacts and texture, which a generator trained on two CPU cores
could not invent from a spline (docs/gan.md). With this base the generator's output is added to the RC-FK
values of the matched motion's rotations (:func:`keyfill.learn.gan.spline_base.track_values`) and the root's
path is the matched one, so a generator whose residual is zero gives the match (inside the joint ranges), and
``--seed``, which picks among the library's good stretches (:func:`keyfill.learn.library.search.choose`),
gives another motion per seed.

**Completing** (:func:`matched_start`): the motion, on the model's skeleton, is filled by the library's
:class:`~keyfill.learn.library.matcher.Matcher` (``--library``, else the shipped library the model names,
``GanConfig.library``), with its default settings and the seed; :func:`keyfill.learn.gan.model.complete_motion`
then corrects it window by window.

**Training** reads a *matched set* of its clips (:mod:`keyfill.learn.gan.matched_set`); a window's base is
its row's match (:func:`matched_arrays`).

Shapes: ``T``/``L`` frames, ``J`` joints, ``D`` driven joints; rotations unit quaternions ``(w, x, y, z)``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from keyfill.errors import ModelError, UsageError
from keyfill.learn.gan.poses import turn
from keyfill.learn.gan.spline_base import track_values, turned_rotations

#: the most poses of a Motion DNA motion that pull the library search (evenly over it, unless frames are listed)
DNA_SEARCH_POSES = 64


def matched_arrays(ranges, num_frames: int, quats: np.ndarray, root: np.ndarray, heading: float,
                   shift: np.ndarray, up_axis: str) -> dict:
    """An in-clip window's ``base (6 + 3 D, num_frames)`` and ``spline_root (num_frames, 3)`` float32 from a matched
    in-between ``quats (L, J, 4)``, ``root (L, 3)`` (metres): turned by ``heading`` radians about the up axis and
    moved by ``-shift`` as the window's truth is, the last frame held after ``L``."""
    q = turned_rotations(quats, heading, up_axis)
    r = turn(np.asarray(root, dtype=np.float64), heading, up_axis) - shift
    pad = num_frames - len(q)
    q = np.concatenate([q, np.repeat(q[-1:], pad, 0)])
    r = np.concatenate([r, np.repeat(r[-1:], pad, 0)])
    return {"base": track_values(ranges, q), "spline_root": r.astype(np.float32)}


def library_path(model, options) -> Path:
    """The library a model on a matched base matches from: ``options.library``, else the shipped library its
    config names (``GanConfig.library``); a :class:`ModelError` when neither is there."""
    from keyfill.learn import installed_models

    if getattr(options, "library", None) is not None:
        return Path(options.library)
    name = model.config.library
    folder = installed_models.shipped(name) if name else None
    if folder is None:
        raise ModelError(f"this gan model corrects a match from the motion library {name or '(none named)'!r}, "
                         f"which is not installed; give library LIB, one of your own", params="library")
    return folder


def matched_start(model, motion, keys, seed: int, library: str | os.PathLike, dna_motion=None, dna_frames=None):
    """``motion`` (on the model's skeleton and frame rate) filled between ``keys`` by the library at ``library``
    (``--method match``'s search and placement, seed ``seed``, feet free): the base a generator on a matched base
    corrects. With a Motion DNA motion ``dna_motion`` (on the model's skeleton), its poses (``dna_frames``, else
    up to :data:`DNA_SEARCH_POSES` frames evenly over it) pull the search towards stretches near them and its own
    stretches join the candidates (:class:`~keyfill.learn.library.search.DnaPull`). Returns ``(motion, per-gap
    report)``; a :class:`ModelError` when the library serves another skeleton or frame rate."""
    from keyfill.learn.library.matcher import Matcher, load_matcher
    from keyfill.learn.library.search import DnaPull
    from keyfill.learn.library.store import on_library, served_by, with_clip
    from keyfill.learn.rig_bridge import fits

    matcher = load_matcher(library)
    lib = matcher.library
    served = served_by(lib.skeleton, lib.fps)
    if abs(lib.fps - motion.fps) > 1e-6 or not fits(served, motion, int(keys.frames[0])):
        raise ModelError(f"the motion library {Path(library).name} serves another skeleton or frame rate "
                         f"({lib.fps:g} fps) than this gan model")
    pull = None
    if dna_motion is not None:
        dna_motion = on_library(dna_motion, lib.skeleton, lib.fps, what="the DNA motion")
        n = dna_motion.num_frames
        frames = np.unique(np.linspace(0, n - 1, min(n, DNA_SEARCH_POSES)).round().astype(np.int64)) \
            if dna_frames is None else np.asarray(dna_frames, dtype=np.int64)
        matcher = Matcher(with_clip(lib, dna_motion, "the Motion DNA"))
        pull = DnaPull(np.asarray(matcher.library.features[lib.num_frames + frames], dtype=np.float64),
                       len(lib.clips))
    return matcher.fill(motion.replace(keys=None), keys, seed, dna=pull)


def completion_start(model, motion, keys, options, dna_motion=None, dna_frames=None) -> tuple[object, dict]:
    """``(start, info)`` of ``complete`` with ``options``: for a model on a matched base the matched in-between
    (:func:`matched_start` from :func:`library_path`, the seed ``options.seed``) and its report (``library``,
    ``matched_gaps``, ``gaps``); for another ``(None, {})``, and a :class:`UsageError` naming ``library`` when
    the options give one."""
    if model.config.base != "match":
        if options.library is not None:
            raise UsageError(f"library applies to a gan model on a matched base; this one corrects "
                             f"{'nothing' if model.config.base == 'none' else 'an interpolation'} "
                             f"(base {model.config.base!r})", params="library")
        return None, {}
    library = library_path(model, options)
    start, gaps = matched_start(model, motion, keys, options.seed, library, dna_motion, dna_frames)
    return start, {"library": library.name, "matched_gaps": sum(g["filled_by"] == "match" for g in gaps), "gaps": gaps}
