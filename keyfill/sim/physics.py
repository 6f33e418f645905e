"""The lamp in pybullet: build it once, then simulate many controllers cheaply.

Model (dimensions in :data:`keyfill.characters.lamp.DIMENSIONS`, parameters in
:class:`keyfill.sim.settings.Settings`):

* Four box links (base, leg, neck, head) in a chain of revolute hinges about Z.
* The motion is kept in the vertical X-Y plane by construction, not by a
  soft constraint: the base hangs from a fixed world link through a
  prismatic X joint, a prismatic Y joint and a revolute Z joint (two
  massless-in-effect slider links of 1 g). The six joint positions are then
  exactly the lamp's six animation variables (:mod:`keyfill.characters.lamp`).
* Gravity along -Y; a ground plane at y = 0; Coulomb friction ``friction``
  on base and ground, no restitution.
* Joint limits on the three hinges (URDF ``<limit>``, enforced by Bullet).

Control: keyfill computes each hinge's PD torque
``tau = kp (theta_d - theta) - kd omega`` itself, clips it to
``max_torque`` and applies it with ``TORQUE_CONTROL`` (after switching off
pybullet's default velocity motors). pybullet's own ``POSITION_CONTROL`` is
a velocity-level constraint whose dimensionless gains behave differently at
every time step and solver iteration count; computing the torque here keeps
the paper's controller, with gains in N m / rad and N m s / rad and a real
torque limit, independent of the integrator settings. It costs two small
pybullet calls per step (measured in ``benchmarks/bench_simulate.py``).

Speed: one :class:`LampWorld` keeps one pybullet connection; each episode
starts with ``restoreState`` of the freshly built world (microseconds,
where reconnecting costs tens of milliseconds) and ends early once the base
has tilted past ``max_tilt``.
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Self

import numpy as np

from keyfill.characters.lamp import Dimensions
from keyfill.files import quiet_stderr
from keyfill.sim.controller import Controller
from keyfill.sim.settings import Settings


def import_pybullet():
    """The pybullet module, imported without its start-up banner."""
    with quiet_stderr():
        import pybullet

    return pybullet


def _box_link(name: str, mass: float, size: tuple[float, float, float], center: tuple[float, float, float]) -> str:
    sx, sy, sz = size
    ixx, iyy, izz = mass * (sy * sy + sz * sz) / 12, mass * (sx * sx + sz * sz) / 12, mass * (sx * sx + sy * sy) / 12
    c = " ".join(f"{v:.9g}" for v in center)
    s = " ".join(f"{v:.9g}" for v in size)
    return (
        f'<link name="{name}"><inertial><origin xyz="{c}"/><mass value="{mass:.9g}"/>'
        f'<inertia ixx="{ixx:.9g}" iyy="{iyy:.9g}" izz="{izz:.9g}" ixy="0" ixz="0" iyz="0"/></inertial>'
        f'<collision><origin xyz="{c}"/><geometry><box size="{s}"/></geometry></collision></link>'
    )


_SLIDER = (
    '<link name="{name}"><inertial><mass value="0.001"/>'
    '<inertia ixx="1e-7" iyy="1e-7" izz="1e-7" ixy="0" ixz="0" iyz="0"/></inertial></link>'
)


def lamp_urdf(dims: Dimensions, settings: Settings) -> str:
    """URDF text of the lamp on its planar X / Y / angle carriage."""
    d = dims
    links = [
        '<link name="world"/>',
        _SLIDER.format(name="slider_x"),
        _SLIDER.format(name="slider_y"),
        _box_link("base", d.base_mass, (d.base_length, d.base_height, d.base_depth), (0, d.base_height / 2, 0)),
        _box_link("leg", d.leg_mass, (d.leg_width, d.leg_length, d.depth), (0, d.leg_length / 2, 0)),
        _box_link("neck", d.neck_mass, (d.neck_width, d.neck_length, d.depth), (0, d.neck_length / 2, 0)),
        _box_link("head", d.head_mass, (d.head_width, d.head_length, d.depth), (0, d.head_length / 2, 0)),
    ]
    free = '<limit lower="-1000" upper="1000" effort="0" velocity="1000"/>'
    joints = [
        (f'<joint name="base_x" type="prismatic"><parent link="world"/><child link="slider_x"/>'
         f'<axis xyz="1 0 0"/>{free}</joint>'),
        (f'<joint name="base_y" type="prismatic"><parent link="slider_x"/><child link="slider_y"/>'
         f'<axis xyz="0 1 0"/>{free}</joint>'),
        ('<joint name="base_angle" type="continuous"><parent link="slider_y"/><child link="base"/>'
         '<axis xyz="0 0 1"/></joint>'),
    ]
    hinges = [("leg", "base", d.base_height), ("neck", "leg", d.leg_length), ("head", "neck", d.neck_length)]
    for k, (child, parent, y) in enumerate(hinges):
        lo, hi, tmax = settings.lower_limits[k], settings.upper_limits[k], settings.max_torque[k]
        joints.append(
            f'<joint name="{child}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="0 {y:.9g} 0"/><axis xyz="0 0 1"/>'
            f'<limit lower="{lo:.9g}" upper="{hi:.9g}" effort="{tmax:.9g}" velocity="100"/></joint>'
        )
    return '<?xml version="1.0"?>\n<robot name="lamp">\n' + "\n".join(links + joints) + "\n</robot>\n"


@dataclass(frozen=True, eq=False)
class Episode:
    """One simulated run of a controller, sampled at every physics step.

    Attributes:
        times: ``(N,)`` seconds since the start, ``k * time_step``.
        states: ``(N, 6)`` the six animation variables at those times (m, rad); row 0 is the start.
        fell: the base tilted past ``max_tilt``.
    """

    times: np.ndarray
    states: np.ndarray
    fell: bool


class LampWorld:
    """A pybullet world holding one lamp on a ground plane.

    Use as a context manager (or call :meth:`close`); each instance owns its
    own pybullet connection, so worlds in different threads or processes do
    not interfere.
    """

    def __init__(self, settings: Settings):
        self.settings = settings
        self.p = p = import_pybullet()
        self.client = p.connect(p.DIRECT)
        cid = self.client
        try:
            p.setGravity(0, -settings.gravity, 0, physicsClientId=cid)
            p.setPhysicsEngineParameter(
                fixedTimeStep=settings.time_step,
                numSolverIterations=settings.solver_iterations,
                numSubSteps=0,
                deterministicOverlappingPairs=1,
                physicsClientId=cid,
            )
            plane = p.createCollisionShape(p.GEOM_PLANE, planeNormal=[0, 1, 0], physicsClientId=cid)
            self.ground = p.createMultiBody(0, plane, physicsClientId=cid)
            with tempfile.TemporaryDirectory() as tmp:
                urdf = Path(tmp) / "lamp.urdf"
                urdf.write_text(lamp_urdf(settings.dimensions, settings))
                self.lamp = p.loadURDF(
                    str(urdf), useFixedBase=True, flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=cid
                )
            n = p.getNumJoints(self.lamp, physicsClientId=cid)
            self.joints = list(range(n))
            self.hinges = self.joints[3:]
            # Bullet gives every joint a velocity motor by default: switch them off.
            p.setJointMotorControlArray(self.lamp, self.joints, p.VELOCITY_CONTROL, forces=[0.0] * n, physicsClientId=cid)
            for link in [-1, *self.joints]:
                p.changeDynamics(
                    self.lamp, link, lateralFriction=settings.friction, restitution=0.0,
                    linearDamping=0.0, angularDamping=0.0, jointDamping=0.0, physicsClientId=cid,
                )
            p.changeDynamics(self.ground, -1, lateralFriction=settings.friction, restitution=0.0, physicsClientId=cid)
            self.clean_state = p.saveState(physicsClientId=cid)
        except BaseException:
            p.disconnect(physicsClientId=cid)
            raise

    def close(self) -> None:
        if self.client is not None:
            self.p.disconnect(physicsClientId=self.client)
            self.client = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def reset(self, hinge_angles: np.ndarray) -> None:
        """Back to the freshly built world, the lamp at rest on the ground with the given hinge angles."""
        p, cid = self.p, self.client
        p.restoreState(self.clean_state, physicsClientId=cid)
        for j, v in zip(self.joints, [0.0, 0.0, 0.0, *map(float, hinge_angles)]):
            p.resetJointState(self.lamp, j, v, 0.0, physicsClientId=cid)

    def simulate(self, controller: Controller, stop_on_fall: bool = True) -> Episode:
        """Run ``settings.cycles`` cycles of ``controller`` plus ``settle_time``; see :class:`Episode`.

        With ``stop_on_fall`` (the default) the episode ends as soon as the
        base tilts past ``max_tilt``; ``False`` runs it to the end regardless
        (``benchmarks/bench_simulate.py`` measures what stopping saves).
        """
        s = self.settings
        p, cid, lamp, joints, hinges = self.p, self.client, self.lamp, self.joints, self.hinges
        dt = s.time_step
        bounds = np.cumsum(np.tile(controller.durations, s.cycles))
        n = int(np.ceil((bounds[-1] + s.settle_time) / dt - 1e-9))
        # The torque applied during step k comes from the state and target at time k * dt.
        state = np.searchsorted(bounds, np.arange(n) * dt, side="right")
        targets = np.vstack([np.tile(controller.poses, (s.cycles, 1)), controller.poses[-1:]])[state].tolist()
        (kp0, kp1, kp2), (kd0, kd1, kd2), (m0, m1, m2) = s.kp, s.kd, s.max_torque
        max_tilt = s.max_tilt
        torque = p.TORQUE_CONTROL
        states = np.empty((n + 1, 6))
        self.reset(controller.start_pose())
        fell = False
        k = 0
        for k in range(n + 1):
            js = p.getJointStates(lamp, joints, physicsClientId=cid)
            row = [j[0] for j in js]
            states[k] = row
            if abs(row[2]) > max_tilt:
                fell = True
                if stop_on_fall:
                    break
            if k == n:
                break
            # PD torques of the three hinges, clipped; written out because this loop is the hot path
            # (a list comprehension with min/max costs about 4x as much).
            t0, t1, t2 = targets[k]
            (q0, w0, _, _), (q1, w1, _, _), (q2, w2, _, _) = js[3], js[4], js[5]
            f0 = kp0 * (t0 - q0) - kd0 * w0
            f1 = kp1 * (t1 - q1) - kd1 * w1
            f2 = kp2 * (t2 - q2) - kd2 * w2
            forces = [
                m0 if f0 > m0 else (max(f0, -m0)),
                m1 if f1 > m1 else (max(f1, -m1)),
                m2 if f2 > m2 else (max(f2, -m2)),
            ]
            p.setJointMotorControlArray(lamp, hinges, torque, forces=forces, physicsClientId=cid)
            p.stepSimulation(physicsClientId=cid)
        count = k + 1
        return Episode(times=np.arange(count) * dt, states=states[:count], fell=fell)
