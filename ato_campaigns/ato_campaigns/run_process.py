"""One run at a time, within a wall-time limit: in a thread of this process, or, on a Dask
worker, in a Python process of its own.

``limited(function, limit_s)`` calls ``function()`` and returns its value within ``limit_s`` s of
wall time, else raises :class:`RunTimeout`; an exception of the run is raised as
:class:`RunFailed`, whose message is the run's reason (the exception's type, message and the
line that raised it: the same text wherever the run ran).

In a process that is not a Dask worker (a serial campaign, a test) the run is a thread of this
process, waited for ``limit_s``; past it, RunTimeout is raised in that thread, which stops a run
looping in Python at its next bytecode (a thread blocked in compiled code cannot be stopped and
is left behind).

On a Dask worker the run goes to the worker's run process (:class:`RunProcess`, one per worker
thread), a Python process of the worker's environment started at the worker's first run and
kept for the next ones, so its imports, the plant's compiled kernels, the parsed scenarios and
the planned target curves stay in it. Three reasons:

- The interpreter lock. A worker's event loop wakes several times a second (heartbeats, its
  memory monitor, ...), and each wake takes the lock from the run's thread, which cost a run
  in the worker's thread several per cent of its time (``make bench``'s campaign section
  measures the engine against the same runs in a process of their own). In its own process a
  run shares the lock with nobody.
- A run past its time limit is killed with its process, wherever it is blocked, and the next
  run gets a new process: nothing is left behind.
- A run that kills its interpreter (a segfault, an out-of-memory kill, ``os._exit``) is
  reported as :class:`RunDied` with the process's exit status; the worker lives on.

The two processes talk over the child's standard input and a duplicate of its standard output:
each message is 8 bytes of length (little-endian) and a cloudpickle payload; the child sends its
own standard output to its standard error, so a run that prints cannot break the exchange. The
child says when a run starts (an empty message, once it has unpickled the function and so
imported what it needs), and the time limit counts from there: starting the process, importing
the run's modules and loading the plant's compiled kernels are not the run's time (a worker's
first run on a loaded machine took longer than a short limit for them alone). Start-up has a
limit of its own, :data:`START_LIMIT_S`. The
child leaves when its input closes (its worker ended). After its first run the child moves what
is alive out of the cyclic garbage collector's sight (as the nodes do after start-up,
``ato_ros.lifecycle.freeze_startup_objects``): a full collection would otherwise visit the imported
numba, scipy and pandas at every few runs.
"""

from __future__ import annotations

import ctypes
import gc
import os
import select
import struct
import subprocess
import sys
import threading
import traceback
from typing import IO, Any, Callable

_LENGTH = struct.Struct('<Q')


class RunTimeout(BaseException):
    """A run exceeded its wall-time limit (a BaseException: a law's own ``except Exception``
    does not swallow it)."""

    def __init__(self, limit_s: float):
        super().__init__(f'exceeded the wall-time limit of {limit_s:g} s')
        self.limit_s = limit_s


class RunFailed(RuntimeError):
    """The run raised; the message is its reason (``failure_reason``)."""


class RunDied(RuntimeError):
    """The run's process ended without an answer (killed, crashed)."""


def failure_reason(error: BaseException) -> str:
    """The exception, its message and the line that raised it."""
    lines = traceback.format_exception(type(error), error, error.__traceback__, limit=-1)
    where = ''.join(lines).splitlines()
    return f'{type(error).__name__}: {error}' + (f' [{where[-3].strip()}]'
                                                  if len(where) >= 3 else '')


def on_dask_worker() -> bool:
    try:
        from distributed import get_worker
        get_worker()
        return True
    except (ImportError, ValueError):
        return False


def limited(function: Callable[[], Any], limit_s: float | None) -> Any:
    """``function()`` within ``limit_s`` s of wall time (None or 0: no limit): in the worker's
    run process on a Dask worker, else in a thread of this process (module docstring)."""
    if on_dask_worker():
        return worker_run_process().call(function, limit_s)
    return with_time_limit(function, limit_s)


#: after its time limit, a run's thread has this long to stop before it is left behind, s
STOP_GRACE_S = 5.0

#: a run process has this long, s, to start and unpickle a run (import its modules), else the
#: run is an error (RunDied) naming it; generous: a cold start on a loaded machine takes seconds
START_LIMIT_S = 120.0


def _raise_in(thread_id: int) -> None:
    ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(thread_id),
                                               ctypes.py_object(RunTimeout))


def with_time_limit(function: Callable[[], Any], limit_s: float | None) -> Any:
    """``function()`` in a thread of its own, waited for ``limit_s`` s of wall time; past it,
    RunTimeout is raised in that thread and here."""
    if not limit_s:
        try:
            return function()
        except Exception as error:  # noqa: BLE001 -- the run's failure, as its reason
            raise RunFailed(failure_reason(error)) from None
    outcome: dict = {}

    def body():
        try:
            outcome['value'] = function()
        except BaseException as error:  # noqa: BLE001 -- handed to the waiting thread
            outcome['error'] = error

    thread = threading.Thread(target=body, daemon=True, name='campaign run')
    thread.start()
    thread.join(limit_s)
    if thread.is_alive():
        # a started thread has its ident
        assert thread.ident is not None
        _raise_in(thread.ident)
        thread.join(STOP_GRACE_S)
        raise RunTimeout(limit_s)
    if 'error' in outcome:
        raised = outcome['error']
        if isinstance(raised, RunTimeout):  # raised just as the run finished
            raise RunTimeout(limit_s) from None
        if isinstance(raised, Exception):
            raise RunFailed(failure_reason(raised)) from None
        raise raised
    return outcome['value']


