"""Real-time scheduling for a node process (off by default: a node parameter turns it on)."""
from __future__ import annotations


def set_realtime_priority(priority: int) -> str:
    """Put every thread of this process (DDS threads included) on SCHED_FIFO ``priority`` (1-99).

    Returns "" on success, else why not (no CAP_SYS_NICE / rtprio limit). Latency under a
    loaded machine is mostly waiting for a core; a real-time class removes that wait.
    Threads started later inherit the class from the thread that starts them.
    """
    import os

    try:
        for tid in os.listdir("/proc/self/task"):
            os.sched_setscheduler(int(tid), os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"cannot use SCHED_FIFO priority {priority}: {exc}"
    return ""
