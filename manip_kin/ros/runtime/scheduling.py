"""How a loop thread asks the kernel for its timing, Linux-specific, each piece behind its
own check (it does nothing, and says so, where the call is not there): the timer slack
(``prctl``), the EEVDF slice (``sched_setattr``) and SCHED_FIFO shared with the threads the
loop waits on (``/proc/self/task`` and ``os.sched_setscheduler``)."""

from __future__ import annotations

import os
import struct
import threading
from dataclasses import dataclass

__all__ = ["SharedPriority", "TIMER_SLACK_NS", "set_scheduler_slice", "set_timer_slack", "share_realtime_priority"]


#: Timer slack of a loop thread [ns]. Linux lets a sleeping thread wake up to its slack
#: (50 µs by default) after the requested time so that wake-ups can be batched; a 1 ms loop
#: wants its deadline instead.
TIMER_SLACK_NS = 1_000
_PR_SET_TIMERSLACK = 29  # prctl option, linux/prctl.h


def set_timer_slack(slack_ns: int) -> bool:
    """Set the calling thread's timer slack (Linux); False where that is not possible."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(_PR_SET_TIMERSLACK, ctypes.c_ulong(slack_ns), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


# sched_setattr / sched_getattr system call numbers (no libc wrapper, none in os).
_SCHED_ATTR_SYSCALLS = {"x86_64": (314, 315), "aarch64": (274, 275)}
_SCHED_ATTR = struct.Struct("<IIQiIQQQII")  # struct sched_attr, SCHED_ATTR_SIZE_VER1 (56 bytes)


def set_scheduler_slice(slice_ns: int) -> tuple[int, str]:
    """Ask the kernel for an EEVDF time slice of ``slice_ns`` for the calling thread.

    Under the normal scheduler (SCHED_OTHER) of Linux >= 6.12, a thread may request its own
    slice (``sched_runtime`` of ``sched_setattr``; no privilege needed, bounded by the kernel to
    0.1-100 ms). A short slice gives the thread an early virtual deadline when it wakes, so it
    preempts a thread running a longer slice instead of queueing behind it: a 1 kHz loop then
    starts on time although other processes keep both cores busy. Its share of CPU is not
    changed. Policy and nice value are kept.

    Returns:
        ``(slice_ns, "")``: the slice the kernel now gives the thread (read back), or ``(0, why
        not)`` (another architecture, a kernel without per-thread slices, a real-time policy).
    """
    import ctypes

    numbers = _SCHED_ATTR_SYSCALLS.get(os.uname().machine)
    if numbers is None:
        return 0, f"sched_setattr not wired for {os.uname().machine}"
    setattr_number, getattr_number = numbers
    try:
        libc = ctypes.CDLL(None, use_errno=True)

        def read() -> list | None:
            """The calling thread's sched_attr fields, or None (errno set)."""
            buffer = ctypes.create_string_buffer(_SCHED_ATTR.size)
            if libc.syscall(getattr_number, 0, buffer, _SCHED_ATTR.size, 0) != 0:
                return None
            return list(_SCHED_ATTR.unpack(buffer.raw))

        fields = read()
        if fields is None:
            return 0, f"sched_getattr failed: {os.strerror(ctypes.get_errno())}"
        if fields[1] != os.SCHED_OTHER:
            return 0, f"the thread's policy is {fields[1]}, not SCHED_OTHER"
        fields[0], fields[2], fields[5] = _SCHED_ATTR.size, 0, int(slice_ns)  # size, flags, runtime
        buffer = ctypes.create_string_buffer(_SCHED_ATTR.pack(*fields), _SCHED_ATTR.size)
        if libc.syscall(setattr_number, 0, buffer, 0) != 0:
            return 0, f"sched_setattr failed: {os.strerror(ctypes.get_errno())}"
        fields = read()
        if fields is None:
            return 0, f"sched_getattr failed: {os.strerror(ctypes.get_errno())}"
    except (OSError, AttributeError) as error:
        return 0, f"sched_setattr not available: {error}"
    granted = fields[5]
    if not granted:
        return 0, "this kernel has no per-thread slices (Linux 6.12 or later)"
    return granted, ""


def _is_middleware_receive_thread(name: str) -> bool:
    """True for the name Fast DDS (2.13 and later) gives a thread that receives on one port:
    ``dds.shm.<port>`` (shared memory) or ``dds.udp.<port>``."""
    parts = name.split(".")
    return len(parts) == 3 and parts[0] == "dds" and parts[1] in ("shm", "udp") and parts[2].isdigit()


@dataclass(frozen=True)
class SharedPriority:
    """The threads :func:`share_realtime_priority` moved to SCHED_FIFO ``priority`` (thread ids)."""

    priority: int
    python_threads: tuple[int, ...] = ()
    middleware_threads: tuple[int, ...] = ()

    def describe(self) -> str:
        """``1 Python thread and 5 middleware receive threads``, or why none were found."""
        python, middleware = len(self.python_threads), len(self.middleware_threads)
        text = f"{python} Python thread{'s' * (python != 1)} and {middleware} middleware receive thread"
        text += "s" * (middleware != 1)
        if not middleware:
            text += " (none recognised: Fast DDS 2.13 or later names them dds.shm.<port>, dds.udp.<port>)"
        return text

    def restore(self) -> None:
        """Normal scheduling again for each of the threads still at SCHED_FIFO ``priority``
        (one that has ended, or was rescheduled since, is left alone)."""
        for thread_id in self.python_threads + self.middleware_threads:
            try:
                if os.sched_getscheduler(thread_id) == os.SCHED_FIFO:
                    if os.sched_getparam(thread_id).sched_priority == self.priority:
                        os.sched_setscheduler(thread_id, os.SCHED_OTHER, os.sched_param(0))
            except OSError:
                continue


def share_realtime_priority(priority: int) -> SharedPriority:
    """Give SCHED_FIFO ``priority`` to the threads of this process that a real-time loop waits on.

    A loop thread alone at SCHED_FIFO is held up by normal-priority threads whenever other
    real-time loops keep the CPUs busy: by the middleware's receive threads, which deliver the
    message that should wake it (a goal), and by the process's other Python threads, one of
    which may hold the GIL the loop needs when it is preempted (priority inversion). So those
    run at the loop's priority too: every other Python thread (``threading.enumerate``; the
    executor's) and Fast DDS's receive threads, recognised by the names Fast DDS 2.13 and
    later gives them (another middleware's threads are not). Only threads at normal
    scheduling are changed; threads started later by one of them inherit its policy.
    Measured in ``make bench`` (the README's speed section).

    Needs the privilege SCHED_FIFO needs (CAP_SYS_NICE or an RLIMIT_RTPRIO): a thread that is
    refused is skipped. :meth:`SharedPriority.restore` undoes it.
    """
    own = threading.get_native_id()
    python_ids = {thread.native_id for thread in threading.enumerate()}
    python_threads, middleware_threads = [], []
    for task in os.listdir("/proc/self/task"):
        thread_id = int(task)
        try:
            if thread_id == own or os.sched_getscheduler(thread_id) != os.SCHED_OTHER:
                continue
            if thread_id in python_ids:
                chosen = python_threads
            else:
                with open(f"/proc/self/task/{task}/comm") as comm:
                    if not _is_middleware_receive_thread(comm.read().strip()):
                        continue
                chosen = middleware_threads
            os.sched_setscheduler(thread_id, os.SCHED_FIFO, os.sched_param(priority))
            chosen.append(thread_id)
        except OSError:  # the thread ended meanwhile, or the kernel refused
            continue
    return SharedPriority(priority, tuple(python_threads), tuple(middleware_threads))
