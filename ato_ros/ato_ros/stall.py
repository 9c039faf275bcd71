"""Telling a hung process from a starved one, for the limits on how long a node may take to end.

A node that takes too long to tear down is ended by a limit (its own, :func:`ato_ros.lifecycle.
tear_down`, and its supervisor's, ``ato_bringup.stack.Stack.stop``). Counted in wall time, such a
limit also ends a node that is merely slow because other processes have the CPUs: the recorder of
a lockstep run runs at nice 19 (``--background``), and beside two busy processes on two cores it
gets about 1.5 % of a core (the scheduler weighs nice 19 at 15 against 1024 for nice 0), so
every millisecond of CPU its teardown needs takes tens of milliseconds of wall time. Such a
recorder was ended half-way through ``destroy_node`` ("Fatal Python error: Aborted", exit -6,
issue 29).

What a limit on hanging should count instead is the time in which the process made no progress
although it could have: wall time not matched by time in which its threads were runnable (on a
CPU or waiting in the run queue for one), each second runnable making up for
``1 / RUNNABLE_SHARE`` seconds. A process blocked in a deadlock sleeps and is counted as stalled;
one waiting for a CPU is not. Linux gives both times of each thread in
``/proc/<pid>/task/<tid>/schedstat`` (ns on a CPU, ns waiting to run, timeslices); where it does
not, every second counts (wall time, as before). The kernel adds a thread's wait to it only once
the thread gets a CPU, so a starved process's figures come in bursts: the stalled time is a
balance that a burst pays back (never below zero), not a sum of intervals judged one by one.

A stalled process whose few periodic threads keep waking (the middleware's timers) may look
runnable now and then on a loaded machine: every limit here also has a bound in wall time.
"""

from __future__ import annotations

import os
import subprocess
import time
from typing import Callable

#: a process runnable for this share of the time is making progress
RUNNABLE_SHARE = 0.5


def runnable_ns(pid: int | str = 'self') -> dict[str, int] | None:
    """Each thread's time on a CPU plus its time waiting for one, ns, by thread id; None where
    /proc does not give them (not Linux, a kernel without schedstat, the process is gone)."""
    folder = f'/proc/{pid}/task'
    try:
        threads = os.listdir(folder)
    except OSError:
        return None
    times = {}
    for tid in threads:
        try:
            with open(f'{folder}/{tid}/schedstat') as stats:
                on_cpu, waiting = stats.read().split()[:2]
        except (OSError, ValueError):
            continue  # the thread has just ended
        times[tid] = int(on_cpu) + int(waiting)
    return times or None


class StallWatch:
    """The time since it was made in which process ``pid`` made no progress although it could
    have (the module's balance), updated by :meth:`update`."""

    def __init__(self, pid: int | str = 'self', clock: Callable[[], float] = time.monotonic):
        self.pid = pid
        self.clock = clock
        self.started = self.last_time = clock()
        self.last = runnable_ns(pid)
        self.stalled_s = 0.0

    def update(self) -> float:
        """The stalled time so far, s, with the interval since the last update accounted."""
        now, sample = self.clock(), runnable_ns(self.pid)
        interval = now - self.last_time
        if sample is None or self.last is None:
            self.stalled_s += interval
        else:
            # threads that ended lose only this interval; new ones count from their start
            runnable = sum(t - self.last.get(tid, 0) for tid, t in sample.items()) / 1e9
            self.stalled_s = max(0.0, self.stalled_s + interval - runnable / RUNNABLE_SHARE)
        self.last_time, self.last = now, sample
        return self.stalled_s

    def wall_s(self) -> float:
        return self.clock() - self.started


def wait_for_exit(process: subprocess.Popen, stall_limit_s: float, wall_limit_s: float,
                  poll_s: float = 0.05, idle: Callable[[], None] | None = None,
                  watch: StallWatch | None = None) -> int:
    """``process.wait`` with the limits of this module: the exit code, or
    ``subprocess.TimeoutExpired`` once the process has been stalled for ``stall_limit_s`` or
    has run for ``wall_limit_s`` since the call. Between looks: ``idle()`` (e.g. spin an
    executor), else a sleep of ``poll_s``; ``watch``: the caller's, to read the times after."""
    watch = watch or StallWatch(process.pid)
    while process.poll() is None:
        if watch.update() > stall_limit_s or watch.wall_s() > wall_limit_s:
            raise subprocess.TimeoutExpired(process.args, watch.wall_s())
        if idle is None:
            time.sleep(poll_s)
        else:
            idle()
    return process.returncode