class RunProcess:
    """A Python process of this one's environment that runs one function at a time (module
    docstring); started at the first call, started again after a run that was killed or died."""

    def __init__(self):
        self.process: subprocess.Popen | None = None

    def _start(self) -> subprocess.Popen:
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        self.process = subprocess.Popen(
            [sys.executable, '-m', 'ato_campaigns.run_process'], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, env=env)
        return self.process

    @staticmethod
    def _pipes(process: subprocess.Popen) -> tuple[IO[bytes], IO[bytes]]:
        """The process's standard input and output."""
        # _start opens both as pipes
        assert process.stdin is not None and process.stdout is not None
        return process.stdin, process.stdout

    def call(self, function: Callable[[], Any], limit_s: float | None) -> Any:
        """``function()`` in the process; RunTimeout past ``limit_s`` (the process is killed),
        RunFailed if it raised, RunDied if the process ended without an answer."""
        import cloudpickle
        process = self.process if self.process is not None and self.process.poll() is None \
            else self._start()
        data = cloudpickle.dumps(function)
        stdin, _ = self._pipes(process)
        try:
            stdin.write(_LENGTH.pack(len(data)) + data)
            stdin.flush()
            answer = self._receive(process, limit_s)
        except RunTimeout:
            self.stop()
            raise
        except (OSError, EOFError):
            code = self.stop()
            raise RunDied(f"the run's process ended without an answer (exit status {code})") \
                from None
        ok, value = cloudpickle.loads(answer)
        if not ok:
            raise RunFailed(value)
        return value

    def _receive(self, process: subprocess.Popen, limit_s: float | None) -> bytes:
        """The answer: first the run's start (an empty message) within START_LIMIT_S (else
        RunDied: the process, not the run, failed), then the answer within ``limit_s`` of the
        start."""
        try:
            started = self._message(process, START_LIMIT_S)
        except RunTimeout:
            self.stop()
            raise RunDied(f"the run's process did not load the run within {START_LIMIT_S:g} s "
                          '(run_process.START_LIMIT_S)') from None
        if started:  # the run's process could not load the run: its reason, as an answer
            return started
        return self._message(process, limit_s)

    @staticmethod
    def _message(process: subprocess.Popen, limit_s: float | None) -> bytes:
        # read from the descriptor, unbuffered: a buffered reader could hold the answer that
        # came with the start, where select() no longer sees it
        out = RunProcess._pipes(process)[1].fileno()
        if limit_s and not select.select([out], [], [], limit_s)[0]:
            raise RunTimeout(limit_s)
        (length,) = _LENGTH.unpack(_read_exactly(out, _LENGTH.size))
        return _read_exactly(out, length)

    def stop(self) -> int | None:
        """Kill the process (a run past its limit) and return its exit status."""
        process, self.process = self.process, None
        if process is None:
            return None
        if process.poll() is None:
            process.kill()
        code = process.wait()
        for stream in self._pipes(process):
            try:
                stream.close()
            except OSError:
                pass
        return code


def _read_exactly(source, count: int) -> bytes:
    """``count`` bytes from a stream or a file descriptor; EOFError if it ends first."""
    parts, left = [], count
    while left:
        part = os.read(source, left) if isinstance(source, int) else source.read(left)
        if not part:
            raise EOFError(f'{count - left} of {count} bytes')
        parts.append(part)
        left -= len(part)
    return b''.join(parts)


_local = threading.local()


def worker_run_process() -> RunProcess:
    """The run process of this thread of the worker (one per worker thread: a worker with
    several threads runs several runs at once)."""
    process = getattr(_local, 'process', None)
    if process is None:
        process = _local.process = RunProcess()
    return process


def serve(requests, answers) -> None:
    """The run process: each request a function, each answer (True, its value) or (False, the
    reason it raised), until the requests end."""
    import cloudpickle
    first = True
    while True:
        header = requests.read(_LENGTH.size)
        if len(header) < _LENGTH.size:
            return
        payload = _read_exactly(requests, _LENGTH.unpack(header)[0])
        try:
            function = cloudpickle.loads(payload)
        except Exception as error:  # noqa: BLE001 -- a run that cannot be loaded, as its reason
            answer = (False, 'the run could not be loaded in its process: '
                      + failure_reason(error))
        else:
            answers.write(_LENGTH.pack(0))  # the run starts: its time limit counts from here
            answers.flush()
            try:
                answer = (True, function())
            except Exception as error:  # noqa: BLE001 -- the run's failure, as its reason
                answer = (False, failure_reason(error))
            del function
        data = cloudpickle.dumps(answer)
        answers.write(_LENGTH.pack(len(data)) + data)
        answers.flush()
        if first:
            gc.collect()
            gc.freeze()
            first = False


def main() -> int:
    answers = os.fdopen(os.dup(1), 'wb')
    os.dup2(2, 1)  # what a run prints goes to standard error
    serve(sys.stdin.buffer, answers)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
