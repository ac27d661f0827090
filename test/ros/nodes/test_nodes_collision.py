"""cartesian_controller with collision_avoidance on an arm that holds its last command (test/support/held_arm.py).

Every distance the tests assert is computed here, independently of the controller's code path:
closed forms for the ball arm's spheres against a box (test/support/collision_robots.py), fresh coal
objects for the Panda's hand and link 1; over every position the fake arm integrated.
"""

import ctypes
import math
import os
import re
import shutil
import time

import numpy as np
import pytest
from collision_robots import (
    BALL_ARM_SPHERES,
    BALL_ARM_URDF,
    PANDA_FOLDED,
    PANDA_READY,
    ball_centres,
    fresh_hand_link1_distance,
    panda_files,
    point_box_distance,
)
from fake_hardware import FakeHardware
from geometry_msgs.msg import PoseStamped, TwistStamped
from held_arm import send_goal, start_held_arm
from node_harness import Harness, statuses
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import Marker, MarkerArray

from manip_kin.core.kinematics import frame_pose
from manip_kin.core.robots import load_robot
from manip_kin.motion.joint_trajectory import TrajectoryPoint
from manip_kin.pipeline.outcome import goal_outcome
from manip_kin.ros.nodes.cartesian_controller import CartesianControllerNode
from manip_kin.ros.nodes.collision_inputs import MARKER_NS
from manip_kin.ros.nodes.trajectory_generator import TrajectoryGeneratorNode
from manip_kin.ros.wire.joint_messages import make_joint_trajectory
from manip_kin.ros.wire.messages import make_pose_stamped, make_twist_stamped

SAFETY = 0.02
START_Q, GOAL_Q = np.array([-0.6, 0.4, 0.8]), np.array([0.6, 0.4, 0.8])
BOX_EXTENTS = (0.08, 0.08, 0.08)
# The arm stops moving on a command after this [s], below the damper's hold time (0.16 s at the
# default distances and gain): a loop stalled longer cannot then take a pair within the safety
# distance (test_a_stall_within_the_arms_command_timeout_keeps_the_safety_distance).
ARM_COMMAND_TIMEOUT = 0.1


@pytest.fixture
def harness():
    h = Harness()
    yield h
    h.close()


@pytest.fixture(scope="module")
def ball_urdf(tmp_path_factory):
    path = tmp_path_factory.mktemp("ball") / "ball_arm.urdf"
    path.write_text(BALL_ARM_URDF)
    return str(path)


def _box_marker(centre, extents, frame="base_link", key=("cell", 1)) -> MarkerArray:
    marker = Marker()
    marker.header.frame_id = frame
    marker.ns, marker.id = key
    marker.type, marker.action = Marker.CUBE, Marker.ADD
    marker.pose.position.x, marker.pose.position.y, marker.pose.position.z = (float(v) for v in centre)
    marker.pose.orientation.w = 1.0
    marker.scale.x, marker.scale.y, marker.scale.z = extents
    return MarkerArray(markers=[marker])


def _ball_box_distance(model, q, centre, extents) -> float:
    """The nearest of the ball arm's moving spheres to an axis-aligned box, in closed form [m]."""
    return min(point_box_distance(c, centre, extents) - r for _, c, r in ball_centres(model, q))


def _last_values(diagnostics, node) -> tuple[str, dict]:
    found = statuses(diagnostics, node.status_name)
    if not found:
        return "", {}
    return found[-1].message, {kv.key: kv.value for kv in found[-1].values}


def _reported(harness, diagnostics, node, state: str) -> tuple[str, dict]:
    """The first status of ``node`` in ``state`` (waited for)."""
    assert harness.spin_until(lambda: _last_values(diagnostics, node)[0] == state, 3)
    return _last_values(diagnostics, node)


