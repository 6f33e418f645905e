"""``--method match``: fill each gap with the stretch of real motion in a library that best joins its keys.

The method is a thin layer over :class:`keyfill.learn.library.matcher.Matcher`: its "model" is a motion
library folder (``keyfill library build``; ``--library``, default the shipped ``bandai2-library`` of the
model distribution models/bandai). Motions of other humanoid rigs and frame rates reach the library's
skeleton through the rig bridge, as the learned human methods do (:mod:`keyfill.learn.rig_bridge`).
``--seed 0`` takes the best stretch of every gap; other seeds draw among the good ones
(:func:`keyfill.learn.library.search.choose`). The keys come out exact. docs/match.md has the method and its
figures.
"""

from __future__ import annotations

import os
from pathlib import Path

from keyfill.learn import installed_models
from keyfill.learn.completion import Completion
from keyfill.motion import Keys, Motion

#: the library ``keyfill complete --method match`` uses without --library (CC BY-NC 4.0: models/bandai)
DEFAULT_MODEL = installed_models.shipped("bandai2-library")
#: ends the error for a motion the library cannot take
TRAIN_HINT = "; build a library of your own clips with 'keyfill library build CLIPS -o LIB'"


class MatchModel:
    """A loaded library as ``match``'s model: its :class:`~keyfill.learn.library.matcher.Matcher` and the hook
    of the LaFAN1 protocol (``keyfill evaluate match DATA``)."""

    def __init__(self, matcher):
        self.matcher = matcher
        self.library = matcher.library

    def benchmark_method(self):
        """This library as a method of :func:`keyfill.learn.protocols.lafan1.evaluate`
        (:func:`keyfill.learn.library.matcher.window_method`)."""
        from keyfill.learn.library.matcher import window_method

        return window_method(self.matcher)


def load(path: str | os.PathLike, device: str = "cpu") -> MatchModel:
    """The :class:`MatchModel` of the library folder ``path`` (``device`` is ignored: matching runs on the
    CPU), loaded once per process while its manifest is unchanged."""
    from keyfill.learn.library.matcher import load_matcher

    return MatchModel(load_matcher(path))


def model_path(options, keys=None) -> Path:
    """The library these options use: ``options.library``, else the shipped one (the error of a missing
    distribution otherwise)."""
    if options.library is not None:
        return Path(options.library)
    return installed_models.require(DEFAULT_MODEL, "match")


def served(options, keys=None):
    """What the library serves (:class:`keyfill.learn.rig_bridge.Served`): its skeleton and frame rate."""
    from keyfill.learn.library.store import served_by

    lib = load(model_path(options, keys)).library
    return served_by(lib.skeleton, lib.fps)


def complete(motion: Motion, keys: Keys, options) -> Completion:
    """Fill ``motion`` between ``keys`` from the library (on its skeleton and frame rate: the registry's rig
    bridge brings other motions there); keys exact."""
    from keyfill.learn.exact_keys import snap_to_keys

    path = model_path(options, keys)
    filled, gaps = load(path).matcher.fill(motion.replace(keys=None), keys, options.seed)
    info = {"model": path.name, "model_path": str(path.resolve()), "gaps": gaps,
            "matched_gaps": sum(g["filled_by"] == "match" for g in gaps)}
    if options.exact_keys:
        filled, report = snap_to_keys(filled, motion, keys)
        info.update(report)
    return Completion(filled.replace(keys=keys), info)
