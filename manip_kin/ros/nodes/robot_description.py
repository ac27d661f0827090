"""One robot model, loudly: which ``robot_description`` a node uses, and what it does when another comes.

A node that reads its model from ``robot_description`` (transient local) may find several
publishers there: robot_state and a robot_state_publisher of the same arm (the same text:
fine), or two arms' descriptions in one namespace (different texts: which one is meant?).
:class:`DescriptionWatch`:

* **at start** (:meth:`DescriptionWatch.wait`) waits for the description and then
  :data:`SETTLE_S` more for the other publishers' (each latched description arrives once its
  publisher is discovered). One text, from any number of publishers: used. Different texts:
  refused (the node exits with code 2), naming each publisher's node and robot, until the
  parameter ``robot_description_publisher`` names the node to take it from.
* **while running** (:meth:`DescriptionWatch.follow`, a timer in the executor thread: the
  loop does no work for it) it logs a WARN once per different description that arrives (a
  changed one from the same publisher, or another publisher's), saying whether its joints
  match. The running model stays until the service ``~/reload_robot_description``
  (std_srvs/Trigger) is called: the node then loads the description chosen as at start and
  switches to it where it can (the reply says what happened or why not). When the arm's
  ``joint_states`` no longer carry the model's joints, the nodes reject them and hold the arm
  at rest, as for any stale joint state.

Publishers are told apart by the GID rcl gives with each message
(:class:`~manip_kin.ros.runtime.publisher_take.AttributedSubscription`).
"""

from __future__ import annotations

import hashlib
import re
import time
from collections.abc import Callable
from dataclasses import dataclass

from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from manip_kin.core.model import RobotModel
from manip_kin.errors import InvalidArgumentError, ManipKinError
from manip_kin.ros.runtime.publisher_take import AttributedSubscription

#: Seconds to wait, after the first description, for the other publishers' descriptions.
SETTLE_S = 0.25
#: Longest such wait [s] when a discovered publisher has sent nothing (not latched).
MAX_SETTLE_S = 2.0
#: Seconds between two "still waiting for robot_description" lines.
WAIT_LOG_PERIOD_S = 10.0
#: Period of the check for a new description while running [s].
FOLLOW_PERIOD_S = 0.5
#: Checks after a message whose sender is not on the graph (yet, or any more).
CHECK_RETRIES = 6
#: Publishers named in one message at most.
MAX_NAMED = 8

PARAMETER = "robot_description_publisher"
SERVICE = "~/reload_robot_description"


@dataclass(frozen=True)
class Description:
    """One publisher's newest robot description.

    Attributes:
        text: the URDF.
        publisher: its node, fully qualified (``/ns/name``); ``a publisher`` when unknown.
        digest: a short hash of the text (equal texts, equal digests).
    """

    text: str
    publisher: str
    digest: str

    @property
    def robot(self) -> str:
        """The ``<robot name>`` of the text (at most 60 characters), or ``?``."""
        match = re.search(r"<robot\b[^>]*?\bname\s*=\s*[\"']([^\"']{0,60})", self.text[:10000])
        return match.group(1) if match else "?"

    def summary(self) -> str:
        """``/node (robot 'name', N characters, digest)``."""
        return f"{self.publisher} (robot {self.robot!r}, {len(self.text)} characters, {self.digest})"


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8", "replace")).hexdigest()[:12]


def publisher_matches(wanted: str, publisher: str) -> bool:
    """True when ``wanted`` (``/ns/name``, ``ns/name`` or a bare ``name``) names ``publisher``."""
    wanted = wanted.strip()
    return wanted.lstrip("/") == publisher.lstrip("/") or ("/" not in wanted and publisher.rsplit("/", 1)[-1] == wanted)


def joints_problem(running: RobotModel, new: RobotModel) -> str | None:
    """Why a node on ``running`` cannot switch to ``new`` in place (other joints), or None."""
    if new.joint_names == running.joint_names:
        return None
    return (
        f"the new model {new.name!r} has other joints ({_listed(list(new.joint_names))}) than the running "
        f"{running.name!r} ({_listed(list(running.joint_names))}): restart the node to use it"
    )


def _listed(items: list[str]) -> str:
    shown = items[:MAX_NAMED]
    more = f" and {len(items) - MAX_NAMED} more" if len(items) > MAX_NAMED else ""
    return ", ".join(shown) + more


