"""Keyboard teleoperation, without ROS or a terminal: keys → the command to stream, and the status line.

:func:`apply_key` is the whole key map of ``manip_kin teleop`` (as teleop_twist_keyboard's:
a key sets the velocity, which stays until another key or space): it takes the current
:class:`TeleopState` and one key and returns the next state. The state's :meth:`TeleopState.twist`
or :meth:`TeleopState.jog` is what the terminal loop streams on ``twist_command`` or
``joint_jog``. :func:`nearest_limit` and :func:`status_line` make the one-line display.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from manip_kin.core.rotations import matrix_to_rpy

#: Twist keys: key → (axis 0..5 of (vx, vy, vz, wx, wy, wz), sign).
TWIST_KEYS = {
    "w": (0, 1.0),
    "s": (0, -1.0),
    "a": (1, 1.0),
    "d": (1, -1.0),
    "r": (2, 1.0),
    "f": (2, -1.0),
    "u": (3, 1.0),
    "j": (3, -1.0),
    "i": (4, 1.0),
    "k": (4, -1.0),
    "o": (5, 1.0),
    "l": (5, -1.0),
}
#: Joint-mode keys: key → sign of the selected joint's velocity.
JOINT_KEYS = {"w": 1.0, "s": -1.0}
STOP_KEYS = (" ", "x")
QUIT_KEYS = ("q", "\x03", "\x04")  # q, Ctrl-C, Ctrl-D
FASTER_KEYS = ("+", "=")
SLOWER_KEYS = ("-", "_")
FRAME_KEY = "t"
MODE_KEY = "m"
#: Factor of one speed step.
SPEED_STEP = 1.25

KEY_HELP = """keys (the velocity a key sets stays until another key or space):
  twist mode   w/s +x/-x   a/d +y/-y   r/f +z/-z            [m/s]
               u/j +roll/-roll   i/k +pitch/-pitch   o/l +yaw/-yaw   [rad/s]
  joint mode   1..9 select joint   w/s +/- velocity of the selected joint   [rad/s | m/s]
  both         space or x: stop   + / -: speed up / down (x1.25)   t: base / tool frame
               m: twist / joint mode   q or Ctrl-C: stop and quit"""


@dataclass(frozen=True)
class TeleopState:
    """What the keyboard has set.

    Attributes:
        mode: ``twist`` or ``joint``.
        tool_frame: twists in the tool (controlled) frame instead of the base frame.
        linear_speed: speed of a linear key [m/s].
        angular_speed: speed of an angular key [rad/s].
        joint_speed: speed of a joint key [rad/s | m/s].
        direction: the active twist direction, 6 signs (vx, vy, vz, wx, wy, wz), or zeros.
        joint: index of the selected joint (joint mode).
        joint_direction: sign of the selected joint's velocity, 0 when stopped.
        quit: the user asked to quit.
    """

    mode: str = "twist"
    tool_frame: bool = False
    linear_speed: float = 0.05
    angular_speed: float = 0.2
    joint_speed: float = 0.2
    direction: tuple[float, ...] = (0.0,) * 6
    joint: int = 0
    joint_direction: float = 0.0
    quit: bool = False

    @property
    def moving(self) -> bool:
        """True while a key's velocity is active."""
        return any(self.direction) or bool(self.joint_direction)

    def twist(self) -> tuple[np.ndarray, np.ndarray]:
        """``(linear [m/s], angular [rad/s])`` of the active twist, shapes (3,), (3,)."""
        direction = np.asarray(self.direction, dtype=float)
        return direction[:3] * self.linear_speed, direction[3:] * self.angular_speed

    def jog(self) -> float:
        """Velocity of the selected joint [rad/s | m/s]."""
        return self.joint_direction * self.joint_speed

    def stopped(self) -> TeleopState:
        """The same settings, no velocity."""
        return replace(self, direction=(0.0,) * 6, joint_direction=0.0)


