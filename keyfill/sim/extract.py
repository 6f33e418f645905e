"""From a simulated episode to a keyframed training sequence (paper section 5).

Each hop is resampled evenly in time to ``hop_frames`` (25) frames from its
liftoff to its landing, and each pause between a landing and the next
liftoff to ``pause_frames`` (6) frames strictly in between. With three hops
a sequence has ``3 * 25 + 2 * 6 = 87`` frames and starts at the first
liftoff::

    frame  0 .. 24   hop 1 (0 = liftoff, 24 = landing)
    frame 25 .. 30   pause
    frame 31 .. 55   hop 2
    frame 56 .. 61   pause
    frame 62 .. 86   hop 3

Keys: each hop's liftoff, its landing and one pose chosen at random among
the hop's in-air frames (1 .. 23 within the hop). Frames are spaced evenly
within each hop and pause, not in time: the motion's ``fps`` is nominal
(``Settings.fps``) and the true simulation time of every frame is kept in
:attr:`Extracted.frame_times`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.characters.lamp import from_variables
from keyfill.motion import Keys, Motion
from keyfill.sim.hops import Hops
from keyfill.sim.physics import Episode
from keyfill.sim.settings import Settings


@dataclass(frozen=True, eq=False)
class Extracted:
    """A keyframed hop sequence.

    Attributes:
        motion: the lamp :class:`Motion` with its keys.
        frame_times: ``(F,)`` simulation time of each frame, seconds.
        liftoff_frames, landing_frames, air_frames: ``(H,)`` frame indices of
            each hop's liftoff, landing and in-air key.
    """

    motion: Motion
    frame_times: np.ndarray
    liftoff_frames: np.ndarray
    landing_frames: np.ndarray
    air_frames: np.ndarray


def frame_times(hops: Hops, episode: Episode, settings: Settings) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Simulation times of the sequence's frames and the frame indices of liftoffs and landings."""
    t = episode.times
    n_hop, n_pause = settings.hop_frames, settings.pause_frames
    pieces, lift, land = [], [], []
    count = 0
    for i, (a, b) in enumerate(zip(hops.liftoffs, hops.landings)):
        if i > 0:
            gap = np.linspace(t[hops.landings[i - 1]], t[a], n_pause + 2)[1:-1]
            pieces.append(gap)
            count += n_pause
        pieces.append(np.linspace(t[a], t[b], n_hop))
        lift.append(count)
        land.append(count + n_hop - 1)
        count += n_hop
    return np.concatenate(pieces), np.array(lift, dtype=np.int64), np.array(land, dtype=np.int64)


def extract(episode: Episode, hops: Hops, rng: np.random.Generator, settings: Settings) -> Extracted:
    """The keyframed sequence of ``episode``'s hops; ``rng`` picks each hop's in-air key."""
    times, lift, land = frame_times(hops, episode, settings)
    # Linear interpolation of the densely sampled states (one sample per physics step); liftoff and
    # landing frames fall exactly on samples, so they are the simulated states themselves.
    values = np.stack([np.interp(times, episode.times, episode.states[:, c]) for c in range(6)], axis=1)
    air = lift + rng.integers(1, settings.hop_frames - 1, size=len(lift))
    keys = Keys(np.sort(np.concatenate([lift, air, land])))
    motion = from_variables(values, settings.fps, keys=keys, dims=settings.dimensions)
    return Extracted(motion=motion, frame_times=times, liftoff_frames=lift, landing_frames=land, air_frames=air)
