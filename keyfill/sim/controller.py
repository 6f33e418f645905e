"""The hop controller: a cyclic pose control graph of four timed states.

After van de Panne, Kim and Fiume (1994) and Zhang & van de Panne (2018,
Figure 4): state ``i`` holds target angles ``poses[i]`` (leg, neck, head) for
``durations[i]`` seconds, then the graph moves to state ``i + 1``, and from
state 4 back to state 1. Each joint's PD controller pulls it towards the
current target. One cycle of the graph is meant to make one hop; the
annealing search (:mod:`keyfill.sim.search`) tunes the 4 durations and the
4 x 3 target angles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from keyfill.sim.settings import Settings

NUM_STATES = 4


@dataclass(frozen=True, eq=False)
class Controller:
    """Parameters of the pose control graph.

    Attributes:
        durations: ``(4,)`` seconds spent in each state.
        poses: ``(4, 3)`` target angles (leg, neck, head) of each state, radians.
    """

    durations: np.ndarray
    poses: np.ndarray

    def __post_init__(self):
        d = np.array(self.durations, dtype=np.float64).reshape(NUM_STATES)
        p = np.array(self.poses, dtype=np.float64).reshape(NUM_STATES, 3)
        d.setflags(write=False)
        p.setflags(write=False)
        object.__setattr__(self, "durations", d)
        object.__setattr__(self, "poses", p)

    @property
    def cycle_time(self) -> float:
        """Seconds of one cycle of the graph."""
        return float(self.durations.sum())

    def start_pose(self) -> np.ndarray:
        """``(3,)`` joint angles the lamp rests in before the first cycle: the last state's target."""
        return self.poses[-1]

    def clipped(self, settings: Settings) -> Controller:
        """Durations within ``[min_duration, max_duration]``, targets within the joint limits."""
        return Controller(
            np.clip(self.durations, settings.min_duration, settings.max_duration),
            np.clip(self.poses, settings.lower_limits, settings.upper_limits),
        )

    def neighbour(self, rng: np.random.Generator, settings: Settings) -> Controller:
        """A candidate near this one (paper section 4.4.2).

        One of the four durations moves by ``duration_step`` (7 ms) and, in
        each of the four target poses, one joint angle moves by
        ``angle_step`` (0.5 rad); directions and choices are random.
        """
        d = self.durations.copy()
        p = self.poses.copy()
        i = rng.integers(NUM_STATES)
        d[i] += settings.duration_step * rng.choice((-1.0, 1.0))
        joints = rng.integers(3, size=NUM_STATES)
        signs = rng.choice((-1.0, 1.0), size=NUM_STATES)
        p[np.arange(NUM_STATES), joints] += settings.angle_step * signs
        return Controller(d, p).clipped(settings)

    def perturbed(self, rng: np.random.Generator, settings: Settings) -> Controller:
        """This controller with small Gaussian noise on every parameter (a run's initial guess)."""
        d = self.durations + rng.normal(0.0, settings.init_duration_noise, NUM_STATES)
        p = self.poses + rng.normal(0.0, settings.init_angle_noise, (NUM_STATES, 3))
        return Controller(d, p).clipped(settings)

    def to_dict(self) -> dict:
        return {"durations": self.durations.tolist(), "poses": self.poses.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> Controller:
        return cls(np.array(d["durations"]), np.array(d["poses"]))


#: The search's starting point: a controller that makes three small forward hops and whose
#: neighbours mostly do not fall (72 % of 40 random neighbours stayed up). It was found by a
#: random search over statically stable target poses (see docs/simulate.md).
REFERENCE = Controller(
    durations=np.array([0.089, 0.061, 0.082, 0.222]),
    poses=np.array(
        [
            [-0.18, -0.49, 1.26],  # crouch: lean back, head up
            [0.07, 0.04, 0.97],  # push off: straighten leg and neck
            [0.36, -1.18, 0.67],  # in the air: fold the neck forward
            [-0.05, -0.46, -1.69],  # land and rest: head tipped down
        ]
    ),
)