def test_obstacle_on_the_path_is_kept_at_the_safety_distance_and_a_goal_beside_it_is_reached(harness, ball_urdf):
    model = load_robot(ball_urdf)
    start, goal = frame_pose(model, START_Q), frame_pose(model, GOAL_Q)
    centre = 0.5 * (start[:3, 3] + goal[:3, 3])  # on the straight path of the tool
    assert _ball_box_distance(model, START_Q, centre, BOX_EXTENTS) > 0.05
    model, hardware, node, diagnostics = start_held_arm(
        harness,
        ball_urdf,
        START_Q,
        arm_command_timeout=ARM_COMMAND_TIMEOUT,
        collision_avoidance=True,
        collision_safety_distance=SAFETY,
        collision_pair_samples=100,
        task="position",
        gain_linear=3.0,
    )
    try:
        markers = harness.collect(MarkerArray, f"{node.test_namespace}/markers")
        topic = f"{node.test_namespace}/collision_objects"
        harness.wait_matched(topic, MarkerArray)
        harness.publish(topic, _box_marker(centre, BOX_EXTENTS))
        assert harness.spin_until(lambda: len(node.collision.scene) == 1, 3)
        stamp = send_goal(harness, node, goal)  # straight through the box
        assert harness.spin_until(lambda: node.state == "blocked", 10), (node.state, node.detail)
        assert "obstacle:cell/1" in node.detail
        state, values = _reported(harness, diagnostics, node, "blocked")
        outcome = goal_outcome(values, state, stamp)
        assert outcome.word == "blocked" and outcome.exit_code == 1 and "obstacle:cell/1" in outcome.reason
        held_off = np.linalg.norm(frame_pose(model, hardware.positions())[:3, 3] - goal[:3, 3])
        assert float(values["position_error"]) == pytest.approx(held_off, abs=2e-3)  # where it was held off
        assert values["nearest_pair"].endswith("obstacle:cell/1")
        assert float(values["nearest_distance"]) == pytest.approx(SAFETY, abs=5e-3)
        # On a 250 Hz loop: at least one period, and at most the 30 ms a sample is held to.
        assert 1.0 <= float(values["command_drive_periods"]) <= 0.03 * 250
        assert harness.spin_until(lambda: node.command_filter.at_rest, 3)  # blocked: at rest
        ours = [m for msg in markers for m in msg.markers if m.ns == MARKER_NS and m.action == Marker.ADD]
        assert ours and ours[-1].type == Marker.LINE_LIST and len(ours[-1].points) == 2
        # A goal beside the box, its spheres 3.5 cm beyond the safety distance from it: reached.
        beside_q = np.array([0.0, 0.2, 0.8])
        assert _ball_box_distance(model, beside_q, centre, BOX_EXTENTS) > SAFETY + 0.03
        beside = frame_pose(model, beside_q)
        send_goal(harness, node, beside)
        assert harness.spin_until(lambda: node.state == "converged", 10), (node.state, node.detail)
        np.testing.assert_allclose(frame_pose(model, hardware.positions())[:3, 3], beside[:3, 3], atol=5e-4)
        nearest = min(_ball_box_distance(model, q, centre, BOX_EXTENTS) for q in list(hardware.history))
        assert nearest >= SAFETY - 1e-3, nearest
        assert nearest < SAFETY + 0.01  # it did go up to the box
    finally:
        hardware.close()


def _ball_arm_before_the_box(harness, ball_urdf, speed: float = 0.1, **params):
    """The ball arm with collision avoidance (and ``params``) and the box on the straight path
    between START_Q and GOAL_Q, taken by the controller: ``(model, hardware, node, centre,
    send)``; ``send()`` publishes one twist of ``speed`` [m/s] towards the box."""
    model = load_robot(ball_urdf)
    start, goal = frame_pose(model, START_Q), frame_pose(model, GOAL_Q)
    centre = 0.5 * (start[:3, 3] + goal[:3, 3])
    model, hardware, node, _ = start_held_arm(
        harness,
        ball_urdf,
        START_Q,
        arm_command_timeout=ARM_COMMAND_TIMEOUT,
        collision_avoidance=True,
        collision_pair_samples=100,
        task="position",
        **params,
    )
    try:
        topic = f"{node.test_namespace}/collision_objects"
        harness.wait_matched(topic, MarkerArray)
        harness.publish(topic, _box_marker(centre, BOX_EXTENTS))
        assert harness.spin_until(lambda: len(node.collision.scene) == 1, 3)
        towards = speed * (goal[:3, 3] - start[:3, 3]) / np.linalg.norm(goal[:3, 3] - start[:3, 3])
        twist_topic = f"{node.test_namespace}/twist_command"
        harness.wait_matched(twist_topic, TwistStamped)
    except BaseException:
        hardware.close()
        raise

    def send():
        stamp = harness.node.get_clock().now().to_msg()
        harness.publish(twist_topic, make_twist_stamped((0, 0, 0), towards, "base_link", stamp))

    return model, hardware, node, centre, send


