"""What a simulated episode did: ground contact, hops, falls, distance, height, energy.

Ground contact is read from the geometry of the recorded states: the base
touches the ground when its lowest corner is within ``contact_tolerance`` of
it (Bullet keeps resting contacts about 0.1 mm deep). A *hop* is a stretch
without base contact that lasts at least ``min_air_time``; shorter ones
(a bounce on landing, an edge that skips) belong to the ground phase around
them. The *liftoff* is the last sample in contact before a hop and the
*landing* the first sample in contact after it.

The lamp has *fallen* when the base tilts past ``max_tilt`` or any corner of
the leg, neck or head reaches the ground.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.characters.lamp import Dimensions
from keyfill.sim.physics import Episode
from keyfill.sim.settings import Settings


def _corners(length: float, width: float) -> np.ndarray:
    """``(4, 2)`` corners of a link box in its own frame (length along +Y from the hinge)."""
    return np.array([[-width / 2, 0.0], [width / 2, 0.0], [-width / 2, length], [width / 2, length]])


def link_clearances(states: np.ndarray, dims: Dimensions) -> np.ndarray:
    """Height of the lowest corner of each link above the ground, ``(N, 4)`` (base, leg, neck, head), m.

    ``states`` are ``(N, 6)`` animation variables (see :mod:`keyfill.characters.lamp`).
    """
    base = np.array([[-0.5, 0.0], [0.5, 0.0], [-0.5, 1.0], [0.5, 1.0]]) * [dims.base_length, dims.base_height]
    links = [
        (base, 0.0),
        (_corners(dims.leg_length, dims.leg_width), dims.base_height),
        (_corners(dims.neck_length, dims.neck_width), dims.leg_length),
        (_corners(dims.head_length, dims.head_width), dims.neck_length),
    ]
    out = np.empty((states.shape[0], 4))
    hinge_y = states[:, 1]
    angle = np.zeros(states.shape[0])
    for j, (corners, offset) in enumerate(links):
        # Link j hangs from a hinge ``offset`` up the previous link's +Y axis and turns by its own angle.
        hinge_y = hinge_y + offset * np.cos(angle)
        angle = angle + states[:, 2 + j]
        c, s = np.cos(angle), np.sin(angle)
        out[:, j] = (hinge_y[:, None] + corners[:, 0] * s[:, None] + corners[:, 1] * c[:, None]).min(axis=1)
    return out


@dataclass(frozen=True, eq=False)
class Hops:
    """The outcome of an episode.

    Attributes:
        liftoffs, landings: ``(H,)`` sample indices of each hop's liftoff and landing.
        contact: ``(N,)`` bool, the base touches the ground.
        distance: forward (+X) travel of the base from start to end, m.
        max_height: highest clearance of the base above the ground, m.
        fell: the lamp fell over (or the episode stopped early).
        final_tilt: |base angle| at the end, rad.
    """

    liftoffs: np.ndarray
    landings: np.ndarray
    contact: np.ndarray
    distance: float
    max_height: float
    fell: bool
    final_tilt: float

    @property
    def count(self) -> int:
        return len(self.liftoffs)


def analyse(episode: Episode, settings: Settings) -> Hops:
    """Find the hops of ``episode`` and measure it."""
    states = episode.states
    clear = link_clearances(states, settings.dimensions)
    contact = clear[:, 0] <= settings.contact_tolerance
    fell = episode.fell or bool(np.any(clear[:, 1:] <= 0.0))
    # Airborne stretches: [start, end) sample ranges without base contact, ended by a landing.
    edges = np.diff(np.concatenate([[0], (~contact).astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    min_samples = settings.min_air_time / settings.time_step
    keep = [(a, b) for a, b in zip(starts, ends) if a > 0 and b < len(contact) and (b - a) >= min_samples - 1e-9]
    liftoffs = np.array([a - 1 for a, _ in keep], dtype=np.int64)
    landings = np.array([b for _, b in keep], dtype=np.int64)
    return Hops(
        liftoffs=liftoffs,
        landings=landings,
        contact=contact,
        distance=float(states[-1, 0] - states[0, 0]),
        max_height=float(clear[:, 0].max()),
        fell=fell,
        final_tilt=float(abs(states[-1, 2])),
    )


def energy(hops: Hops, w_e: float) -> float:
    """Equation (1): ``E = -(1 - w_e) D - w_e H_max`` (lower is better); ``inf`` for a lamp that fell."""
    if hops.fell:
        return float("inf")
    return -(1.0 - w_e) * hops.distance - w_e * hops.max_height


def satisfactory(hops: Hops, settings: Settings) -> str | None:
    """``None`` when the episode is a keeper, else why not (one short phrase).

    A keeper has exactly ``cycles`` hops (one per cycle of the graph), travels
    at least ``min_distance``, rises at least ``min_height``, never falls and
    ends standing on its base.
    """
    if hops.fell:
        return "fell over"
    if hops.count != settings.cycles:
        return f"{hops.count} hops instead of {settings.cycles}"
    if not hops.contact[-1]:
        return "still in the air at the end"
    if hops.final_tilt > settings.max_final_tilt:
        return "ends tilted"
    if hops.distance < settings.min_distance:
        return "too short"
    if hops.max_height < settings.min_height:
        return "too low"
    return None
