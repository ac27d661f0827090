"""The MuJoCo plant: rigid-body dynamics with gravity, a velocity servo per joint, contact.

Each joint has a drive that is a PI loop on velocity, torque limited::

    tau = Kv (v_ref - v) + Ki ∫ (v_ref - v) dt,   |tau| <= effort limit

The integral of the velocity error is ``q_ref - q`` with ``q_ref`` the integrated command,
so the loop is one MuJoCo position actuator with gain ``Ki``, damping ``Kv`` and the
control ``q_ref + (Kv/Ki) v_ref``; MuJoCo's ``implicitfast`` integrator treats its damping
implicitly, so a stiff servo stays stable at 1 kHz. The gains are given normalised, as the
bandwidths a drive is tuned to, and scaled by each joint's inertia at the start
configuration ``M_ii(q0)`` (with armature): ``Kv = servo_velocity_gain · M_ii``,
``Ki = servo_integral_gain · M_ii``. A joint alone is then ``M ë + Kv ė + Ki e = 0`` on the
velocity error ``e``: with ``servo_integral_gain = servo_velocity_gain² / 4`` (the
defaults, 200 1/s and 10 000 1/s²) it is critically damped with a double pole at
``-servo_velocity_gain / 2``, and a constant load torque ``d`` (gravity) is held with a
position error ``d / Ki`` and no velocity error.

Anti-windup: ``q_ref`` stays within the joint limits and within ``effort / Ki`` of ``q``,
so a saturated or blocked drive does not wind up. A stale command (None) holds ``q_ref``:
zero velocity target, the servo holds the arm where the reference is, as ros2_control
holds a velocity interface at zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.core.scene import Scene
from manip_kin.errors import InvalidArgumentError, JointCountError
from manip_kin.plant.mujoco_model import (
    OBSTACLE_PREFIX,
    JointDynamics,
    SpecSource,
    add_obstacles,
    build_spec,
    urdf_dir_of,
)
from manip_kin.plant.outputs import ChainOutputs


@dataclass(frozen=True)
class ServoGains:
    """Normalised velocity-servo gains: ``velocity`` [1/s] and ``integral`` [1/s²] (see the module docstring)."""

    velocity: float = 200.0
    integral: float = 10000.0


@dataclass(frozen=True)
class PhysicsConfig:
    """Settings of the MuJoCo plant.

    Attributes:
        rate_hz: physics step rate [Hz]; a plant step of ``dt`` runs ``dt · rate_hz`` of them
            (the fraction carried to the next step).
        dynamics: joint damping, armature and friction.
        servo: the velocity servo's gains.
        effort_limits: torque/force limit per joint [N·m | N], model order; None: the URDF's
            ``<limit effort>`` (unlimited where it gives none or 0).
        mesh_search_path: ``:``-separated directories holding packages, for ``package://`` meshes.
    """

    rate_hz: float = 1000.0
    dynamics: JointDynamics = field(default_factory=JointDynamics)
    servo: ServoGains = field(default_factory=ServoGains)
    effort_limits: tuple[float, ...] | None = None
    mesh_search_path: str = ""


@dataclass(frozen=True)
class ContactReport:
    """The strongest contact since the last report: ``force`` [N] (normal force), between
    ``link`` and ``obstacle`` (``NS/ID``), in ``steps`` of the physics steps since then."""

    force: float
    link: str
    obstacle: str
    steps: int


def urdf_effort_limits(model: RobotModel, urdf_text: str | None) -> list[float]:
    """``<limit effort>`` per model joint [N·m | N]; inf where the URDF gives none or 0 (or there is no URDF)."""
    if urdf_text is None:
        return [math.inf] * model.dof
    from manip_kin.core.urdf.document import UrdfTree

    joints = {j.name: j for j in UrdfTree(urdf_text, model.source or "robot_description").joints}
    efforts = []
    for name in model.joint_names:
        effort = joints[name].limit.get("effort", 0.0) if name in joints else 0.0
        efforts.append(effort if effort > 0 else math.inf)
    return efforts


class MujocoPlant(ChainOutputs):
    """A MuJoCo model of the arm, stepped at ``config.rate_hz`` with a velocity servo per joint.

    Args:
        model: the robot.
        q0: start positions, shape (n,), inside the limits.
        config: the plant's settings.
        urdf_text: the URDF ``model`` was loaded from (inertials, collision shapes, efforts),
            None for a robot YAML, DH or PoE model (default links, see
            :mod:`manip_kin.plant.mujoco_model`).

    Attributes:
        effort_values: the servo torques/forces of the last physics step [N·m | N], n floats.
        notes: what the model build left out or assumed (for the node's log).
        gains_kv, gains_ki: the servo gains per joint [N·m·s/rad, N·m/rad] (prismatic: N·s/m, N/m).

    Raises:
        ModelFileError: a malformed ``<inertial>``/``<collision>``, a moving link without mass.
        JointCountError, InvalidArgumentError: effort limits of the wrong length or not > 0.
    """

    name = "mujoco"

    def __init__(self, model: RobotModel, q0: np.ndarray, config: PhysicsConfig, urdf_text: str | None = None):
        super().__init__(model, q0)
        import mujoco

        self._mujoco = mujoco
        self.config = config
        n = model.dof
        efforts = urdf_effort_limits(model, urdf_text) if config.effort_limits is None else list(config.effort_limits)
        if len(efforts) != n:
            raise JointCountError("parameter effort_limits", len(efforts), n)
        if not all(e > 0 for e in efforts):
            raise InvalidArgumentError(f"parameter effort_limits {efforts}: valid: values > 0 (inf: unlimited)")
        self.effort_limits = np.array(efforts, dtype=float)
        self._source = SpecSource(model, urdf_text, urdf_dir_of(model), config.mesh_search_path)
        self._h = 1.0 / config.rate_hz
        self._q_ref = np.array(q0, dtype=float)
        self._time_debt = 0.0
        self._scene_version = -1
        self._compile(Scene(), q0, np.zeros(n))
        self.notes = list(self._source.notes)
        full = np.zeros((self.mj_model.nv, self.mj_model.nv))
        self._mujoco.mj_fullM(self.mj_model, self.data, full)
        diagonal = full[self._dof, self._dof]
        self.gains_kv = config.servo.velocity * diagonal
        self.gains_ki = config.servo.integral * diagonal
        self._feedforward = self.gains_kv / self.gains_ki
        self._windup = self.effort_limits / self.gains_ki
        self._set_gains()
        self.effort_values = [0.0] * n
        self._contact: ContactReport | None = None

    # --- model --------------------------------------------------------------------------------

    def _compile(self, scene: Scene, q: np.ndarray, qdot: np.ndarray) -> None:
        mujoco = self._mujoco
        self._source.notes.clear()
        spec = build_spec(self._source, self.config.dynamics, self._h)
        add_obstacles(spec, scene, self._source)
        m = spec.compile()
        d = mujoco.MjData(m)
        ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name) for name in self.model.joint_names]
        self._qpos = m.jnt_qposadr[ids]
        self._dof = m.jnt_dofadr[ids]
        d.qpos[self._qpos] = q
        d.qvel[self._dof] = qdot
        for i, effort in enumerate(self.effort_limits):
            if math.isfinite(effort):
                m.actuator_forcelimited[i] = 1
                m.actuator_forcerange[i] = (-effort, effort)
        self.mj_model, self.data = m, d
        self._obstacle_bodies = {
            g: m.geom(g).name[len(OBSTACLE_PREFIX) :]
            for g in range(m.ngeom)
            if m.geom(g).name.startswith(OBSTACLE_PREFIX)
        }
        if hasattr(self, "gains_kv"):
            self._set_gains()
        mujoco.mj_forward(m, d)

    def _set_gains(self) -> None:
        m = self.mj_model
        m.actuator_gainprm[:, 0] = self.gains_ki
        m.actuator_biasprm[:, 1] = -self.gains_ki
        m.actuator_biasprm[:, 2] = -self.gains_kv
        self._mujoco.mj_forward(m, self.data)

    def set_scene(self, scene: Scene) -> bool:
        """Rebuild the MuJoCo model with ``scene``'s obstacles when its version moved; True when rebuilt.

        The arm's state (positions, velocities, servo references) carries over.
        """
        if scene.version == self._scene_version:
            return False
        self._scene_version = scene.version
        d = self.data
        self._compile(scene, d.qpos[self._qpos].copy(), d.qvel[self._dof].copy())
        self.notes = list(self._source.notes)
        return True

    # --- stepping -----------------------------------------------------------------------------

    def step(self, command: np.ndarray | None, dt: float) -> None:
        """Advance by ``dt`` seconds (whole physics steps, the rest carried) with velocity target ``command``.

        ``command`` (shape (n,), None: zero, the servo holds) is scaled down as a whole to
        the velocity limits, as the kinematic plant does.
        """
        mujoco, m, d = self._mujoco, self.mj_model, self.data
        self._time_debt += max(dt, 0.0)
        steps = int(self._time_debt / self._h + 1e-9)
        self._time_debt -= steps * self._h
        if command is None:
            v_ref, self.velocity_scale = np.zeros(self._n), 1.0
        else:
            peak = float(np.max(np.abs(command) / self.model.velocity_limits, initial=0.0))
            self.velocity_scale = 1.0 / peak if peak > 1.0 else 1.0
            v_ref = command * self.velocity_scale
        advance, lead = v_ref * self._h, self._feedforward * v_ref
        lower, upper, windup = self.model.lower, self.model.upper, self._windup
        q_ref = self._q_ref
        for _ in range(steps):
            q = d.qpos[self._qpos]
            q_ref = np.clip(np.clip(q_ref + advance, lower, upper), q - windup, q + windup)
            d.ctrl[:] = q_ref + lead
            mujoco.mj_step(m, d)
            if d.ncon:
                self._record_contacts()
        self._q_ref = q_ref
        self.q_values = d.qpos[self._qpos].tolist()
        self.qdot_values = d.qvel[self._dof].tolist()
        self.effort_values = d.actuator_force.tolist()
        self._update_kinematics()

    def _record_contacts(self) -> None:
        m, d = self.mj_model, self.data
        wrench = np.zeros(6)
        best = self._contact
        strongest, pair = -1.0, ("", "")
        for i in range(d.ncon):
            contact = d.contact[i]
            g1, g2 = int(contact.geom1), int(contact.geom2)
            obstacle_geom, arm_geom = (g1, g2) if g1 in self._obstacle_bodies else (g2, g1)
            self._mujoco.mj_contactForce(m, d, i, wrench)
            if wrench[0] > strongest:
                strongest = float(wrench[0])
                pair = (m.body(m.geom_bodyid[arm_geom]).name, self._obstacle_bodies.get(obstacle_geom, "?"))
        steps = 1 if best is None else best.steps + 1
        if best is None or strongest > best.force:
            self._contact = ContactReport(strongest, pair[0], pair[1], steps)
        else:
            self._contact = ContactReport(best.force, best.link, best.obstacle, steps)

    def take_contact(self) -> ContactReport | None:
        """The strongest contact since the last call (None: no contact since), and start over."""
        report, self._contact = self._contact, None
        return report

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return float(self.data.time)
