"""DDS isolation for the processes this package starts: the discovery range and a free domain.

Every process started by :class:`~manip_kin.pipeline.supervisor.Pipeline`, the demo, the
tests and the benchmark runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE`` and ``ROS_DOMAIN_ID``
set; when the caller set neither, :func:`ensure_ros_isolation` picks LOCALHOST and a free
domain for this process and its children (a caller's values are never overridden, so a
user who runs the nodes across machines with ``SUBNET`` keeps it).
"""

from __future__ import annotations

import os
import random
import socket
from collections.abc import Iterable, Mapping

from manip_kin.pipeline.errors import PipelineError


def _domain_is_free(domain_id: int) -> bool:
    # Fast DDS binds the first participant's unicast discovery port to 7410 + 250 * domain.
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", 7410 + 250 * domain_id))
        except OSError:
            return False
    return True


def pick_free_domain(exclude: Iterable[str] = ()) -> int:
    """A random ``ROS_DOMAIN_ID`` in 1..100 that no local participant uses.

    Raises:
        PipelineError: every domain is taken (sharing one would mix two runs' topics).
    """
    excluded = {str(d) for d in exclude}
    candidates = [d for d in range(1, 101) if str(d) not in excluded]
    random.SystemRandom().shuffle(candidates)
    for domain_id in candidates:
        if _domain_is_free(domain_id):
            return domain_id
    raise PipelineError("no free ROS_DOMAIN_ID in 1..100 on this machine")


def ensure_ros_isolation(environ: dict | None = None) -> dict:
    """Set ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` and a free ``ROS_DOMAIN_ID`` where unset.

    Args:
        environ: the environment to complete (default ``os.environ``, so that this
            process's own rclpy and every child inherit it).

    Returns:
        The same mapping.
    """
    environ = os.environ if environ is None else environ
    environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if not environ.get("ROS_DOMAIN_ID"):
        environ["ROS_DOMAIN_ID"] = str(pick_free_domain())
    return environ


def fresh_domain_env(environ: Mapping[str, str] | None = None) -> dict:
    """A copy of ``environ`` (default ``os.environ``) on a free ``ROS_DOMAIN_ID`` of its own.

    For two pipelines alive at once that must not see each other (two pipelines that
    should share a domain go into two namespaces instead).
    """
    env = dict(os.environ if environ is None else environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    env["ROS_DOMAIN_ID"] = str(pick_free_domain(exclude=[env.get("ROS_DOMAIN_ID", "")]))
    return env
