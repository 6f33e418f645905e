"""The library search: for each gap between two keys, the stretches of real motion that best join them.

A *stretch* is ``(i, L)``: library frames ``i .. i + L`` of one clip, played over a gap of ``g`` frames
(``L / g`` is its time warp, one of :attr:`Costs.warps`). Its cost, with ``A`` and ``B`` the keys, ``F`` the
pose features, ``T`` the ground travel from the first frame to the last in the first frame's heading, ``H``
the heading (all in meters and radians; :mod:`keyfill.learn.library.features`)::

    cost = (|F[i] - F(A)|^2 + |F[i+L] - F(B)|^2) / J                     poses at both keys (mean square, m^2)
         + travel * |T(i, i+L) - T(A, B)|^2                              where the body goes (m^2)
         + turn * wrap(H[i+L] - H[i] - (H(B) - H(A)))^2                  how it turns (rad^2)
         + warp * log(L / g)^2                                           how far the stretch is retimed
         + roughness * mean(roughness[i .. i+L])^2                       the source's own jitter ((m/s^3)^2)
         + velocity * (|V[i] - V(A)|^2 + |V[i+L] - V(B)|^2) / J          only where the frame next to a key is
                                                                        given too (m^2/s^2, per joint)
         + dna * mean_s min_p |F[i + s L / 4] - P_p|^2 / J               only with a Motion DNA: its poses P,
                                                                        s = 0..4 (m^2; :func:`dna_distance`)

Candidates are found with the library's tree (:class:`keyfill.learn.library.index.Tree`): the
:attr:`Costs.neighbours` poses nearest to key ``A`` start a stretch, those nearest to ``B`` end one; every
warp is tried on each; the full cost above ranks them. Seed 0 takes the cheapest; another seed draws among
the good ones (a cost within :attr:`Costs.margin` of the best, one per source clip) with weights
``exp(-(cost - best) / temperature)``, so two seeds differ and quality holds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Costs:
    """Weights and search settings (see the module docstring for the cost)."""

    travel: float = 1.0
    turn: float = 1.0
    warp: float = 0.02
    roughness: float = 1e-7
    velocity: float = 0.01
    warps: tuple[float, ...] = (0.75, 0.85, 0.95, 1.0, 1.05, 1.15, 1.3)
    neighbours: int = 256
    #: the good candidates another seed draws from: cost at most best * (1 + margin) + margin_abs
    margin: float = 3.0
    margin_abs: float = 0.002
    temperature: float = 0.01
    #: weight of a Motion DNA's pull (the search's ``dna`` poses; without them the term is left out)
    dna: float = 30.0


@dataclass(frozen=True)
class Gap:
    """What the search knows of one gap: the key frames ``a < b`` and the key descriptions at both ends
    (``features (2, D)``, ``ground (2, 2)``, ``heading (2,)``) and, where the frame next to a key is given,
    the feature velocities ``velocity (2, D)`` (m/s; NaN where unknown). Without ``end_pose`` only the ground
    point of ``B`` is known (a root path): its pose and turn terms are left out."""

    a: int
    b: int
    features: np.ndarray
    ground: np.ndarray
    heading: np.ndarray
    velocity: np.ndarray
    end_pose: bool = True


@dataclass(frozen=True, eq=False)
class DnaPull:
    """A Motion DNA for the search: the features ``poses (P, D)`` of its poses, which pull the search towards
    stretches near them (:func:`dna_distance`, weighted by :attr:`Costs.dna`), and the library ``clip`` that
    holds the DNA's own motion (every other frame of it then starts candidates too, so its stretches compete
    where the library has nothing like it), or None."""

    poses: np.ndarray
    clip: int | None = None


def _wrap(x: np.ndarray) -> np.ndarray:
    return (x + np.pi) % (2 * np.pi) - np.pi


def candidates(lib, tree, gaps: list[Gap], costs: Costs = Costs(),
               dna: DnaPull | None = None) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """For each gap, ``(starts i (C,), lengths L (C,), costs (C,))`` of its candidate stretches, cheapest first
    (empty arrays when no clip of the library is long enough for the gap); ``dna``: a Motion DNA's pull."""
    from keyfill.learn.library.features import to_ground

    J = lib.features.shape[1] // 3
    if not gaps:
        return []
    queries = np.concatenate([g.features for g in gaps])  # (2G, D): A0, B0, A1, B1, ...
    near = tree.query(queries, costs.neighbours).reshape(len(gaps), 2, -1)
    starts = lib.starts()
    clip_start = starts[lib.clip_of]
    clip_stop = starts[lib.clip_of + 1]
    out = []
    for n, gap in enumerate(gaps):
        g = gap.b - gap.a
        Ls = np.unique(np.maximum(1, np.rint(g * np.asarray(costs.warps)).astype(np.int64)))
        fa = near[n, 0]
        fb = near[n, 1] if gap.end_pose else near[n, 1][:0]  # a root path's B has no pose to be near
        i = np.concatenate([np.repeat(fa, len(Ls)), np.repeat(fb, len(Ls)) - np.tile(Ls, len(fb))])
        L = np.concatenate([np.tile(Ls, len(fa)), np.tile(Ls, len(fb))])
        if dna is not None and dna.clip is not None:  # the DNA's own stretches
            own = np.arange(starts[dna.clip], starts[dna.clip + 1], 2)
            i = np.concatenate([i, np.repeat(own, len(Ls))])
            L = np.concatenate([L, np.tile(Ls, len(own))])
        ok = (i >= 0) & (i < lib.num_frames)
        i, L = i[ok], L[ok]
        ok = (i >= clip_start[i]) & (i + L < clip_stop[i])
        i, L = i[ok], L[ok]
        if len(i):
            pair = np.unique(np.stack([i, L], axis=1), axis=0)
            i, L = pair[:, 0], pair[:, 1]
        if not len(i):
            out.append((i, L, np.zeros(0)))
            continue
        j = i + L
        F_i = np.asarray(lib.features[i], dtype=np.float64)
        F_j = np.asarray(lib.features[j], dtype=np.float64)
        H_i, H_j = np.asarray(lib.heading[i], np.float64), np.asarray(lib.heading[j], np.float64)
        cost = ((F_i - gap.features[0]) ** 2).sum(-1) / J
        if gap.end_pose:
            cost += ((F_j - gap.features[1]) ** 2).sum(-1) / J
            cost += costs.turn * _wrap((H_j - H_i) - (gap.heading[1] - gap.heading[0])) ** 2
        travel = to_ground(np.asarray(lib.ground[j], np.float64) - np.asarray(lib.ground[i], np.float64), H_i)
        want = to_ground(gap.ground[1] - gap.ground[0], gap.heading[0])
        cost += costs.travel * ((travel - want) ** 2).sum(-1)
        cost += costs.warp * np.log(L / g) ** 2
        rough = _range_means(lib, i, j)
        cost += costs.roughness * rough**2
        for end, frame in ((0, i), (1, j)):
            v = gap.velocity[end] if end == 0 or gap.end_pose else np.nan
            if np.isfinite(v).all():
                lo = np.maximum(frame - 1, clip_start[frame])
                hi = np.minimum(frame + 1, clip_stop[frame] - 1)
                dv = (np.asarray(lib.features[hi], np.float64) - np.asarray(lib.features[lo], np.float64))
                dv *= (lib.fps * (L / g) / np.maximum(hi - lo, 1))[:, None]
                cost += costs.velocity * ((dv - v) ** 2).sum(-1) / J
        if dna is not None:
            cost += costs.dna * dna_distance(lib, i, L, dna.poses)
        order = np.argsort(cost, kind="stable")
        out.append((i[order], L[order], cost[order]))
    return out


