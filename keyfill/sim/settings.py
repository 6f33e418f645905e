"""Every number that shapes a simulated hop, in one frozen record.

:class:`Settings` is written into each dataset folder (``simulate.json``) and
into every manifest record, so a dataset says exactly how it was made, and a
folder built with other settings is recognised as a different configuration.
Units: meters, kilograms, seconds, radians, newton-meters.

Why these values (measured by ``benchmarks/bench_simulate.py``; see
``docs/simulate.md``):

* ``time_step`` 1/480 s, ``solver_iterations`` 10: against a 1/1920 s,
  100-iteration reference the median error is 1.5 cm of hop distance and
  1.4 mm of height (1/240 s: 2.8 cm and 4.0 mm); 5 to 50 solver iterations
  make no measurable difference for one box on a plane. The explicit PD
  controller is stable with a wide margin (``omega * dt`` below about 0.15 for
  the stiffest joint, estimated from the link inertias; stability needs < 2).
* PD gains and torque limits: enough to throw the 1.49 kg lamp 0.05-0.25 m
  high, not so much that most changes of a target flip it over.
* ``max_tilt`` ends an episode once the base has turned past it: such a lamp
  cannot land on its base any more, and stopping there cuts a fallen
  episode from about 900 to 370 steps (41 to 17 ms).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from keyfill.characters.lamp import DIMENSIONS, Dimensions

#: Bumped whenever the simulation changes in a way that changes its output.
SIM_VERSION = 1


@dataclass(frozen=True)
class Settings:
    """Physics, control, search and extraction parameters of ``keyfill simulate``."""

    # --- physics (pybullet) ---
    dimensions: Dimensions = DIMENSIONS
    gravity: float = 9.81
    time_step: float = 1.0 / 480.0
    solver_iterations: int = 10
    friction: float = 0.8
    #: joint limits (rad) of the leg, neck and head hinges
    lower_limits: tuple[float, float, float] = (-1.3, -2.6, -1.8)
    upper_limits: tuple[float, float, float] = (1.3, 2.6, 1.8)

    # --- PD control: tau = kp (theta_d - theta) - kd omega, clipped to +-max_torque ---
    kp: tuple[float, float, float] = (12.0, 8.0, 2.0)
    kd: tuple[float, float, float] = (0.3, 0.2, 0.04)
    max_torque: tuple[float, float, float] = (6.0, 4.0, 1.5)

    # --- episodes ---
    cycles: int = 3
    #: time the last target pose is held after the last cycle, so the last hop can land and settle
    settle_time: float = 0.5
    #: the base touches the ground when its lowest point is at most this high
    contact_tolerance: float = 1e-3
    #: |base angle| beyond which the lamp has fallen (episode ends early)
    max_tilt: float = 1.2

    # --- what counts as a hop, and a satisfactory run ---
    min_air_time: float = 0.06
    min_distance: float = 0.15
    min_height: float = 0.02
    max_final_tilt: float = 0.35

    # --- simulated annealing (Algorithm 1) ---
    duration_step: float = 0.007
    angle_step: float = 0.5
    initial_temperature: float = 2.0
    cooling: float = 0.999307
    min_duration: float = 0.02
    max_duration: float = 0.6
    #: spread of the per-run perturbation of the reference controller (rad, s)
    init_angle_noise: float = 0.1
    init_duration_noise: float = 0.01

    # --- extraction (paper section 5) ---
    hop_frames: int = 25
    pause_frames: int = 6
    #: nominal frame rate of the extracted sequences (their frames are evenly spaced per hop, not in time)
    fps: float = 60.0

    version: int = SIM_VERSION

    def to_dict(self) -> dict:
        """A JSON-ready dict (nested dimensions included)."""
        d = dataclasses.asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


DEFAULT_SETTINGS = Settings()
