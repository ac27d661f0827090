"""Forward kinematics, Jacobians and twists of a :class:`~manip_kin.core.model.RobotModel`.

Pinocchio-style: the model is immutable; per-call results go into a
:class:`KinematicsData` workspace filled by :func:`forward_kinematics`, and the
other functions read from it. Convenience wrappers (:func:`frame_pose`,
:func:`jacobian`) do both for one-off calls.

Frames are indexed as in :meth:`RobotModel.frame_index`: 0 base, 1..n joint
frames, n + 1 end effector, n + 2 tool. All poses are expressed in the base frame.

Jacobian kinds (all shape (6, n) with rows ``[angular; linear]``, as :class:`Jacobian`):
    * ``geometric``: angular velocity and linear velocity of the frame origin, w.r.t. the
      base, projected on the base axes.
    * ``space``: the space-frame twist (screw theory): ``[ω; ṗ - ω × p]``.
    * ``body``: the twist in the frame's own axes: ``[Rᵀω; Rᵀṗ]``.
    * ``analytical``: ``[d(roll, pitch, yaw)/dt; ṗ]``, singular at pitch = ±π/2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from manip_kin.core.model import RobotModel
from manip_kin.core.pose_jacobian import POSE_VALUES
from manip_kin.core.rotations import invert_transform, matrix_to_rpy, rpy_rate_matrix, skew
from manip_kin.errors import InvalidArgumentError

JACOBIAN_KINDS = ("geometric", "space", "body", "analytical")
_BATCH_BLOCK = 4096  # configurations per block in batch_frame_pose: 16 x 32 KiB temporaries


class KinematicsData:
    """Per-call workspace for one model: buffers reused across calls (not thread-safe).

    Attributes:
        joint_inputs: ``[cos q, sin q, q, 1]`` per joint, shape (n, 4, 1).
        moving: joint frames before their child offset (z = joint axis), in base, shape (n, 4, 4).
        ee: end-effector pose in base, shape (4, 4).
        tool: tool pose in base (the end effector when there is no tool), shape (4, 4).
        q: the configuration these results belong to, shape (n,).
    """

    def __init__(self, model: RobotModel):
        n = model.dof
        self.joint_inputs = np.zeros((n, 4, 1))
        self.joint_inputs[:, 3, 0] = 1.0
        self.moving = np.zeros((n, 4, 4))
        self.ee = np.eye(4)
        self.tool = np.eye(4)
        self.q = np.zeros(n)
        self.moving_to_tool = (
            model.chain.moving_to_ee @ model.tool if model.tool is not None else model.chain.moving_to_ee
        )


def forward_kinematics(model: RobotModel, data: KinematicsData, q: np.ndarray) -> None:
    """Fill ``data`` with the joint frames, end effector and tool at ``q``.

    ``q`` must already be a float array of shape (n,) (see :meth:`RobotModel.check_q`);
    the hot path does not re-validate it.
    """
    chain = model.chain
    inputs = data.joint_inputs
    np.cos(q, out=inputs[:, 0, 0])
    np.sin(q, out=inputs[:, 1, 0])
    inputs[:, 2, 0] = q
    data.q[:] = q
    # Every local transform F_i Z(q_i) in one batched product, then the chain.
    local = np.matmul(chain.basis, inputs).reshape(-1, 4, 4)
    moving = data.moving
    moving[0] = local[0]
    for i in range(1, local.shape[0]):
        np.dot(moving[i - 1], local[i], out=moving[i])
    np.dot(moving[-1], chain.moving_to_ee, out=data.ee)
    np.dot(moving[-1], data.moving_to_tool, out=data.tool)


def all_frames(model: RobotModel, data: KinematicsData) -> np.ndarray:
    """Every frame in base after :func:`forward_kinematics`: base, 1..n, ee, tool; shape (n + 3, 4, 4)."""
    n = model.dof
    frames = np.empty((n + 3, 4, 4))
    frames[0] = np.eye(4)
    np.matmul(data.moving, model.chain.frame_offsets, out=frames[1 : n + 1])
    frames[n + 1] = data.ee
    frames[n + 2] = data.tool
    return frames


def frame_in_base(model: RobotModel, data: KinematicsData, frame_index: int) -> np.ndarray:
    """Pose of one frame in base after :func:`forward_kinematics`, shape (4, 4)."""
    n = model.dof
    if frame_index == n + 2:
        return data.tool.copy()
    if frame_index == n + 1:
        return data.ee.copy()
    if frame_index == 0:
        return np.eye(4)
    return data.moving[frame_index - 1] @ model.chain.frame_offsets[frame_index - 1]


def _moving_joint_count(model: RobotModel, frame_index: int) -> int:
    """How many joints move a frame: frame i is moved by joints 1..i."""
    return min(frame_index, model.dof)


def geometric_jacobian_from_data(
    model: RobotModel, data: KinematicsData, frame_index: int, frame_position: np.ndarray | None = None
) -> np.ndarray:
    """Geometric Jacobian ``[angular; linear]`` of a frame, shape (6, n), from a filled workspace.

    Args:
        model: the robot.
        data: workspace after :func:`forward_kinematics`.
        frame_index: frame whose origin velocity is described.
        frame_position: that frame's origin in base, shape (3,), if already known.
    """
    n = model.dof
    count = _moving_joint_count(model, frame_index)
    if frame_position is None:
        frame_position = frame_in_base(model, data, frame_index)[:3, 3]
    axes = data.moving[:, :3, 2]  # (n, 3) joint axes in base
    origins = data.moving[:, :3, 3]
    lever = frame_position - origins
    revolute = model.chain.revolute_mask
    out = np.empty((6, n))
    # z × r written out: np.cross costs several microseconds on tiny arrays.
    out[3] = axes[:, 1] * lever[:, 2] - axes[:, 2] * lever[:, 1]
    out[4] = axes[:, 2] * lever[:, 0] - axes[:, 0] * lever[:, 2]
    out[5] = axes[:, 0] * lever[:, 1] - axes[:, 1] * lever[:, 0]
    out[3:] *= revolute
    out[3:] += axes.T * model.chain.prismatic_mask
    out[:3] = axes.T * revolute
    if count < n:
        out[:, count:] = 0.0
    return out


@dataclass(frozen=True)
class Jacobian:
    """A Jacobian with its blocks named.

    Attributes:
        kind: ``geometric``, ``space``, ``body`` or ``analytical`` (see the module docstring).
        frame: name of the frame it describes.
        angular: rows mapping q̇ to angular velocity [rad/s] (rpy rates for ``analytical``), shape (3, n).
        linear: rows mapping q̇ to linear velocity [m/s], shape (3, n).
    """

    kind: str
    frame: str
    angular: np.ndarray
    linear: np.ndarray

    @property
    def matrix(self) -> np.ndarray:
        """``[angular; linear]`` stacked, shape (6, n)."""
        return np.vstack([self.angular, self.linear])


def jacobian_from_data(model: RobotModel, data: KinematicsData, frame_index: int, kind: str) -> Jacobian:
    """Any Jacobian kind of a frame from a filled workspace."""
    if kind not in JACOBIAN_KINDS:
        raise InvalidArgumentError(f"unknown Jacobian kind {kind!r}; valid: {', '.join(JACOBIAN_KINDS)}")
    pose = frame_in_base(model, data, frame_index)
    geometric = geometric_jacobian_from_data(model, data, frame_index, pose[:3, 3])
    angular, linear = geometric[:3], geometric[3:]
    if kind == "space":
        # v_s = ṗ - ω × p = ṗ + p × ω
        linear = linear + skew(pose[:3, 3]) @ angular
    elif kind == "body":
        rotation_t = pose[:3, :3].T
        angular, linear = rotation_t @ angular, rotation_t @ linear
    elif kind == "analytical":
        angular = np.linalg.solve(rpy_rate_matrix(matrix_to_rpy(pose[:3, :3])), angular)
    return Jacobian(kind=kind, frame=model.frame_name(frame_index), angular=angular, linear=linear)


# --- the fast path: unrolled code per frame (see chain_codegen) ---------------------------------


def _frame_tail(model: RobotModel, frame_index: int) -> tuple[np.ndarray, int]:
    """Constant transform from the last moving joint frame to ``frame_index``, and that joint count."""
    chain = model.chain
    n = model.dof
    if frame_index == 0:
        return np.eye(4), 0
    if frame_index <= n:
        return chain.frame_offsets[frame_index - 1], frame_index
    tail = chain.moving_to_ee
    if frame_index == n + 2:
        tail = tail @ model.tool
    return tail, n


def compiled_kinematics(model: RobotModel, frame_index: int, with_jacobian: bool, vectorized: bool = False):
    """The unrolled ``chain(q) -> tuple`` for one frame, built once per model (``model.kernels``).

    With ``vectorized`` it runs on one numpy array of configurations per joint (see
    :func:`manip_kin.codegen.chain.compile_chain`).
    """
    return model.kernels.get(
        ("kinematics", frame_index, with_jacobian, vectorized), _chain_of, model, frame_index, with_jacobian, vectorized
    )


def _chain_of(model: RobotModel, frame_index: int, with_jacobian: bool, vectorized: bool):
    from manip_kin.codegen.chain import compile_chain

    tail, count = _frame_tail(model, frame_index)
    revolute = [bool(flag) for flag in model.chain.revolute_mask]
    return compile_chain(model.chain.fixed, revolute, tail, count, with_jacobian, vectorized=vectorized)


def compiled_frames(model: RobotModel):
    """The unrolled ``frames(q) -> tuple`` of every model frame and joint twist
    (:func:`manip_kin.codegen.chain.generate_frames_source`), built once per model."""
    return model.kernels.get(("frames",), _frames_of, model)


def _frames_of(model: RobotModel):
    from manip_kin.codegen.chain import compile_frames

    chain = model.chain
    return compile_frames(chain.fixed, [bool(flag) for flag in chain.revolute_mask], chain.frame_offsets)


def pose_in_base(model: RobotModel, q: np.ndarray, frame_index: int) -> np.ndarray:
    """Pose of one frame in base, shape (4, 4): the fast path for control loops.

    Args:
        q: joint positions, a float array of shape (n,), not re-validated here.
        frame_index: see :meth:`RobotModel.frame_index`.
    """
    return np.array(compiled_kinematics(model, frame_index, False)(q.tolist())).reshape(4, 4)


def pose_and_jacobian_in_base(model: RobotModel, q: np.ndarray, frame_index: int) -> tuple[np.ndarray, np.ndarray]:
    """Pose (4, 4) and geometric Jacobian ``[angular; linear]`` (6, n) of a frame: the fast path."""
    values = np.array(compiled_kinematics(model, frame_index, True)(q.tolist()))
    return values[:POSE_VALUES].reshape(4, 4), values[POSE_VALUES:].reshape(6, model.dof)


# --- one-off convenience wrappers ---------------------------------------------------------------


def _filled(model: RobotModel, q) -> KinematicsData:
    data = KinematicsData(model)
    forward_kinematics(model, data, model.check_q(q))
    return data


def frame_pose(model: RobotModel, q, frame: str | int | None = None) -> np.ndarray:
    """Pose of ``frame`` (default: tool if any, else ee) in base at ``q``, shape (4, 4)."""
    index = model.frame_index(model.default_frame if frame is None else frame)
    return pose_in_base(model, model.check_q(q), index)


def frame_poses(model: RobotModel, q) -> np.ndarray:
    """Every frame in base at ``q``: base, 1..n, ee, tool; shape (n + 3, 4, 4)."""
    return all_frames(model, _filled(model, q))


def transform_between(model: RobotModel, q, frame_from: str | int, frame_to: str | int) -> np.ndarray:
    """Pose of ``frame_to`` expressed in ``frame_from`` at ``q``, shape (4, 4)."""
    frames = frame_poses(model, q)
    a = frames[model.frame_index(frame_from)]
    b = frames[model.frame_index(frame_to)]
    return invert_transform(a) @ b


def jacobian(model: RobotModel, q, frame: str | int | None = None, kind: str = "geometric") -> Jacobian:
    """Jacobian of ``frame`` (default: tool if any, else ee) at ``q``; see :class:`Jacobian`."""
    index = model.frame_index(model.default_frame if frame is None else frame)
    return jacobian_from_data(model, _filled(model, q), index, kind)


def frame_twist(model: RobotModel, q, qdot, frame: str | int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Angular [rad/s] and linear [m/s] velocity of a frame w.r.t. base, in base, each shape (3,)."""
    qdot = model.check_q(qdot, "qdot")
    j = jacobian(model, q, frame)
    return j.angular @ qdot, j.linear @ qdot