def dna_distance(lib, i: np.ndarray, L: np.ndarray, dna: np.ndarray) -> np.ndarray:
    """``(C,)`` m^2: how far each stretch ``(i, L)`` is from the Motion DNA poses ``dna (P, D)`` (features): at five
    frames evenly along it, the mean square joint distance to the nearest DNA pose, averaged."""
    J = lib.features.shape[1] // 3
    d = np.asarray(dna, dtype=np.float64)
    dd = np.square(d).sum(1)
    out = np.zeros(len(i))
    for s in range(5):
        F = np.asarray(lib.features[i + (L * s) // 4], dtype=np.float64)
        d2 = np.square(F).sum(1)[:, None] - 2 * F @ d.T + dd[None]
        out += np.maximum(d2.min(1), 0.0) / J
    return out / 5


def _range_means(lib, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Mean of ``lib.roughness`` over frames ``i .. j`` (inclusive) of each pair (through a cumulative sum,
    computed once per library)."""
    cum = lib.__dict__.get("_roughness_cumsum")
    if cum is None:
        cum = np.concatenate([[0.0], np.cumsum(np.asarray(lib.roughness, dtype=np.float64))])
        object.__setattr__(lib, "_roughness_cumsum", cum)
    return (cum[j + 1] - cum[i]) / (j - i + 1)


def choose(i: np.ndarray, L: np.ndarray, cost: np.ndarray, clip_of: np.ndarray, seed: int, gap_index: int,
           costs: Costs = Costs()) -> int:
    """The candidate (an index into the sorted arrays) a seed takes: 0 (the cheapest) for seed 0; otherwise a
    draw among the good candidates, one per source clip, weighted by ``exp(-(cost - best) / temperature)``."""
    if seed == 0 or len(cost) == 1:
        return 0
    best = cost[0]
    good = np.flatnonzero(cost <= best * (1 + costs.margin) + costs.margin_abs)
    _, first = np.unique(clip_of[i[good]], return_index=True)
    pool = good[np.sort(first)]
    w = np.exp(-(cost[pool] - best) / costs.temperature)
    rng = np.random.default_rng([seed, gap_index])
    return int(pool[rng.choice(len(pool), p=w / w.sum())])


def path_start(lib, length_m: float, g: int, seed: int, costs: Costs = Costs(), stride: int = 2) -> tuple[int, int]:
    """The stretch ``(i, L)`` that starts a root path: no pose is known, only how far the hips travel over the
    first gap of ``g`` frames (``length_m``); every ``stride``-th library frame is tried with every warp, by
    ``travel * (|T| - length)^2 + warp + roughness`` (seed 0: the cheapest; others: :func:`choose`)."""
    starts = lib.starts()
    i0 = np.arange(0, lib.num_frames, stride)
    Ls = np.unique(np.maximum(1, np.rint(g * np.asarray(costs.warps)).astype(np.int64)))
    i = np.repeat(i0, len(Ls))
    L = np.tile(Ls, len(i0))
    ok = i + L < starts[lib.clip_of[i] + 1]
    i, L = i[ok], L[ok]
    if not len(i):
        return -1, -1
    ground = np.asarray(lib.ground, dtype=np.float64)
    travel = np.linalg.norm(ground[i + L] - ground[i], axis=-1)
    cost = costs.travel * (travel - length_m) ** 2 + costs.warp * np.log(L / g) ** 2
    cost += costs.roughness * _range_means(lib, i, i + L) ** 2
    order = np.argsort(cost, kind="stable")
    c = choose(i[order], L[order], cost[order], lib.clip_of, seed, 0, costs)
    return int(i[order][c]), int(L[order][c])