def test_a_twist_command_into_the_box_stops_at_the_safety_distance(harness, ball_urdf):
    model, hardware, _, centre, send = _ball_arm_before_the_box(harness, ball_urdf)
    try:
        harness.spin_for(3.0, every=send)  # 0.3 m of commanded travel: the box is 0.1 m away
        distances = [_ball_box_distance(model, q, centre, BOX_EXTENTS) for q in list(hardware.history)]
        assert min(distances) >= SAFETY - 1e-3, min(distances)
        assert distances[-1] < SAFETY + 0.01  # it went up to the box
    finally:
        hardware.close()


@pytest.mark.parametrize("speed, acceleration", [(0.5, 1.0), (0.1, 0.3)])
def test_soft_joint_limits_still_stop_a_twist_at_the_safety_distance(harness, ball_urdf, speed, acceleration):
    # The command filter stops a joint from full speed in 2 s (1 rad/s²) or 6.7 s (0.3 rad/s²):
    # with dampers that took the rates as applied at once, the ball went 14 and 17 mm into the
    # box; with the filter's stop counted but not its stretch under load (a loop that runs late
    # drives each command longer), 20 mm into it beside eight busy processes.
    slow = {f"joint_limits.{joint}.max_acceleration": acceleration for joint in ("j1", "j2", "j3")}
    model, hardware, _, centre, send = _ball_arm_before_the_box(harness, ball_urdf, speed, **slow)
    try:
        harness.spin_for(4.0, every=send)
        distances = [_ball_box_distance(model, q, centre, BOX_EXTENTS) for q in list(hardware.history)]
        assert min(distances) >= SAFETY - 1e-3, min(distances)
        assert distances[-1] < SAFETY + 0.01  # it went up to the box
    finally:
        hardware.close()


def _stall_the_process(seconds: float) -> None:
    """Every thread of this process stopped for ``seconds``: libc's usleep called with the GIL
    held (ctypes.PyDLL keeps it), as a publish that stalls inside rcl does
    (docs/performance_limits.md). The controller's loop and the fake arm's thread both stop;
    the arm then integrates the command it held over the whole interval, up to its timeout."""
    ctypes.PyDLL(None).usleep(int(seconds * 1e6))


def test_a_stall_within_the_arms_command_timeout_keeps_the_safety_distance(harness, ball_urdf):
    # The damper lets a pair close at (d - d_s) / hold_time at most, so an arm that stops moving
    # on a command after a timeout below hold_time cannot be taken within d_s by a stall of any
    # length. Stalled 0.4 s where the damper binds (d ~ 0.03 m): a held-forever arm closes
    # 25 mm there (through d_s), one with a 0.2 s timeout 12.5 mm (past d_s - 1 mm).
    model, hardware, node, centre, send = _ball_arm_before_the_box(harness, ball_urdf)
    try:
        hold_time = node.law.qp.collision_limit.hold_time
        assert hold_time == pytest.approx((0.10 - SAFETY) / 0.5) and ARM_COMMAND_TIMEOUT < hold_time
        stalled_at = None
        deadline = time.monotonic() + 4.0
        while time.monotonic() < deadline:
            send()
            harness.spin_for(0.004)
            distance = _ball_box_distance(model, hardware.positions(), centre, BOX_EXTENTS)
            if stalled_at is None and distance < 0.03:
                stalled_at = distance
                _stall_the_process(0.4)
        assert stalled_at is not None and stalled_at > 0.028, stalled_at  # where the damper binds
        distances = [_ball_box_distance(model, q, centre, BOX_EXTENTS) for q in list(hardware.history)]
        assert min(distances) >= SAFETY - 1e-3, (min(distances), stalled_at)
        assert distances[-1] < SAFETY + 0.01  # it went on up to the box
    finally:
        hardware.close()


