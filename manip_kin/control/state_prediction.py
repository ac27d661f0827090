"""Which joint state a command will act on: compensating the state → command → robot delay.

A controller in another process than the robot computes its command from a joint state
that is already old, and the robot applies that command one or two of its cycles later.
The command ``q̇ = J(q)⁺ v`` is then right for where the arm *was*, and the arm, having
moved on, follows ``J(q_now) J(q)⁺ v``: a velocity error of about ``v·(v/L)·δ`` for a
delay δ and a lever L, which the position gain K turns into a steady lag beside a line
of ``v²δ/(L·K)``. On the irb120 line at 0.4 m/s, K = 6/s and 1 kHz, simulated offline
(``test_state_prediction``): 0.06 mm beside the line when the command acts one period
after the state, 0.17 mm after two (which of the two depends on the phase of the loops),
and a few µm with the prediction below.

The cure: evaluate the law at the state the command will act on. The robot model is
robot_state's (and that of most simulators): the robot runs a cycle on the grid of its
state stamps; at each cycle it drives the arm over the period that ends at that cycle's
stamp with the newest command it holds. A command published now is at the robot
``command_latency`` later, so it drives the period ending at the first stamp after
that, and the state it acts on is the one in the middle of that period. A robot that
stamps a state *before* its cycle's command takes effect (ros2_control's read → update
→ write) is the same model with one period more of command latency.

The goal the law compares the state with must be for the same instant:
:mod:`manip_kin.control.streamed_goal`.
"""

from __future__ import annotations

import math

import numpy as np

from manip_kin.core.plain_floats import float_list

__all__ = [
    "MAX_STATE_AGE_PERIODS",
    "PLAUSIBLE_RATE_FACTOR",
    "command_horizon",
    "predict_positions",
    "prediction_horizon",
    "state_for_command",
]

#: A state older than this many periods (or stamped more than one period in the future: clocks
#: that disagree) is used as it is: a prediction from it would be a guess.
MAX_STATE_AGE_PERIODS = 10

#: A reported joint velocity beyond this multiple of the joint's velocity limit is not believed
#: (a robot overshoots its limit a little, not twice over).
PLAUSIBLE_RATE_FACTOR = 2.0


def command_horizon(state_age: float, period: float, command_latency: float) -> float:
    """Time from a joint state's stamp to the middle of the period a command sent now drives [s].

    Args:
        state_age: now − the state's stamp [s]; negative (clock skew) counts as 0.
        period: the robot's cycle [s], > 0.
        command_latency: from sending a command to the robot holding it [s], >= 0.

    Returns:
        ``(k − ½)·period`` with ``k >= 1`` the number of robot cycles from the stamp to the
        first one after the command arrives.
    """
    cycles = max(math.ceil((max(state_age, 0.0) + command_latency) / period), 1)
    return (cycles - 0.5) * period


def predict_positions(q, qdot, horizon: float, lower, upper) -> np.ndarray:
    """Joint positions ``horizon`` seconds on at the rates ``qdot``, within the position limits.

    Args:
        q: joint positions [rad | m], shape (n,).
        qdot: joint rates [rad/s | m/s], shape (n,).
        horizon: [s], >= 0.
        lower, upper: position limits, shape (n,).

    Returns:
        ``q + qdot·horizon``, shape (n,), stopped at a limit it would cross; a joint already
        outside its limits (a reported state may be, by a margin) is not moved onto them.
    """
    predicted = []
    for position, rate, low, high in zip(float_list(q), float_list(qdot), float_list(lower), float_list(upper)):
        value = position + rate * horizon
        # clamp to [min(low, position), max(high, position)]
        if value > high:
            value = high if position <= high else min(value, position)
        elif value < low:
            value = low if position >= low else max(value, position)
        predicted.append(value)
    return np.array(predicted)


def state_for_command(
    q, qdot, state_age: float, period: float, command_latency: float, lower, upper, max_rate
) -> np.ndarray:
    """The joint positions a command sent now acts on (see the module text), shape (n,).

    Args:
        q: reported joint positions [rad | m], shape (n,).
        qdot: reported joint velocities [rad/s | m/s], shape (n,), or None.
        state_age: now − the state's stamp [s], on the clock that stamped it.
        period: the robot's cycle [s], > 0.
        command_latency: [s], >= 0 (see :func:`command_horizon`).
        lower, upper: position limits, shape (n,).
        max_rate: largest plausible |velocity| per joint, shape (n,).

    Returns:
        The predicted positions; ``q`` itself when there are no velocities, when one is
        not finite or above ``max_rate``, or when the age is outside
        ``[-period, MAX_STATE_AGE_PERIODS·period]``.
    """
    horizon = prediction_horizon(qdot, state_age, period, command_latency, max_rate)
    return q if horizon is None else predict_positions(q, qdot, horizon, lower, upper)


def prediction_horizon(qdot, state_age: float, period: float, command_latency: float, max_rate) -> float | None:
    """:func:`command_horizon` [s] for a state with these velocities and age, or None where
    :func:`state_for_command` uses the state as it is (see there for the arguments)."""
    if qdot is None or not -period <= state_age <= MAX_STATE_AGE_PERIODS * period:
        return None
    for rate, limit in zip(float_list(qdot), float_list(max_rate)):
        if not abs(rate) <= limit:  # False for NaN too
            return None
    return command_horizon(state_age, period, command_latency)
