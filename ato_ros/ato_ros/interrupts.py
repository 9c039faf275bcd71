"""A stop that comes while a process is still starting: a clean exit, not a traceback.

Python turns a SIGINT into ``KeyboardInterrupt`` from its first instruction; a node's imports
(rclpy, numba, scipy) take seconds, and a Ctrl-C or a launch's SIGINT in that time printed a
``KeyboardInterrupt`` traceback and ended the process with -2, which a launch reports as a
failed node. Each executable's entry point calls :func:`quiet_until_running` before it imports
anything heavy: until the node installs its own handlers (``ato_ros.lifecycle.run_nodes``), a
SIGINT or SIGTERM ends the process at once with exit code 0 and one line on stderr. Light on
purpose: this module imports nothing but the standard library's ``signal``, ``os`` and ``sys``.
"""

from __future__ import annotations

import os
import signal
import sys

#: the exit code of a process stopped before it ran: it was asked to stop, and did
STOPPED_WHILE_STARTING = 0


def _stop_now(signum: int, frame) -> None:
    name = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else 'process'
    try:
        sys.stderr.write(f'{name}: stopped while starting ({signal.Signals(signum).name})\n')
        sys.stderr.flush()
    finally:
        _exit_now(signum, frame)


def _exit_now(signum: int, frame) -> None:
    # no interpreter teardown: half-imported modules have nothing to finalise
    os._exit(STOPPED_WHILE_STARTING)


def quiet_until_running(say: bool = True) -> None:
    """From now until the node installs its own handlers, SIGINT and SIGTERM end the process
    with exit code 0, without a traceback, and (``say``) a line naming the signal."""
    handler = _stop_now if say else _exit_now
    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
