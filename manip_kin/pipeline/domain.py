"""DDS isolation for the processes this package starts: the discovery range and a free domain.

Every process started by :class:`~manip_kin.pipeline.supervisor.Pipeline`, the demo, the
tests and the benchmark runs with ``ROS_AUTOMATIC_DISCOVERY_RANGE`` and ``ROS_DOMAIN_ID``
set; when the caller set neither, :func:`ensure_ros_isolation` picks LOCALHOST and a free
domain for this process and its children (a caller's values are never overridden, so a
user who runs the nodes across machines with ``SUBNET`` keeps it).

A picked domain stays reserved while the process that picked it lives (a lock file per
domain in the temp directory): a test session between two tests has no participant on its
domain, and a benchmark started then once took the same one, mixing the two runs' topics.
"""

from __future__ import annotations

import fcntl
import os
import random
import socket
import tempfile
from collections.abc import Iterable, Mapping

from manip_kin.pipeline.errors import PipelineError

#: Lock files of the domains this process reserved, by domain; open until the process ends.
_reserved: dict[int, int] = {}


def _lock_path(domain_id: int) -> str:
    return os.path.join(tempfile.gettempdir(), f"manip_kin_ros_domain_{domain_id}.lock")


def _reserve(domain_id: int) -> bool:
    """Take the machine-wide lock on ``domain_id`` for the rest of this process; False when
    another process (or this one, earlier) holds it."""
    try:
        descriptor = os.open(_lock_path(domain_id), os.O_RDONLY | os.O_CREAT, 0o444)
    except OSError:  # an unusable temp directory: the participant probe alone decides
        return True
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(descriptor)
        return False
    _reserved[domain_id] = descriptor
    return True


def _release(domain_id: int) -> None:
    descriptor = _reserved.pop(domain_id, None)
    if descriptor is not None:
        os.close(descriptor)


def _domain_is_free(domain_id: int) -> bool:
    # Fast DDS binds the first participant's unicast discovery port to 7410 + 250 * domain.
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", 7410 + 250 * domain_id))
        except OSError:
            return False
    return True


def pick_free_domain(exclude: Iterable[str] = ()) -> int:
    """A random ``ROS_DOMAIN_ID`` in 1..100 that no local participant uses and no other
    manip_kin process reserved; it stays reserved while this process lives.

    Raises:
        PipelineError: every domain is taken (sharing one would mix two runs' topics).
    """
    excluded = {str(d) for d in exclude}
    candidates = [d for d in range(1, 101) if str(d) not in excluded]
    random.SystemRandom().shuffle(candidates)
    for domain_id in candidates:
        if not _reserve(domain_id):
            continue
        if _domain_is_free(domain_id):
            return domain_id
        _release(domain_id)
    raise PipelineError("no free ROS_DOMAIN_ID in 1..100 on this machine")


#: Fast DDS's variables naming an XML profiles file; a caller's own file is never replaced.
FAST_DDS_PROFILE_VARIABLES = ("FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")

#: The heartbeat period of a client's reliable writers [s] (Fast DDS's default: 3 s).
CLIENT_HEARTBEAT_PERIOD_S = 0.02

_CLIENT_PROFILE = f"""<?xml version="1.0" encoding="UTF-8" ?>
<!-- manip_kin's clients (CLI, PipelineClient): reliable writers announce their samples every
     {CLIENT_HEARTBEAT_PERIOD_S * 1e3:g} ms, so a reader's acknowledgement comes without a wait of up to 3 s. -->
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <data_writer profile_name="manip_kin_client_writer" is_default_profile="true">
    <times>
      <heartbeatPeriod><sec>0</sec><nanosec>{round(CLIENT_HEARTBEAT_PERIOD_S * 1e9)}</nanosec></heartbeatPeriod>
    </times>
  </data_writer>
</profiles>
"""


def _client_profile_location() -> str:
    return os.path.join(tempfile.gettempdir(), f"manip_kin_fastdds_client_{os.getuid()}.xml")


def client_profile_path() -> str:
    """The Fast DDS profile of :data:`CLIENT_HEARTBEAT_PERIOD_S`, written once to the temp dir."""
    path = _client_profile_location()
    try:
        with open(path, encoding="utf-8") as existing:
            if existing.read() == _CLIENT_PROFILE:
                return path
    except OSError:
        pass
    partial = f"{path}.{os.getpid()}.tmp"
    with open(partial, "w", encoding="utf-8") as out:
        out.write(_CLIENT_PROFILE)
    os.replace(partial, path)
    return path


def use_prompt_acknowledgements(environ: dict | None = None) -> dict:
    """Give this process's Fast DDS writers a heartbeat of :data:`CLIENT_HEARTBEAT_PERIOD_S`.

    A reliable reader acknowledges a sample when the writer's heartbeat asks, and Fast DDS's
    default period is 3 s: a client that waits until its goal is acknowledged
    (:meth:`~manip_kin.pipeline.client.PipelineClient.publish_delivered`) waited 2.6 to 3.0 s
    per message, 11 to 39 ms with this (docs/performance.md). Only for rmw_fastrtps, only where
    the caller named no profile file, and only before the process's first participant (Fast
    DDS reads the file once). The nodes do not get it (:func:`node_environment`).

    Returns:
        ``environ`` (default ``os.environ``).
    """
    environ = os.environ if environ is None else environ
    if environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp") != "rmw_fastrtps_cpp":
        return environ
    if any(environ.get(name) for name in FAST_DDS_PROFILE_VARIABLES):
        return environ
    try:
        environ[FAST_DDS_PROFILE_VARIABLES[0]] = client_profile_path()
    except OSError:  # an unusable temp directory: acknowledgements come at Fast DDS's own pace
        pass
    return environ


def node_environment(environ: Mapping[str, str]) -> dict:
    """``environ`` for a node process: without the client profile of :func:`use_prompt_acknowledgements`
    (a node keeps Fast DDS's defaults; a caller's own profile file stays)."""
    env = dict(environ)
    for name in FAST_DDS_PROFILE_VARIABLES:
        if env.get(name) == _client_profile_location():
            del env[name]
    return env


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
