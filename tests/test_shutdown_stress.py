"""Clean shutdown under load (issue 29, item 8): a recorder running as in a lockstep run (at nice
19, ``--background``) and a loop node beside it are stopped as the runner stops them
(``Stack.stop``: SIGINT, wait, abort what does not end) again and again while busy processes take
their CPU. Every exit code is 0, every recording is closed, and no log shows an abort, a teardown
timeout or a traceback.

For the shutdown, every thread of both processes is moved to one core where busy processes run:
a nice-19 process beside two busy ones gets well under 1 % of it, as on a machine whose every core
is busy, while the test costs the machine one core and only while they stop (they start on an
unloaded core: their start-up is not what is tested). ``make test`` repeats it twice beside two
busy processes; ``make test-stress`` (``--stress-load``) five times beside three."""

import contextlib
import os
import subprocess
import sys

import pytest

from ato_bringup.stack import Stack, StackConfig

#: (repetitions, busy processes on the core) in make test and in make test-stress
MODEST = (2, 2)
HEAVY = (5, 3)
BAD_SIGNS = ('Fatal Python error', 'Timeout', 'Traceback', 'Segmentation fault',
             'terminate called')
#: the core the stopping processes share with the busy ones
CORE = max(os.sched_getaffinity(0))


def pin(pid: int) -> None:
    """Every thread of process ``pid`` (and so every thread it starts later) on CORE."""
    for tid in os.listdir(f'/proc/{pid}/task'):
        with contextlib.suppress(ProcessLookupError):  # a thread that has just ended
            os.sched_setaffinity(int(tid), {CORE})


@contextlib.contextmanager
def busy_core(count: int):
    """``count`` processes that keep CORE busy (at the test's own priority)."""
    processes = [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
                 for _ in range(count)]
    try:
        for process in processes:
            pin(process.pid)
        yield
    finally:
        for process in processes:
            process.kill()
            process.wait()


def shut_down_once(tmp_path, domain_id, attempt: int, busy: int
                   ) -> tuple[dict[str, int], dict[str, str]]:
    log_dir = tmp_path / f'attempt_{attempt}'
    config = StackConfig('short_line', domain_id=domain_id, log_dir=log_dir)
    with Stack(config) as stack:
        stack.start_process('recorder', {}, ['-o', str(log_dir / 'bag'), '--sim-time',
                                             '--background'])
        stack.start_process('profile', {'scenario': 'short_line', 'lockstep': True})
        # the recorder is up (its last words of start-up) and has the profile's latched curve:
        # both are up, and there is a file to close
        assert stack.spin_until(lambda: all(words in stack.logs['recorder'].read_text()
                                            for words in ('recording /ato/', 'recording all')),
                                300.0), stack.log_tail('recorder')
        with busy_core(busy):
            for process in stack.processes.values():
                pin(process.pid)
            codes = stack.stop()
    return codes, {name: path.read_text(errors='replace') for name, path in stack.logs.items()}


@pytest.mark.timeout(3600)
def test_a_recorder_and_a_loop_node_end_cleanly_under_load_every_time(tmp_path, domain_id,
                                                                    request):
    repetitions, busy = HEAVY if request.config.getoption('stress_load') else MODEST
    for attempt in range(repetitions):
        codes, logs = shut_down_once(tmp_path, domain_id, attempt, busy)
        failed = {name: text[-3000:] for name, text in logs.items()
                  if codes[name] != 0 or any(sign in text for sign in BAD_SIGNS)}
        assert not failed, f'attempt {attempt}: exit codes {codes}\n' + '\n'.join(
            f'--- {name}.log\n{text}' for name, text in failed.items())
        assert 'closed ' in logs['recorder'], logs['recorder'][-3000:]