def batch_frame_pose(model: RobotModel, configurations, frame: str | int | None = None) -> np.ndarray:
    """Pose of one frame for many configurations at once.

    Runs the unrolled chain on numpy arrays, a block of configurations at a time so the
    temporaries stay in cache.

    Args:
        configurations: joint vectors, shape (N, n).
        frame: frame name or index (default: tool if any, else ee).
    Returns:
        Poses in base, shape (N, 4, 4).
    """
    q = np.asarray(configurations, dtype=float)
    if q.ndim != 2 or q.shape[1] != model.dof:
        raise InvalidArgumentError(f"configurations have shape {q.shape}; valid: (N, {model.dof})")
    index = model.frame_index(model.default_frame if frame is None else frame)
    chain_function = compiled_kinematics(model, index, False, vectorized=True)
    count = q.shape[0]
    joint_rows = np.ascontiguousarray(q.T)  # one contiguous row of N values per joint
    out = np.empty((count, 16))
    block = np.empty((16, _BATCH_BLOCK))
    for start in range(0, count, _BATCH_BLOCK):
        stop = min(start + _BATCH_BLOCK, count)
        width = stop - start
        for entry, value in enumerate(chain_function(list(joint_rows[:, start:stop]))):
            block[entry, :width] = value
        out[start:stop] = block[:, :width].T
    return out.reshape(count, 4, 4)
