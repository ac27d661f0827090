"""Helpers for tests that run node processes: checked teardown, the realtime privilege, threads."""

from __future__ import annotations

import contextlib
import os
import re
import threading
from pathlib import Path

from manip_kin.pipeline import Pipeline

#: The nodes of a pipeline whose loops carry a motion.
PIPELINE_NODES = ("robot_state", "cartesian_controller", "trajectory_generator")


def loops_lateness_s(client, names=PIPELINE_NODES) -> float:
    """The sum of the named nodes' worst loop lateness so far [s], from their newest status
    (``loop_period_error_max_ms``): how long a late cycle can have held a command on."""
    return 1e-3 * sum(float(client.wait_status(name).values["loop_period_error_max_ms"]) for name in names)


def stop_checked(pipeline: Pipeline) -> None:
    """Stop every node; each must exit with 0 (a node that crashed or hung is a failure)."""
    # 30 s before escalating to SIGTERM/SIGKILL (Pipeline's default is 5 s): on a loaded machine
    # a clean shutdown can take longer, and an escalation would show as a failed exit code.
    codes = pipeline.stop(timeout=30.0)
    failed = {name: code for name, code in codes.items() if code != 0}
    tails = "\n".join(f"--- {name} ---\n{pipeline.log_tail(name)}" for name in failed)
    assert not failed, f"nodes exited with {failed}:\n{tails}"


@contextlib.contextmanager
def checked_pipeline(processes, **kwargs):
    """``with Pipeline(processes, **kwargs)`` that also asserts exit code 0 of every node at the end.

    The check runs only when the body passed: a failing body's own error is the one reported.
    """
    pipeline = Pipeline(processes, **kwargs).start()
    try:
        yield pipeline
    except BaseException:
        pipeline.stop()
        raise
    stop_checked(pipeline)


def realtime_scheduling_error(priority: int = 10) -> str:
    """'' when this process may run a thread at SCHED_FIFO ``priority`` (CAP_SYS_NICE or RLIMIT_RTPRIO),
    else why not. Tried in a throwaway thread, as the nodes' RateLoop does for its loop thread."""
    outcome: list[str] = []

    def attempt() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            outcome.append("")
        except (OSError, AttributeError) as error:
            outcome.append(f"SCHED_FIFO {priority} refused: {error}")

    thread = threading.Thread(target=attempt)
    thread.start()
    thread.join()
    return outcome[0]


def thread_slice_ns(native_id: int) -> int | None:
    """A thread of this process's EEVDF slice as the kernel reports it (``se.slice`` in /proc,
    ns), or None where the kernel reports none."""
    for line in open(f"/proc/self/task/{native_id}/sched"):
        if line.startswith("se.slice"):
            return int(line.split(":")[1])
    return None


def fast_dds_receive_threads(pid: int | str = "self") -> list[int]:
    """Thread ids of process ``pid``'s Fast DDS receive threads (named dds.shm.<port>, dds.udp.<port>)."""
    return [
        int(task.name)
        for task in Path(f"/proc/{pid}/task").iterdir()
        if re.fullmatch(r"dds\.(shm|udp)\.\d+", (task / "comm").read_text().strip())
    ]


@contextlib.contextmanager
def realtime_measurement(priority: int = 5):
    """Run this process's thread and its middleware receive threads at SCHED_FIFO ``priority``
    (below the nodes' 10) for the body, where permitted: a test that takes a 500 Hz stream is
    an instrument that must keep up. At normal scheduling, beside the SCHED_FIFO nodes and a
    second test worker, it fell seconds behind and lost a line's cruise (54 of 600 poses kept).
    Child processes (the CLI) start at normal scheduling, as a user's would."""
    from manip_kin.ros.runtime.scheduling import share_realtime_priority

    try:
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    except OSError:  # refused: measured at normal scheduling, as before
        yield
        return
    shared = share_realtime_priority(priority)
    try:
        yield
    finally:
        shared.restore()
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def recorder_reads(client, topics) -> bool:
    """True once ``client``'s graph shows a recorder subscription on each of ``topics`` and a
    publisher on each: the pair the recorder must have matched (a proxy, on one host). Under
    load a recorder's reader matched seconds late and missed the start of a motion."""
    node = client.node
    for topic in topics:
        readers = node.get_subscriptions_info_by_topic(topic)
        if not any(info.node_name == "recorder" for info in readers) or not node.get_publishers_info_by_topic(topic):
            return False
    return True
