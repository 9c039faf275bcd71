"""A process that sleeps is stalled; one that waits for a CPU taken by others is not (the limits
on a node's teardown and on its stop count only the former: ato_ros.stall)."""

import os
import subprocess
import sys
import time

import pytest

from ato_ros import stall
from ato_ros.stall import StallWatch, runnable_ns, wait_for_exit

CORE = max(os.sched_getaffinity(0))
SLEEPS = 'import time\nwhile True: time.sleep(1)'
SPINS = 'while True: pass'
needs_schedstat = pytest.mark.skipif(runnable_ns() is None,
                                     reason='the kernel gives no /proc/<pid>/task/*/schedstat')


def started(code: str, nice: int = 0, core: int | None = None) -> subprocess.Popen:
    process = subprocess.Popen([sys.executable, '-c', f'import os\nos.nice({nice})\n{code}'])
    if core is not None:
        os.sched_setaffinity(process.pid, {core})
    return process


def watched_for(watch: StallWatch, seconds: float) -> float:
    """The most the watch showed as stalled over ``seconds``, updated as the limits update it."""
    most, deadline = 0.0, time.monotonic() + seconds
    while time.monotonic() < deadline:
        time.sleep(0.05)
        most = max(most, watch.update())
    return most


@pytest.fixture
def processes():
    running = []
    yield running
    for process in running:
        process.kill()
        process.wait()


@needs_schedstat
def test_a_sleeping_process_is_stalled_and_a_starved_one_is_not(processes):
    # two busy processes and a nice-19 busy one on one core: it gets well under 1 % of it
    processes += [started(SPINS, core=CORE) for _ in range(2)]
    processes += [started(SPINS, nice=19, core=CORE), started(SLEEPS)]
    starved, sleeping = processes[2], processes[3]
    time.sleep(0.5)
    watches = StallWatch(starved.pid), StallWatch(sleeping.pid)
    most = watched_for(watches[0], 4.0)
    assert watches[1].update() > 3.9  # asleep all along
    assert most < 2.0  # what the kernel has not yet added of its wait for a CPU


@needs_schedstat
def test_wait_for_exit_gives_the_code_or_gives_up_on_a_stalled_process(processes):
    assert wait_for_exit(subprocess.Popen([sys.executable, '-c', 'raise SystemExit(3)']),
                         5.0, 60.0) == 3
    processes.append(started(SLEEPS))
    began = time.monotonic()
    with pytest.raises(subprocess.TimeoutExpired):
        wait_for_exit(processes[-1], 1.0, 60.0)
    assert 1.0 <= time.monotonic() - began < 30.0
    processes.append(started(SPINS))  # never stalled: the bound in wall time ends the wait
    with pytest.raises(subprocess.TimeoutExpired):
        wait_for_exit(processes[-1], 60.0, 1.0)


def test_without_schedstat_every_second_counts(monkeypatch):
    monkeypatch.setattr(stall, 'runnable_ns', lambda pid='self': None)
    now = [0.0]
    watch = StallWatch(clock=lambda: now[0])
    now[0] = 2.5
    assert watch.update() == 2.5