def test_without_collision_avoidance_the_same_goal_drives_through_the_box(harness, ball_urdf):
    model = load_robot(ball_urdf)
    start, goal = frame_pose(model, START_Q), frame_pose(model, GOAL_Q)
    centre = 0.5 * (start[:3, 3] + goal[:3, 3])
    model, hardware, node, _ = start_held_arm(harness, ball_urdf, START_Q, task="position", gain_linear=3.0)
    try:
        assert node.law is node.controller  # the plain law's fast path
        send_goal(harness, node, goal)
        assert harness.spin_until(lambda: node.state == "converged", 10), (node.state, node.detail)
        assert min(_ball_box_distance(model, q, centre, BOX_EXTENTS) for q in list(hardware.history)) < 0.0
    finally:
        hardware.close()


def test_a_self_collision_goal_on_the_panda_ends_blocked_without_contact(harness):
    urdf, srdf, share = panda_files()
    model, hardware, node, diagnostics = start_held_arm(
        harness,
        str(urdf),
        PANDA_READY,
        collision_avoidance=True,
        srdf=str(srdf),
        mesh_search_path=share,
        gain_linear=2.0,
        gain_angular=2.0,
    )
    try:
        goal = frame_pose(model, PANDA_FOLDED, "ee")  # the hand 4.7 cm into link 1
        stamp = send_goal(harness, node, goal, model.base_frame)
        assert harness.spin_until(lambda: node.state == "blocked", 15), (node.state, node.detail)
        assert "panda_link1-panda_hand" in node.detail
        assert harness.spin_until(lambda: node.command_filter.at_rest, 3)
        history = list(hardware.history)
        nearest = min(fresh_hand_link1_distance(model, q) for q in history[:: max(1, len(history) // 200)])
        assert nearest > SAFETY - 2e-3, nearest
        state, values = _reported(harness, diagnostics, node, "blocked")
        assert goal_outcome(values, state, stamp).exit_code == 1
        assert values["nearest_pair"] == "panda_link1-panda_hand"
        assert math.isfinite(float(values["nearest_distance"]))
        assert values["qp_fallbacks"] == "0" and values["qp_status"]
        # This machine has a C++ compiler: the controller runs coal from C++.
        assert values["narrow_phase"] == ("native" if shutil.which("c++") else "python")
    finally:
        hardware.close()


def test_the_collision_geometry_comes_from_robot_description_when_robot_is_empty(harness):
    namespace = f"/description_{os.getpid()}"
    hardware = FakeHardware(BALL_ARM_URDF, START_Q, rate_hz=200.0, namespace=namespace)
    try:
        node = harness.start(
            CartesianControllerNode,
            namespace=namespace,
            robot="",
            collision_avoidance=True,
            collision_pair_samples=100,
            task="position",
        )
        # The URDF's <collision> elements: the base box, link1's cylinder, the two spheres.
        shapes = {g.link: str(g.shape.kind) for g in node.collision.checker.collision_model.geometries}
        assert shapes == {"base_link": "box", "link1": "cylinder", "link2": "sphere", "link3": "sphere"}
        assert node.law is not node.controller
    finally:
        hardware.close()


def test_a_bundled_yaml_robot_with_collision_avoidance_is_refused_at_start(harness):
    with pytest.raises(Exception, match="collision_avoidance needs the robot's URDF"):
        harness.start(CartesianControllerNode, robot="genova7", collision_avoidance=True)


def _first_tip_contact(start, goal, centre, extents, clearance) -> float:
    """Where along the tool's straight line the tip sphere (centred on the tool) first comes
    nearer than ``clearance`` to the box, in closed form (bisection on the line) [0..1]."""
    radius = BALL_ARM_SPHERES[-1][2]
    fractions = np.linspace(0.0, 1.0, 100001)
    points = start[None, :] + fractions[:, None] * (goal - start)[None, :]
    outside = np.maximum(np.abs(points - centre) - 0.5 * np.asarray(extents), 0.0)
    near = np.flatnonzero(np.linalg.norm(outside, axis=1) - radius < clearance)
    return float(fractions[near[0]])


def test_the_generator_refuses_a_line_and_a_joint_trajectory_through_a_box(harness, ball_urdf):
    model = load_robot(ball_urdf)
    start, goal = frame_pose(model, START_Q), frame_pose(model, GOAL_Q)
    centre = 0.5 * (start[:3, 3] + goal[:3, 3])
    namespace = f"/generator_{os.getpid()}"
    hardware = FakeHardware(BALL_ARM_URDF, START_Q, rate_hz=200.0, namespace=namespace)
    try:
        node = harness.start(
            TrajectoryGeneratorNode,
            namespace=namespace,
            robot=ball_urdf,
            collision_check=True,
            collision_safety_distance=SAFETY,
            task="position",
        )
        topic = f"{namespace}/collision_objects"
        harness.wait_matched(topic, MarkerArray)
        harness.publish(topic, _box_marker(centre, BOX_EXTENTS))
        assert harness.spin_until(lambda: len(node.path_check.scene_input.scene) == 1, 3)
        harness.wait_matched(f"{namespace}/line_target", PoseStamped)
        # The generator reads the newest joint state when a target comes: let the arm's arrive first.
        assert harness.spin_until(lambda: hardware._joint_states.get_subscription_count() > 0, 5)
        harness.spin_for(0.1)
        harness.publish(
            f"{namespace}/line_target",
            make_pose_stamped(goal, "base_link", harness.node.get_clock().now().to_msg()),
        )
        assert harness.spin_until(lambda: node.supervisor.rejected_targets == 1, 5), node.state
        reason = node.supervisor.last_rejection
        found = re.search(r"at (\d+) % of the way", reason)
        assert found, reason
        percent = float(found.group(1))
        expected = 100.0 * _first_tip_contact(start[:3, 3], goal[:3, 3], centre, BOX_EXTENTS, SAFETY)
        assert abs(percent - expected) <= 3.0, (reason, expected)  # samples every centimetre of 41 cm
        assert "link3 and obstacle:cell/1" in reason and node.supervisor.rejection_kind == "unreachable"
        # The same motion as a joint trajectory: j1 sweeps from -0.6 to 0.6 through the box too.
        harness.wait_matched(f"{namespace}/joint_trajectory", JointTrajectory)
        trajectory = make_joint_trajectory(model.joint_names, [TrajectoryPoint(2.0, GOAL_Q.tolist())])
        trajectory.header.stamp = harness.node.get_clock().now().to_msg()
        harness.publish(f"{namespace}/joint_trajectory", trajectory)
        assert harness.spin_until(lambda: node.supervisor.rejected_targets == 2, 5), node.state
        assert "joint trajectory not free of collision" in node.supervisor.last_rejection
        assert "% of the way" in node.supervisor.last_rejection and "obstacle:cell/1" in node.supervisor.last_rejection
        # Without the box both are free: the line starts.
        clear = MarkerArray(markers=[Marker(action=Marker.DELETEALL)])
        harness.publish(topic, clear)
        assert harness.spin_until(lambda: len(node.path_check.scene_input.scene) == 0, 3)
        harness.publish(
            f"{namespace}/line_target",
            make_pose_stamped(goal, "base_link", harness.node.get_clock().now().to_msg()),
        )
        assert harness.spin_until(lambda: node.state == "streaming", 5), node.supervisor.last_rejection
    finally:
        hardware.close()


def test_collision_objects_are_polled_every_scene_poll_period_not_every_cycle():
    """An empty poll costs a 1 kHz loop more than the scene's changes are worth: the loop takes
    collision_objects every SCENE_POLL_NS, and then every queued array."""
    from types import SimpleNamespace

    from manip_kin.ros.nodes import scene_input

    class Queue:
        def __init__(self):
            self.polls, self.queued = 0, []

        def take(self):
            self.polls += 1
            return self.queued.pop(0) if self.queued else None

    taker = scene_input.SceneInput.__new__(scene_input.SceneInput)  # no node: the polling only
    taker.subscription, taker._next_poll_ns, taker.refused = Queue(), 0, 0
    taker.checker = SimpleNamespace(update_scene=lambda scene: False, scene_problems=())
    taker.scene = None
    start = time.monotonic_ns()
    for _ in range(200):
        taker.take()
    elapsed = time.monotonic_ns() - start
    assert elapsed < scene_input.SCENE_POLL_NS  # else the machine was too slow to tell
    assert taker.subscription.polls == 1  # one empty poll in 200 cycles within a period
    time.sleep(scene_input.SCENE_POLL_NS * 1e-9)
    taker.take()
    assert taker.subscription.polls == 2
