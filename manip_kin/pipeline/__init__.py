"""Run the manip_kin nodes without ``ros2 launch`` and talk to them from Python.

* :mod:`~manip_kin.pipeline.domain`: DDS isolation (discovery range, a free domain id);
* :mod:`~manip_kin.pipeline.node_process`: :class:`NodeProcess`, what is run, and
  :func:`pipeline_processes`, the pipeline nodes of a robot;
* :mod:`~manip_kin.pipeline.supervisor`: :class:`Pipeline`, node processes started and
  stopped together, optionally in a namespace;
* :mod:`~manip_kin.pipeline.client`: :class:`PipelineClient`, an rclpy node that sends goals
  and line targets and follows ``/diagnostics``.

None of these imports rclpy at import time (test/conftest.py sets the environment first).
"""

from manip_kin.pipeline.client import PipelineClient
from manip_kin.pipeline.domain import ensure_ros_isolation, fresh_domain_env, pick_free_domain
from manip_kin.pipeline.errors import PipelineError
from manip_kin.pipeline.node_process import (
    IRB120_LINE_GENERATOR,
    PIPELINE_NODES,
    NodeProcess,
    find_executable,
    pipeline_processes,
)
from manip_kin.pipeline.status import Status, normalize_namespace, status_name
from manip_kin.pipeline.supervisor import Pipeline

__all__ = [
    "IRB120_LINE_GENERATOR",
    "PIPELINE_NODES",
    "NodeProcess",
    "Pipeline",
    "PipelineClient",
    "PipelineError",
    "Status",
    "ensure_ros_isolation",
    "find_executable",
    "fresh_domain_env",
    "normalize_namespace",
    "pick_free_domain",
    "pipeline_processes",
    "status_name",
]
