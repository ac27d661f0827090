"""What an IK iteration needs about one (model, frame, task), built once and cached.

The compiled chain and its damped solver, the limits (which joints wrap by whole turns and
which are clipped), the generated iteration (:mod:`manip_kin.codegen.ik_step`), the random-restart
ranges, the reach bound and the seed table (:mod:`manip_kin.ik.seeds`).
"""

from __future__ import annotations

import math

import numpy as np

from manip_kin.codegen.ik_step import compile_ik_iteration
from manip_kin.control.resolved_rate import _pose_error_values
from manip_kin.core.damped_least_squares import DampedSolver
from manip_kin.core.kinematics import compiled_kinematics
from manip_kin.core.model import RobotModel
from manip_kin.core.pose_jacobian import jacobian_entry
from manip_kin.core.pose_rows import Task
from manip_kin.ik.seeds import SeedTable

_TWO_PI = 2.0 * math.pi


class IKProblem:
    """Everything about (model, frame, task) an IK iteration needs, built once and cached."""

    def __init__(self, model: RobotModel, frame_index: int, task: Task):
        n = model.dof
        self.model = model
        self.n = n
        self.rows = task.rows
        self.orientation_rows = task.orientation_rows
        self.position_rows = task.position_rows
        self.chain = compiled_kinematics(model, frame_index, True)
        # The one damped solve; reads every Jacobian entry from the chain's output, so held
        # columns can be zeroed.
        self.solver = DampedSolver(self.chain, n, task.rows)
        self.solve = self.solver.shifted
        self.lower, self.upper = model.lower.tolist(), model.upper.tolist()
        # Revolute joints spanning a full turn are wrapped (q and q ± 2π are the same pose);
        # the others are clipped.
        span = [self.upper[j] - self.lower[j] for j in range(n)]
        self.wraps = [
            joint.is_revolute and math.isfinite(span[j]) and span[j] >= _TWO_PI - 1e-12
            for j, joint in enumerate(model.joints)
        ]
        self.clipped = [j for j in range(n) if not self.wraps[j]]
        self.iterate = compile_ik_iteration(self.chain, n, task.rows, self.lower, self.upper, self.wraps)
        # Random restarts: uniform within the limits (finite stand-ins for continuous joints).
        self.sample_low = [
            lo if math.isfinite(lo) else (-1.0 if j.type.value == "prismatic" else -math.pi)
            for lo, j in zip(self.lower, model.joints)
        ]
        sample_high = [
            hi if math.isfinite(hi) else (1.0 if j.type.value == "prismatic" else math.pi)
            for hi, j in zip(self.upper, model.joints)
        ]
        self.sample_span = [high - low for low, high in zip(self.sample_low, sample_high)]
        self.reach = _reach_bound(model, frame_index)
        self.first_joint = model.chain.fixed[0][:3, 3].copy()
        self.seeds = SeedTable(
            model,
            frame_index,
            self.sample_low,
            self.sample_span,
            bool(self.position_rows),
            bool(self.orientation_rows),
            self.reach,
        )

    def random_start(self, generator: np.random.Generator) -> list:
        return [
            low + span * u for low, span, u in zip(self.sample_low, self.sample_span, generator.random(self.n).tolist())
        ]

    def project(self, q: list) -> list:
        """``q`` moved into the limits: wrapped by whole turns or clipped."""
        lower, upper, wraps = self.lower, self.upper, self.wraps
        for j in range(self.n):
            value = q[j]
            if value < lower[j]:
                if wraps[j]:
                    value += _TWO_PI * math.ceil((lower[j] - value) / _TWO_PI)
                q[j] = value if lower[j] <= value <= upper[j] else lower[j]
            elif value > upper[j]:
                if wraps[j]:
                    value -= _TWO_PI * math.ceil((value - upper[j]) / _TWO_PI)
                q[j] = value if lower[j] <= value <= upper[j] else upper[j]
        return q

    def errors(self, values, goal) -> tuple[list, float, float]:
        """Task error vector (m values), orientation and position norms."""
        error = _pose_error_values(values, goal)
        task_error = [error[r] for r in self.rows]
        orientation = math.sqrt(sum(error[r] * error[r] for r in self.orientation_rows))
        position = math.sqrt(sum(error[r] * error[r] for r in self.position_rows))
        return task_error, orientation, position

    def held_joints(self, values, q: list, error: list) -> list[int]:
        """Joints at a limit whose gradient ``(Jᵀe)ⱼ`` points outside the limits."""
        n, rows = self.n, self.rows
        held = []
        for j in self.clipped:
            at_lower, at_upper = q[j] <= self.lower[j], q[j] >= self.upper[j]
            if at_lower or at_upper:
                gradient = sum(values[jacobian_entry(n, r, j)] * error[i] for i, r in enumerate(rows))
                if (at_lower and gradient < 0.0) or (at_upper and gradient > 0.0):
                    held.append(j)
        return held


def problem_for(model: RobotModel, frame_index: int, task: Task) -> IKProblem:
    """The :class:`IKProblem` of (model, frame, task), built on first use (kept in ``model.kernels``)."""
    return model.kernels.get(("ik problem", frame_index, task.rows), IKProblem, model, frame_index, task)


def _reach_bound(model: RobotModel, frame_index: int) -> float:
    """An upper bound of the distance from joint 1's origin to the frame [m].

    The sum of the fixed offsets between successive joint origins, the prismatic travels and
    the end-effector/tool offsets: no configuration puts the frame farther away.
    """
    chain = model.chain
    n = model.dof
    count = min(frame_index, n)
    total = 0.0
    for i in range(count):
        if i > 0:
            total += float(np.linalg.norm(chain.fixed[i][:3, 3]))
        if chain.prismatic_mask[i] > 0.5:
            total += max(abs(float(model.lower[i])), abs(float(model.upper[i])))
    if frame_index > n:
        tail = chain.moving_to_ee if frame_index == n + 1 or model.tool is None else chain.moving_to_ee @ model.tool
        total += float(np.linalg.norm(tail[:3, 3]))
    elif frame_index >= 1:
        total += float(np.linalg.norm(chain.frame_offsets[frame_index - 1][:3, 3]))
    return total
