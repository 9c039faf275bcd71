"""A run in a process of its own (ato_campaigns.run_process): its value comes back, its failure
as the same reason a thread gives, a run past its limit is killed with its process and the next
run gets a new one, a process that dies is reported, what a run prints does not break the
exchange, and the time limit counts the run, not the loading of it."""

import os
import time

import pytest

from ato_campaigns import run_process
from ato_campaigns.run_process import (
    RunDied,
    RunFailed,
    RunProcess,
    RunTimeout,
    limited,
    with_time_limit,
)


def fails():
    raise ZeroDivisionError('estimate reached zero')


class SlowToLoad:
    """A run whose unpickling takes ``load_s`` (as importing a law's modules on a loaded
    machine does); calling it returns 'ran'."""

    def __init__(self, load_s: float):
        self.load_s = load_s

    def __reduce__(self):
        return (_loaded_after, (self.load_s,))

    def __call__(self):
        return 'ran'


def _loaded_after(load_s: float) -> SlowToLoad:
    time.sleep(load_s)
    return SlowToLoad(load_s)


class Unloadable:
    def __reduce__(self):
        return (_cannot_load, ())


def _cannot_load():
    raise ImportError('no module named lost_law')


@pytest.fixture
def process():
    run = RunProcess()
    yield run
    run.stop()


def test_a_value_comes_back_and_the_process_is_kept_for_the_next_run(process):
    first = process.call(os.getpid, 10.0)
    assert first != os.getpid()
    assert process.call(lambda: [1.5, {'a': 'b'}], 10.0) == [1.5, {'a': 'b'}]
    assert process.call(os.getpid, None) == first


def test_a_failure_gives_the_reason_a_thread_gives(process):
    with pytest.raises(RunFailed) as in_process:
        process.call(fails, 10.0)
    with pytest.raises(RunFailed) as in_thread:
        with_time_limit(fails, 10.0)
    assert str(in_process.value) == str(in_thread.value)
    assert str(in_thread.value).startswith('ZeroDivisionError: estimate reached zero [File ')
    assert 'in fails]' in str(in_thread.value)


def test_a_run_past_its_limit_is_killed_and_the_next_gets_a_new_process(process):
    first = process.call(os.getpid, 10.0)
    started = time.monotonic()
    with pytest.raises(RunTimeout, match='1 s'):
        process.call(lambda: time.sleep(600), 1.0)   # where no exception reaches it
    assert time.monotonic() - started < 30.0
    second = process.call(os.getpid, 10.0)
    assert second != first
    with pytest.raises(ProcessLookupError):
        os.kill(first, 0)   # gone, not left behind


def test_a_process_that_dies_is_reported_with_its_exit_status(process):
    with pytest.raises(RunDied, match='exit status 7'):
        process.call(lambda: os._exit(7), 10.0)
    assert process.call(lambda: 'again', 10.0) == 'again'


def test_what_a_run_prints_goes_to_standard_error(process, capfd):
    assert process.call(lambda: print('a law that prints') or 42, 10.0) == 42
    assert 'a law that prints' in capfd.readouterr().err


def test_outside_a_dask_worker_a_run_is_a_thread_of_this_process():
    assert limited(os.getpid, 10.0) == os.getpid()
    with pytest.raises(RunTimeout):
        limited(lambda: [None for _ in iter(int, 1)], 0.5)   # loops in Python: interrupted


def test_the_limit_counts_the_run_not_the_loading_of_it(process):
    assert process.call(SlowToLoad(2.0), 1.0) == 'ran'


def test_a_process_that_does_not_load_the_run_in_time_is_named(process, monkeypatch):
    limit = run_process.START_LIMIT_S
    monkeypatch.setattr(run_process, 'START_LIMIT_S', 0.5)
    with pytest.raises(RunDied, match="the run's process did not load the run within 0.5 s"):
        process.call(SlowToLoad(30.0), 10.0)
    assert process.process is None   # killed, not left loading
    # the next process is started under the usual limit (a loaded machine may take longer than
    # the short one above to start an interpreter)
    monkeypatch.setattr(run_process, 'START_LIMIT_S', limit)
    assert process.call(lambda: 'again', 10.0) == 'again'


def test_a_run_that_cannot_be_loaded_is_a_failure_with_its_reason(process):
    with pytest.raises(RunFailed, match='could not be loaded in its process: ImportError: no '
                                        'module named lost_law'):
        process.call(Unloadable(), 10.0)
    assert process.call(lambda: 'again', 10.0) == 'again'