class DescriptionWatch:
    """The ``robot_description`` subscription of a node, for its whole life (see the module docstring).

    Args:
        node: the node.
        wanted: the ``robot_description_publisher`` parameter: the node to take the
            description from ("" = the one description there is).
    """

    def __init__(self, node: Node, wanted: str = ""):
        from std_msgs.msg import String

        self._node = node
        self.wanted = wanted
        self._string = String
        latched = QoSProfile(
            depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
        )
        self._subscription = AttributedSubscription(node, String, "robot_description", latched)
        self.topic = self._subscription.topic_name
        self._latest: dict[bytes | str, tuple[str, str]] = {}  # GID (or digest) -> (text, digest)
        self.running: Description | None = None
        self._warned: dict[str, str] = {}  # publisher -> digest already warned about
        self._load: Callable[[str], RobotModel] | None = None
        self._switch: Callable[[RobotModel], str | None] | None = None

    # --- what is there -----------------------------------------------------------------------------

    def poll(self) -> bool:
        """Take every message that arrived (the newest per publisher is kept); True when any did."""
        from rclpy.serialization import deserialize_message

        arrived = False
        while (taken := self._subscription.take()) is not None:
            arrived = True
            gid, data = taken
            try:
                text = deserialize_message(data, self._string).data
            except Exception:  # noqa: BLE001 - a malformed message is no description
                continue
            digest = _digest(text)
            self._latest[gid if gid is not None else digest] = (text, digest)
        return arrived

    def current(self) -> list[Description]:
        """The newest description of each publisher still on the graph (all received ones when
        publishers cannot be told apart)."""
        if not self._subscription.attributed:
            return [Description(text, "a publisher", digest) for text, digest in self._latest.values()]
        names = self._subscription.publishers()
        return [Description(text, names[gid], digest) for gid, (text, digest) in self._latest.items() if gid in names]

    def choose(self) -> Description | None:
        """The description to use now; None while there is none (or not yet the wanted one's).

        Raises:
            InvalidArgumentError: different descriptions and no (usable) ``robot_description_publisher``.
        """
        descriptions = self.current()
        if self.wanted and self._subscription.attributed:
            return next((d for d in descriptions if publisher_matches(self.wanted, d.publisher)), None)
        if len({d.digest for d in descriptions}) <= 1:
            return descriptions[0] if descriptions else None
        publishers = sorted(self._subscription.publishers().values())
        if not self._subscription.attributed:
            raise InvalidArgumentError(
                f"{len({d.digest for d in descriptions})} different robot descriptions on {self.topic} from "
                f"{_listed(publishers)}, and this rclpy cannot tell which node sent which "
                f"({self._subscription.problem}); stop all but one, or set parameter robot to the robot's file"
            )
        example = descriptions[0].publisher
        raise InvalidArgumentError(
            f"several publishers of {self.topic} send different robot descriptions: "
            f"{_listed([d.summary() for d in sorted(descriptions, key=lambda d: d.publisher)])}; "
            f"set parameter {PARAMETER} to the node to take it from (e.g. -p {PARAMETER}:={example}), "
            "or parameter robot to the robot's file"
        )

    # --- at start --------------------------------------------------------------------------------

    def wait(self) -> Description:
        """Wait for the description to use (see the module docstring); spins ``node`` on a
        private executor meanwhile (it is not yet on its main one).

        Raises:
            InvalidArgumentError: different descriptions (see :meth:`choose`).
            ExternalShutdownException: Ctrl-C or SIGTERM while waiting.
        """
        node = self._node
        source = f" from {self.wanted}" if self.wanted else ""
        node.get_logger().info(
            f"waiting for the robot model: a URDF on {self.topic}{source} (transient local, as "
            "robot_state_publisher publishes it); set parameter robot to load a bundled robot or a file instead"
        )
        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        started = time.monotonic()
        next_log = started + WAIT_LOG_PERIOD_S
        first = None
        try:
            while True:
                if not node.context.ok():
                    raise ExternalShutdownException()
                executor.spin_once(timeout_sec=0.05)
                self.poll()
                now = time.monotonic()
                if first is None and self._latest:
                    first = now
                if first is not None and (
                    (self.wanted and self._subscription.attributed) or self._settled(now - first)
                ):
                    chosen = self.choose()
                    if chosen is not None:
                        return chosen
                if now >= next_log:
                    next_log += WAIT_LOG_PERIOD_S
                    publishers = sorted(self._subscription.publishers().values())
                    node.get_logger().info(
                        f"still waiting for {self.topic}{source} after {now - started:.0f} s "
                        f"(publishers: {_listed(publishers) or 'none'})"
                    )
        finally:
            executor.remove_node(node)

    def _settled(self, waited: float) -> bool:
        if waited < SETTLE_S:
            return False
        if waited >= MAX_SETTLE_S or not self._subscription.attributed:
            return True
        return set(self._subscription.publishers()) <= set(self._latest)

    # --- while running ------------------------------------------------------------------------------

    def follow(
        self,
        running: Description,
        load: Callable[[str], RobotModel],
        switch: Callable[[RobotModel], str | None],
        model: RobotModel,
    ) -> None:
        """Watch for other descriptions while the node runs on ``running`` (its model ``model``).

        Args:
            running: the description in use.
            load: text -> model, as at start (the node's chain parameters).
            switch: ``switch(model) -> None`` once the node uses ``model``, or why it cannot.
            model: the running model.
        """
        from std_srvs.srv import Trigger

        self.running = running
        self._model = model
        self._load = load
        self._switch = switch
        self._warned = {running.publisher: running.digest}
        self._retries = 1  # the descriptions already taken while waiting are checked at once
        self._node.create_timer(FOLLOW_PERIOD_S, self._check)
        self._node.create_service(Trigger, SERVICE, self._reload)

    def close(self) -> None:
        """Stop watching: the description was read once."""
        self._subscription.destroy()

    def _check(self) -> None:
        """Timer: log each description that differs from the running one, once.

        Works only when a message came (or, a few times, when a sender was not yet on the graph).
        """
        try:
            if not self.poll() and self._retries <= 0:
                return
            descriptions = self.current()
            unresolved = len(descriptions) < len(self._latest)
            self._retries = (self._retries - 1 if self._retries > 0 else CHECK_RETRIES) if unresolved else 0
            if unresolved and self._retries == 0:
                self._forget_gone()
            for description in descriptions:
                if description.digest in (self.running.digest, self._warned.get(description.publisher)):
                    continue
                self._warned[description.publisher] = description.digest
                self._node.get_logger().warning(self._difference(description))
        except Exception as error:  # noqa: BLE001 - a watch must never end the executor
            self._node.get_logger().error(f"checking {self.topic} failed: {type(error).__name__}: {error}"[:400])

    def _forget_gone(self) -> None:
        """Drop the descriptions of publishers no longer on the graph (memory stays bounded)."""
        if self._subscription.attributed:
            present = self._subscription.publishers()
            self._latest = {gid: value for gid, value in self._latest.items() if gid in present}

    def _difference(self, description: Description) -> str:
        """The WARN line for a description that differs from the running one."""
        try:
            joints = self._load(description.text).joint_names
            if joints == self._model.joint_names:
                fit = "same joints"
            else:
                fit = (
                    f"its joints ({_listed(list(joints))}) differ from the running model's "
                    f"({_listed(list(self._model.joint_names))}): joint_states of that arm are rejected, and the "
                    "node then holds the arm at rest"
                )
        except ManipKinError as error:
            fit = f"it does not load here: {str(error)[:200]}"
        return (
            f"a different robot description on {self.topic} from {description.summary()} ({fit}); "
            f"keeping the running model {self._model.name!r} from {self.running.summary()}; call "
            f"{self._node.get_fully_qualified_name()}/{SERVICE[2:]} (std_srvs/Trigger) to switch"
        )

    def _reload(self, request, response):
        """Service: switch to the description chosen as at start."""
        try:
            self.poll()
            chosen = self.choose()
            if chosen is None:
                wanted = f" from {self.wanted}" if self.wanted else ""
                response.success, response.message = False, f"no robot description{wanted} on {self.topic}"
            elif chosen.digest == self.running.digest:
                response.success, response.message = True, f"already running {self.running.summary()}"
            else:
                model = self._load(chosen.text)
                problem = self._switch(model)
                if problem:
                    response.success, response.message = False, problem
                else:
                    previous = self._model.name
                    self.running, self._model = chosen, model
                    response.success = True
                    response.message = f"switched from {previous!r} to {model.name!r} from {chosen.summary()}"
                    self._node.get_logger().info(response.message)
        except Exception as error:  # noqa: BLE001 - an exception here would end the executor
            response.success, response.message = False, str(error) if isinstance(error, ManipKinError) else repr(error)
        response.message = response.message[:400]
        return response
