"""``cartesian_controller``'s services: ``~/stop`` (std_srvs/Trigger: come to rest, drop the goal)
and ``~/pause`` (std_srvs/SetBool: hold still keeping the goal, or resume it).

The service callbacks run in the executor thread and only queue the request (a deque is
thread-safe); the loop acts on it (:meth:`ControllerRequests.take`), so the state has one writer.
"""

from __future__ import annotations

from collections import deque

from std_srvs.srv import SetBool, Trigger

from manip_kin.control.state_machines import ControllerSupervisor


class ControllerRequests:
    """The ``~/stop`` and ``~/pause`` services of ``node``, queued for its loop."""

    def __init__(self, node):
        self._requests: deque[tuple[str, bool]] = deque()
        node.create_service(Trigger, "~/stop", self._on_stop)
        node.create_service(SetBool, "~/pause", self._on_pause)

    def take(self, supervisor: ControllerSupervisor) -> bool:
        """Act on the queued requests (in the loop thread); True when there was one."""
        acted = False
        while self._requests:
            kind, value = self._requests.popleft()
            if kind == "stop":
                supervisor.stop_requested()
            else:
                supervisor.pause_requested(value)
            acted = True
        return acted

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self._requests.append(("stop", True))
        response.success = True
        response.message = "stopping: the commands come to rest within the limits; the goal is dropped"
        return response

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        self._requests.append(("pause", bool(request.data)))
        response.success = True
        response.message = "pausing: holding still, the goal kept" if request.data else "resuming the goal"
        return response
