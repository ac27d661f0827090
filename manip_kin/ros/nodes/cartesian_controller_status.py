"""``cartesian_controller``'s status: the key-values of its ``/diagnostics`` status (the state,
the errors of the goal of either kind, the rejections, servoing, the command filter, collision
avoidance and the loop's timing; see docs/interfaces.md), and one INFO line per change of the
command type or into or out of a halted state.
"""

from __future__ import annotations

import numpy as np

from manip_kin.control.state_machines import HALTED_STATES, ControllerState, ControllerSupervisor, GoalKind
from manip_kin.core.kinematics import frame_pose
from manip_kin.ros.runtime.rate_loop import stats_key_values


def status_values(node) -> list[tuple[str, str]]:
    """The status key-values of a :class:`~manip_kin.ros.nodes.cartesian_controller.CartesianControllerNode`."""
    supervisor = node.supervisor
    inputs = node.inputs
    # Blocked: the errors where the arm was held off, for the outcome's words.
    held_off = supervisor.state is ControllerState.BLOCKED
    joint_space = supervisor.goal_kind in (GoalKind.JOINT, GoalKind.JOG)
    if supervisor.goal_kind is GoalKind.JOINT:
        values = _joint_values(node, (supervisor.active or held_off) and node.joint_output is not None)
    else:
        values = _pose_values(node, (supervisor.active or held_off) and node.output is not None)
    return (
        values
        + [
            ("goal_kind", supervisor.goal_kind or ""),
            # When the goal was first within the tolerances (ROS clock): what --wait calls "settled".
            ("converged_stamp", node.stamp_key_of(supervisor.converged_ns) if supervisor.converged_ns else ""),
            ("task", node.controller.task.name),
            ("position_tolerance", f"{node.position_tolerance:g}"),
            ("orientation_tolerance", f"{node.orientation_tolerance:g}"),
            ("joint_tolerance", f"{node.joint_tolerance:g}"),
            ("rejected_goals", str(inputs.rejected_goals)),
            ("rejected_twists", str(inputs.rejected_twists)),
            ("rejected_joint_states", str(inputs.rejected_joint_states)),
            ("rejected_references", str(inputs.rejected_references)),
            ("rejected_stamp", inputs.rejected_stamp),
            ("last_rejection", inputs.last_rejection),
            ("base_frame", node.base_frame),
            ("controlled_frame", node.model.frame_name(node.controller.frame_index)),
            ("servo_scale", f"{node.servo.scale:.4f}"),
            ("servo_sigma_min", f"{node.servo.sigma_min:.4g}"),
            ("rejected_servo_commands", str(node.servo.rejected)),
            ("command_filter", node.command_filter.result),
            ("braking_joints", ",".join(node.model.joint_names[i] for i in node.command_filter.braking_joints)),
            ("command_drive_periods", f"{node.command_filter.drive_time.periods:.3f}"),
            ("unreachable_errors", " ".join(f"{v:.6g}" for v in supervisor.unreachable_errors or ())),
            ("loop_error", node.loop_error()),
            *node.collision.report(node.get_clock().now().to_msg(), node.joint_output if joint_space else node.output),
        ]
        + stats_key_values(node.loop.stats())
    )


def _pose_values(node, active: bool) -> list[tuple[str, str]]:
    output = node.output
    goal = node.inputs.goal
    return [
        ("state", node.state),
        ("detail", node.detail),
        ("goal_stamp", node.goal_stamp),
        ("goal_xyz", " ".join(f"{v:.6f}" for v in goal[:3, 3]) if goal is not None else ""),
        ("position_error", f"{output.position_error_norm:.9f}" if active else ""),
        ("orientation_error", f"{output.orientation_error_norm:.9f}" if active else ""),
        ("joint_error", ""),
        ("manipulability", f"{output.manipulability:.6g}" if active else ""),
        ("damping", f"{output.damping:.6g}" if active else ""),
        ("velocity_scale", f"{output.velocity_scale:.4f}" if active else ""),
        ("limited_joints", ",".join(node.model.joint_names[i] for i in output.limited_joints) if active else ""),
    ]


def _joint_values(node, active: bool) -> list[tuple[str, str]]:
    """Status values while following a joint reference; the pose errors are those of the
    controlled frame w.r.t. where the reference puts it (at the diagnostics rate only)."""
    output = node.joint_output
    reference = node.inputs.reference[0]
    goal = frame_pose(node.model, reference, node.controller.frame_index)
    position_error = orientation_error = ""
    if active:
        orientation, position = node.controller.error(node.inputs.q, goal)
        position_error = f"{np.linalg.norm(position):.9f}"
        orientation_error = f"{np.linalg.norm(orientation):.9f}"
    return [
        ("state", node.state),
        ("detail", node.detail),
        ("goal_stamp", node.goal_stamp),
        ("goal_xyz", " ".join(f"{v:.6f}" for v in goal[:3, 3])),
        ("goal_q", " ".join(f"{v:.6f}" for v in reference)),
        ("position_error", position_error),
        ("orientation_error", orientation_error),
        ("joint_error", f"{np.max(np.abs(output.joint_error)):.9f}" if active else ""),
        ("manipulability", ""),
        ("damping", ""),
        ("velocity_scale", f"{output.velocity_scale:.4f}" if active else ""),
        ("limited_joints", ",".join(node.model.joint_names[i] for i in output.limited_joints) if active else ""),
    ]


class StateChangeLog:
    """One INFO line per change of the command type, and per change into or out of a halted or
    unreachable state (``log(key, text)``: a throttled log)."""

    def __init__(self, log, state: ControllerState):
        self._log = log
        self._state = state
        self._kind: GoalKind | None = None

    def update(self, supervisor: ControllerSupervisor) -> None:
        """Log what changed since the last call, if anything."""
        state, kind = supervisor.state, supervisor.goal_kind
        if state == self._state and kind == self._kind:
            return
        previous, self._state = self._state, state
        previous_kind, self._kind = self._kind, kind
        if kind != previous_kind:
            self._log(f"kind:{kind}", f"command {previous_kind or 'none'} -> {kind or 'none'}: {supervisor.detail}")
        elif state in HALTED_STATES or previous in HALTED_STATES:
            self._log(f"state:{state}", f"{previous} -> {state}: {supervisor.detail}")