def apply_key(state: TeleopState, key: str, joint_count: int) -> TeleopState:
    """The state after ``key`` (one character); unknown keys change nothing.

    Args:
        state: the current state.
        key: the key pressed.
        joint_count: joints of the arm (joint selection is 1..min(9, joint_count)).
    """
    if key in QUIT_KEYS:
        return replace(state.stopped(), quit=True)
    if key in STOP_KEYS:
        return state.stopped()
    if key in FASTER_KEYS or key in SLOWER_KEYS:
        factor = SPEED_STEP if key in FASTER_KEYS else 1.0 / SPEED_STEP
        return replace(
            state,
            linear_speed=state.linear_speed * factor,
            angular_speed=state.angular_speed * factor,
            joint_speed=state.joint_speed * factor,
        )
    if key == FRAME_KEY:
        return replace(state.stopped(), tool_frame=not state.tool_frame)
    if key == MODE_KEY:
        return replace(state.stopped(), mode="joint" if state.mode == "twist" else "twist")
    if state.mode == "joint":
        if key.isdigit() and 1 <= int(key) <= min(9, joint_count):
            return replace(state.stopped(), joint=int(key) - 1)
        if key in JOINT_KEYS:
            return replace(state, joint_direction=JOINT_KEYS[key])
        return state
    if key in TWIST_KEYS:
        axis, sign = TWIST_KEYS[key]
        direction = [0.0] * 6
        direction[axis] = sign
        return replace(state, direction=tuple(direction))
    return state


@dataclass(frozen=True)
class LimitDistance:
    """The joint nearest to a position limit.

    Attributes:
        joint: its name.
        distance: to the nearer limit [rad | m] (0 at the limit).
        fraction: that distance over the joint's range (0 at the limit, 0.5 mid-range).
        side: ``lower`` or ``upper``.
    """

    joint: str
    distance: float
    fraction: float
    side: str


def nearest_limit(names, lower, upper, positions) -> LimitDistance | None:
    """The joint whose position is nearest to a limit, relative to its range (None: no finite limits).

    Args:
        names: joint names, length n.
        lower, upper: position limits [rad | m], shape (n,); infinite for none.
        positions: joint positions, shape (n,).
    """
    best: LimitDistance | None = None
    for name, low, high, q in zip(names, lower, upper, positions, strict=True):
        if not (math.isfinite(low) and math.isfinite(high)) or high <= low or not math.isfinite(q):
            continue
        to_low, to_high = q - low, high - q
        side, distance = ("lower", to_low) if to_low <= to_high else ("upper", to_high)
        fraction = distance / (high - low)
        if best is None or fraction < best.fraction:
            best = LimitDistance(name, max(distance, 0.0), max(fraction, 0.0), side)
    return best


def status_line(
    state: TeleopState,
    joint_names,
    tool_pose: np.ndarray | None,
    controller_state: str,
    limit: LimitDistance | None,
) -> str:
    """The one-line display: mode and command, speeds, tool pose, controller state, nearest limit."""
    if state.mode == "joint":
        name = joint_names[state.joint] if state.joint < len(joint_names) else str(state.joint + 1)
        command = f"joint {name} {state.jog():+.3f}"
        speeds = f"speed {state.joint_speed:.3g}"
    else:
        linear, angular = state.twist()
        frame = "tool" if state.tool_frame else "base"
        command = f"twist[{frame}] v {_vector(linear)} w {_vector(angular)}"
        speeds = f"speed {state.linear_speed:.3g} m/s {state.angular_speed:.3g} rad/s"
    if tool_pose is None:
        pose = "pose ?"
    else:
        rpy = matrix_to_rpy(tool_pose[:3, :3])
        pose = f"xyz {_vector(tool_pose[:3, 3])} rpy {_vector(rpy)}"
    limit_text = (
        f"nearest limit {limit.joint} {limit.side} {limit.distance:.3f} ({100 * limit.fraction:.0f}%)"
        if limit is not None
        else "nearest limit ?"
    )
    return f"{command} | {speeds} | {pose} | controller {controller_state or '?'} | {limit_text}"


def _vector(values) -> str:
    return "[" + " ".join(f"{float(v):+.3f}" for v in values) + "]"
