"""Fill the gaps between keys with matched stretches of a motion library (the ``match`` method's work, and
the matched start that other methods may correct).

:class:`Matcher` holds a loaded library and its search tree. :meth:`Matcher.fill` takes a motion on the
library's skeleton and frame rate (the rig bridge brings others there) and its keys, and per gap:

* leaves a *standing* gap to the cubic spline: the hips travel less than :data:`STANDING_TRAVEL_M` and turn
  less than :data:`STANDING_TURN_RAD` between the keys and neither foot moves more than
  :data:`STANDING_FOOT_M` (gestures in place: the spline keeps planted feet planted, a stretch of another
  person's gesture adds sliding and error; measured in docs/match.md);
* otherwise searches the library (:mod:`keyfill.learn.library.search`), places and corrects the chosen
  stretch (:mod:`keyfill.learn.library.stitch`) and cross-fades it into its neighbours over up to
  :data:`SEAM_FRAMES` frames either side of each inner key;
* leaves a gap to cubic when no clip is long enough, or when even the chosen stretch's poses at the keys lie
  more than ``max_key_distance`` spreads from the keys (by default the guard's threshold: the keys are unlike
  anything the library holds).

Keys are exact. The report says, per gap, what filled it and from where.

**Root paths** (partial keys giving only the hips' positions, ``--key-joints HIPS --key-positions``): the
key poses are made first, gap by gap (:meth:`Matcher.path_poses`): the first gap's stretch is the one whose
hips travel as far as the keys' (:func:`~keyfill.learn.library.search.path_start`), turned to travel their
way; every next stretch starts near the pose the last one ended with and travels towards the next spot; the
pose a stretch ends with, moved onto the keyed spot, is the next key's pose. Those whole keys are then filled
as above, and the keyed positions come out exact.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from keyfill import interpolate
from keyfill import rotations as R
from keyfill.errors import DataError, UsageError
from keyfill.learn.library.features import chain_world, describe, hips_world, pose_world, yaw
from keyfill.learn.library.index import THRESHOLD, Tree
from keyfill.learn.library.search import Costs, DnaPull, Gap, candidates, choose, path_start
from keyfill.learn.library.stitch import join, place
from keyfill.motion import Keys, Motion

STANDING_TRAVEL_M = 0.2
STANDING_TURN_RAD = np.radians(20.0)
STANDING_FOOT_M = 0.1
#: frames either side of an inner key over which two stretches are blended
SEAM_FRAMES = 8


@dataclass(frozen=True)
class MatchSettings:
    """How :meth:`Matcher.fill` matches: the search's ``costs``, the ``seam`` frames either side of inner keys,
    whether standing gaps go to the spline (``standing``), and ``max_key_distance``: the largest RMS joint
    distance between a stretch's end poses and the keys, in the library's spreads, for a stretch to be used."""

    costs: Costs = field(default_factory=Costs)
    seam: int = SEAM_FRAMES
    standing: bool = True
    max_key_distance: float = THRESHOLD


class Matcher:
    """A library ready to be searched (its tree is built once, on first use)."""

    def __init__(self, library):
        self.library = library
        self._tree = None

    @property
    def tree(self) -> Tree:
        if self._tree is None:
            lib = self.library
            self._tree = Tree(lib.features, lib.mean, lib.basis)
        return self._tree

    def library_form(self, motion: Motion, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(rotations (K, J, 4), hips (K, 3))`` of ``motion``'s ``frames`` in the library's form."""
        fr = self.library.frames
        rot = np.array(motion.rotations[frames], dtype=np.float64)
        hq, hp = hips_world(rot, motion.positions[frames], motion.skeleton, fr)
        rot[:, fr.hips] = hq
        rot[:, list(fr.ancestors)] = (1.0, 0.0, 0.0, 0.0)
        return rot, hp

    def gaps(self, motion: Motion, keys: Keys) -> list[Gap]:
        """The :class:`~keyfill.learn.library.search.Gap` of every pair of neighbouring keys."""
        lib, fr = self.library, self.library.frames
        k = keys.frames
        rot, hp = self.library_form(motion, k)
        feats, ground, head = describe(pose_world(rot, hp, lib.skeleton, fr), fr)
        head = np.unwrap(head)
        vel = np.full(feats.shape, np.nan)
        given = {int(f) for f in k}
        for n, f in enumerate(k):
            nb = f - 1 if f - 1 in given else (f + 1 if f + 1 in given else None)
            if nb is not None:
                r2, h2 = self.library_form(motion, np.array([nb]))
                f2 = describe(pose_world(r2, h2, lib.skeleton, fr), fr)[0][0]
                vel[n] = (feats[n] - f2) * motion.fps if nb < f else (f2 - feats[n]) * motion.fps
        return [Gap(int(k[s]), int(k[s + 1]), feats[s:s + 2], ground[s:s + 2], head[s:s + 2], vel[s:s + 2])
                for s in range(len(k) - 1)]

    def standing(self, motion: Motion, gap: Gap) -> bool:
        """Whether ``gap`` is a gesture in place (the module docstring)."""
        fr = self.library.frames
        if np.linalg.norm(gap.ground[1] - gap.ground[0]) >= STANDING_TRAVEL_M:
            return False
        if abs(gap.heading[1] - gap.heading[0]) >= STANDING_TURN_RAD:
            return False
        world = motion.frames([gap.a, gap.b]).world_positions() * fr.meters_per_unit
        a, b = fr.ground_axes
        moved = np.linalg.norm(world[1][list(fr.feet)][:, [a, b]] - world[0][list(fr.feet)][:, [a, b]], axis=-1)
        return bool(moved.max() < STANDING_FOOT_M)

    def fill(self, motion: Motion, keys: Keys, seed: int = 0, settings: MatchSettings = MatchSettings(),
             dna: DnaPull | None = None) -> tuple[Motion, list[dict]]:
        """``(motion with every gap filled, per-gap report)``; ``motion`` is on the library's skeleton and
        frame rate, ``keys`` whole poses. Frames outside the keys hold the nearest key, as the splines do.
        ``dna``: a Motion DNA's pull on the search."""
        if keys.partial:
            motion, keys = self.path_poses(motion, keys, seed, settings), Keys(keys.frames)
        lib = self.library
        J = lib.skeleton.num_joints
        spline = interpolate.cubic(motion, keys)
        gaps = self.gaps(motion, keys)
        report: list[dict] = []
        todo = []
        for n, gap in enumerate(gaps):
            entry = {"keys": [gap.a, gap.b], "filled_by": "cubic"}
            if gap.b - gap.a < 2:
                entry["why"] = "no frame between the keys"
            elif settings.standing and self.standing(motion, gap):
                entry["why"] = "standing"
            else:
                todo.append(n)
            report.append(entry)
        found = candidates(lib, self.tree, [gaps[n] for n in todo], settings.costs, dna)
        chosen: dict[int, tuple[int, int, float]] = {}
        for n, (i, L, cost) in zip(todo, found):
            if not len(i):
                report[n]["why"] = "no library clip is long enough"
                continue
            c = choose(i, L, cost, lib.clip_of, seed, n, settings.costs)
            ii, LL = int(i[c]), int(L[c])
            ends = np.asarray(lib.features[[ii, ii + LL]], dtype=np.float64)
            key_rms = np.sqrt(((ends - gaps[n].features) ** 2).sum(-1) / J) / lib.spread
            if key_rms.max() > settings.max_key_distance:
                report[n]["why"] = (f"no stretch comes within {settings.max_key_distance:g} spreads of the keys "
                                    f"(the nearest: {key_rms.max():.1f})")
                continue
            chosen[n] = (ii, LL, float(cost[c]))
            clip = lib.clips[int(lib.clip_of[ii])]
            report[n].update(filled_by="match", source={"clip": clip.name, "frames": [ii - clip.start,
                                                                                      ii + LL - clip.start]},
                             warp=round(LL / (gaps[n].b - gaps[n].a), 4), cost=float(cost[c]),
                             key_distance=[float(x) for x in key_rms])
        rot, hips = self.library_form(spline, np.arange(motion.num_frames))
        key_rot, key_hips = self.library_form(motion, keys.frames)
        g = {n: gaps[n].b - gaps[n].a for n in chosen}
        seams = {n: min(settings.seam, g[n] // 2, g[n + 1] // 2) for n in chosen if n + 1 in chosen}
        pieces = {}
        for n, (i, L, _) in chosen.items():
            gap = gaps[n]
            before, after = seams.get(n - 1, 0), seams.get(n, 0)
            pr, ph = place(lib, i, L, (key_rot[n], key_hips[n]), (key_rot[n + 1], key_hips[n + 1]), g[n],
                           before, after)
            pieces[n] = (before, pr, ph)
            rot[gap.a: gap.b + 1] = pr[before: before + g[n] + 1]
            hips[gap.a: gap.b + 1] = ph[before: before + g[n] + 1]
        for n, h in seams.items():  # blend across the key between gaps n and n + 1
            if h == 0:
                continue
            b, (lb, left_r, left_h), (_, right_r, right_h) = gaps[n].b, pieces[n], pieces[n + 1]
            rows = slice(lb + g[n] - h, lb + g[n] + h + 1)
            jr, jh = join((left_r[rows], left_h[rows]), (right_r[: 2 * h + 1], right_h[: 2 * h + 1]))
            rot[b - h: b + h + 1] = jr
            hips[b - h: b + h + 1] = jh
        return self.to_motion(spline, rot, hips).replace(keys=keys), report

    def path_poses(self, motion: Motion, keys: Keys, seed: int, settings: MatchSettings) -> Motion:
        """``motion`` with a whole pose at every key of a root path (the module docstring); a
        :class:`~keyfill.errors.UsageError` for partial keys of another kind."""
        lib, fr = self.library, self.library.frames
        if keys.given != "position" or not keys.joint_mask(motion.num_joints)[:, fr.hips].all():
            raise UsageError(f"match takes whole poses, or a root path: the hips' positions at every key "
                             f"(key_joints {motion.skeleton.names[fr.hips]}, key_positions)",
                             params=("key_joints", "key_positions"))
        k = keys.frames
        _, hips_k = hips_world(motion.rotations[k], motion.positions[k], motion.skeleton, fr)
        a, b = fr.ground_axes
        spots = hips_k[:, [a, b]] * fr.meters_per_unit  # (K, 2) the path's spots on the ground, meters
        poses = []  # library-form (rotations (J, 4), hips (3,)) at each key
        i, L = path_start(lib, float(np.linalg.norm(spots[1] - spots[0])), int(k[1] - k[0]), seed, settings.costs)
        if i < 0:
            raise DataError(f"no clip of the library {lib.name} is long enough for the first gap of the path")
        src = np.asarray(lib.ground[[i, i + L]], dtype=np.float64)
        turn = (np.arctan2(*(spots[1] - spots[0])[::-1]) - np.arctan2(*(src[1] - src[0])[::-1]))
        poses.append(self._moved(i, turn, src[0], spots[0]))
        for n in range(len(k) - 1):
            rot, hp = poses[-1]
            feats, ground, head = describe(pose_world(rot[None], hp[None], lib.skeleton, fr), fr)
            gap = Gap(int(k[n]), int(k[n + 1]), np.repeat(feats, 2, axis=0), np.stack([ground[0], spots[n + 1]]),
                      np.repeat(head, 2), np.full((2, feats.shape[1]), np.nan), end_pose=False)
            i_s, L_s, cost = candidates(lib, self.tree, [gap], settings.costs)[0]
            if not len(i_s):
                raise DataError(f"no clip of the library {lib.name} is long enough for the path's gap "
                                f"{gap.a}-{gap.b}")
            c = choose(i_s, L_s, cost, lib.clip_of, seed, n, settings.costs)
            i, L = int(i_s[c]), int(L_s[c])
            turn = head[0] - float(lib.heading[i])
            poses.append(self._moved(i + L, turn, np.asarray(lib.ground[i], np.float64), ground[0],
                                     spot=spots[n + 1]))
        rot = np.array(motion.rotations, dtype=np.float64)
        pos = np.array(motion.positions, dtype=np.float64)
        local = self.to_motion(motion.frames(k), np.stack([p[0] for p in poses]), np.stack([p[1] for p in poses]))
        rot[k], pos[k] = local.rotations, local.positions
        return motion.replace(rotations=rot, positions=pos, keys=None)

    def _moved(self, frame: int, turn: float, origin: np.ndarray, target: np.ndarray,
               spot: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The library-form pose of ``frame`` turned by ``turn`` (radians about up) and moved so that the
        ground point ``origin`` (m) lands on ``target`` (m); then its hips' ground point put on ``spot``."""
        lib, fr = self.library, self.library.frames
        a, b = fr.ground_axes
        rot = np.asarray(lib.rotations[frame], dtype=np.float64).copy()
        q = yaw(np.float64(turn), fr)
        rot[fr.hips] = R.quat_mul(q, rot[fr.hips])
        shift = np.zeros(3)
        shift[[a, b]] = origin / fr.meters_per_unit
        hips = R.quat_rotate(q, np.asarray(lib.hips[frame], np.float64) - shift)
        hips[[a, b]] += target / fr.meters_per_unit
        if spot is not None:
            hips[[a, b]] = spot / fr.meters_per_unit
        return rot, hips

    def to_motion(self, spline: Motion, rot: np.ndarray, hips: np.ndarray) -> Motion:
        """Library-form poses back to ``spline``'s local channels: the hips' world transform under the joints
        above the hips as ``spline`` has them; every translation but the hips' from ``spline``."""
        fr = self.library.frames
        out_rot = rot.copy()
        out_pos = np.array(spline.positions, dtype=np.float64)
        anc = list(fr.ancestors)
        out_rot[:, anc] = spline.rotations[:, anc]
        if anc:
            wq, wp = chain_world(spline.rotations, spline.positions, anc)
            inv = R.quat_conjugate(wq)
            out_rot[:, fr.hips] = R.quat_mul(inv, rot[:, fr.hips])
            out_pos[:, fr.hips] = R.quat_rotate(inv, hips - wp)
        else:
            out_pos[:, fr.hips] = hips
        return spline.replace(rotations=R.quat_continuous_np(R.quat_normalize(out_rot), axis=0), positions=out_pos)


def load_matcher(path: str | os.PathLike) -> Matcher:
    """The :class:`Matcher` of the library folder ``path``, loaded once per process while its manifest is
    unchanged (``--method match``'s model, and the matched start of a gan on a matched base)."""
    from keyfill.learn.library.store import MANIFEST

    manifest = Path(path) / MANIFEST
    return _load_matcher(str(Path(path).resolve()), manifest.stat().st_mtime_ns if manifest.is_file() else 0.0)


@functools.lru_cache(maxsize=4)
def _load_matcher(path: str, stamp: float) -> Matcher:
    from keyfill.learn.library.store import load

    return Matcher(load(path))


def window_method(matcher: Matcher):
    """``method(skeleton, quats (B, T, J, 4), root (B, T, 3), keys) -> (quats, root)``: the LaFAN1 protocol's windows
    (:func:`keyfill.learn.protocols.lafan1.evaluate`) each filled as one motion on the library's skeleton. A library
    whose hips sit below one static top joint (Bandai's ``joint_Root``) takes windows whose top joint carries the
    hips' world transform (the protocol folds the clips, as the human models' corpora do); one whose hips are the
    root takes them as they are. ``method.folded`` says which."""
    from keyfill.learn.corpus import bone_difference
    from keyfill.learn.library.store import served_by

    lib = matcher.library
    served = served_by(lib.skeleton, lib.fps)
    hips, top = lib.frames.hips, 0
    identity = np.array([1.0, 0.0, 0.0, 0.0])

    def method(skeleton, quats, root, keys):
        from keyfill.errors import ModelError

        diff = bone_difference(served.skeleton, skeleton)
        if diff is not None or lib.frames.ancestors not in ((), (top,)):
            raise ModelError(f"the library serves another skeleton: {diff or 'joints above its hips'}")
        q_out, r_out = np.array(quats), np.array(root)
        for w in range(len(quats)):  # unknown frames are NaN: only the keys are read
            rot = np.where(np.isnan(quats[w]), identity, quats[w])
            rot[:, hips] = rot[:, top]  # the top joint carries the hips' world transform
            pos = np.broadcast_to(lib.skeleton.offsets, rot.shape[:-1] + (3,)).copy()
            if served.folded:
                rot[:, top] = identity
                pos[:, top] = 0.0
            pos[:, hips] = np.nan_to_num(root[w])
            filled, _ = matcher.fill(Motion(lib.skeleton, lib.fps, rot, pos), Keys(np.asarray(keys)))
            q_out[w] = filled.rotations
            q_out[w][:, top] = filled.rotations[:, hips]
            if served.folded:
                q_out[w][:, hips] = identity
            r_out[w] = filled.positions[:, hips]
        return q_out, r_out

    method.folded = served.folded
    return method
