"""Simulated annealing over hop controllers (Zhang & van de Panne 2018, Algorithm 1).

One *run* searches for one hop style::

    w_e ~ U[0, 1]                                  (a new energy weighting per run)
    s   = INIT()                                   (the reference controller, perturbed)
    for K in 0 .. K_max - 1:
        s' = NEIGHBOUR(s)                          (one duration +-7 ms; one angle per pose +-0.5 rad)
        dE = E(s') - E(s)                          (E = -(1 - w_e) D - w_e H_max over 3 cycles)
        if RANDOM() < ACCEPT(T, dE): s = s'        (1 if dE < 0, else exp(-dE / T))
        T = 2 * 0.999307^K                         (COOLING)

Every candidate costs one episode (one energy evaluation). A run keeps the
best *satisfactory* episode it met (see :func:`keyfill.sim.hops.satisfactory`);
a run that met none is rejected. A lamp that fell gets ``E = inf``: the
search never moves onto it (``exp(-inf) = 0``) but moves off it at once.

Randomness: a run's generator is seeded from ``(seed, run)`` only, so a run
gives the same result in any process, in any order, on any worker.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from keyfill.sim.controller import REFERENCE, Controller
from keyfill.sim.hops import Hops, analyse, energy, satisfactory
from keyfill.sim.physics import Episode, LampWorld
from keyfill.sim.settings import Settings


def run_generator(seed: int, run: int, stream: int = 0) -> np.random.Generator:
    """The random generator of run ``run`` of a dataset with ``seed`` (``stream`` separates uses)."""
    return np.random.default_rng(np.random.SeedSequence(entropy=seed, spawn_key=(run, stream)))


def temperature(k: int, settings: Settings) -> float:
    """Cooling schedule ``T(K) = 2 * 0.999307^K``."""
    return settings.initial_temperature * settings.cooling**k


def accept_probability(delta: float, t: float) -> float:
    """Equation (2): 1 for a strictly better candidate, else ``exp(-dE / T)`` (0 for ``dE = inf``)."""
    if delta < 0:
        return 1.0
    if math.isnan(delta):  # inf - inf: both fell; stay
        return 0.0
    return math.exp(-delta / t)


@dataclass(frozen=True, eq=False)
class RunResult:
    """The outcome of one annealing run.

    Attributes:
        run: run index; seed: the dataset seed; w_e: the run's energy weight.
        episodes: energy evaluations made (``iterations + 1``).
        accepted: a satisfactory episode was found.
        reason: why the run was rejected (``None`` when accepted).
        controller, episode, hops, energy: the best satisfactory episode
            (``None`` when rejected).
    """

    run: int
    seed: int
    w_e: float
    iterations: int
    episodes: int
    accepted: bool
    reason: str | None
    controller: Controller | None = None
    episode: Episode | None = None
    hops: Hops | None = None
    energy: float | None = None


def anneal(
    seed: int,
    run: int,
    iterations: int,
    settings: Settings,
    world: LampWorld | None = None,
    initial: Controller = REFERENCE,
) -> RunResult:
    """Annealing run ``run`` of a dataset with ``seed``: ``iterations`` steps of Algorithm 1.

    ``world`` reuses an open :class:`LampWorld` with the same settings (the
    result does not depend on what it simulated before); by default the run
    opens its own.
    """
    if world is None:
        with LampWorld(settings) as own:
            return anneal(seed, run, iterations, settings, own, initial)
    rng = run_generator(seed, run)
    w_e = float(rng.uniform(0.0, 1.0))
    best: tuple[float, Controller, Episode, Hops] | None = None
    last_reason = "no episode"

    def evaluate(c: Controller) -> float:
        nonlocal best, last_reason
        ep = world.simulate(c)
        hops = analyse(ep, settings)
        e = energy(hops, w_e)
        why = satisfactory(hops, settings)
        if why is None and (best is None or e < best[0]):
            best = (e, c, ep, hops)
        elif why is not None:
            last_reason = why
        return e

    s = initial.perturbed(rng, settings)
    e_s = evaluate(s)
    t = temperature(0, settings)
    for k in range(iterations):
        cand = s.neighbour(rng, settings)
        e_c = evaluate(cand)
        if rng.random() < accept_probability(e_c - e_s, t):
            s, e_s = cand, e_c
        t = temperature(k + 1, settings)
    common = {"run": run, "seed": seed, "w_e": w_e, "iterations": iterations, "episodes": iterations + 1}
    if best is None:
        return RunResult(**common, accepted=False, reason=f"no satisfactory episode (last: {last_reason})")
    e, c, ep, hops = best
    return RunResult(**common, accepted=True, reason=None, controller=c, episode=ep, hops=hops, energy=e)
