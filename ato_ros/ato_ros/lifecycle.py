"""A node's life: the executor, start-up (parameters, help), spinning until done or told to stop,
and a teardown that never hangs. Every node of the suite runs through :func:`run_node` (or
:func:`run_nodes` for the composed stack).
"""
from __future__ import annotations

import faulthandler
import gc
import os
import signal
import sys
import textwrap
import threading
import time
from typing import Any, Callable, Iterable, Sequence

import rclpy
import rclpy.exceptions
import rclpy.signals

from ato_common.commands import ros_command
from ato_ros.publishing import shared_step_recorders
from ato_ros.stall import StallWatch


def make_executor(context=None):
    """The executor every node of the suite spins: EventsExecutor (about 0.35 ms per
    inter-process round trip against 0.57 ms for SingleThreadedExecutor) unless the environment
    variable ATO_EXECUTOR=single asks for the default one (for comparisons in the benchmark)."""
    if os.environ.get('ATO_EXECUTOR', 'events') != 'single':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context)
        except ImportError:  # pragma: no cover - older rclpy
            pass
    from rclpy.executors import SingleThreadedExecutor
    return SingleThreadedExecutor(context=context)


def freeze_startup_objects() -> None:
    """Call once at the end of a node's start-up (everything built, publishers and subscriptions
    created). A full cyclic-GC collection visits every tracked object, and numba's, scipy's and
    the start-up's own are many: tens of ms, every few thousand control periods of a long run,
    each time a late step. Start-up garbage is collected first; what is left is moved out of
    the collector's sight for good (objects made later are collected as usual)."""
    gc.collect()
    gc.freeze()


# A node asked to stop must end: if tearing down the executor, the node's rcl entities and the
# context makes no progress for this long (a rare middleware hang: stalled time, ato_ros.stall,
# not the time a starved process waits for a CPU), every thread's Python stack is written to
# stderr and the process exits with code 1, instead of waiting for its supervisor's SIGKILL.
TEARDOWN_LIMIT_S = 5.0
# A node told to stop (SIGINT, SIGTERM) is gone within this much wall time: a launch escalates
# SIGINT to SIGTERM after 5 s (``sigterm_timeout``) and logs it as an error. Closing the outputs
# (the plant's wait for its last messages' acknowledgement, ``final_delivery_timeout_s``) takes
# its part first; the teardown gets what is left, at least ``LEAST_TEARDOWN_S`` (a teardown
# takes a few tenths of a second).
STOP_BUDGET_S = 4.0
LEAST_TEARDOWN_S = 1.0
# ... and in any case after this long in wall time, even if the hang holds the GIL (then the
# watchdog thread cannot run: faulthandler's own thread ends the process) or periodic middleware
# threads make a hung process look runnable on a loaded machine.
TEARDOWN_WALL_LIMIT_S = 120.0
#: how often the teardown's watchdog judges the progress, s
WATCH_PERIOD_S = 0.1
_teardown_watch: threading.Event | None = None


class RunNodeHooks:
    """What :func:`run_node` calls on the node it runs, with the defaults of a node that needs
    none of it. Every node class of the suite inherits it before ``rclpy.node.Node``
    (``class PlantNode(RunNodeHooks, Node)``); run_node refuses a node that does not.

    ``finished``
        run_node spins until this becomes True (or rclpy shuts down, or a signal arrives).
        Default False: the node runs until it is stopped.
    ``exit_code``
        the process's exit status, read after the teardown. Default 0.
    ``close_outputs()``
        called once spinning has stopped, before the executor and the node are torn down and
        with no time limit: flush and close what the node writes (the recorder's bag).
        Default: nothing to close.
    """

    finished: bool = False
    exit_code: int = 0

    def close_outputs(self) -> None:
        """Nothing to close by default."""


def teardown_limit_s(stopped_at: float | None) -> float:
    """The time without progress the teardown may take: ``TEARDOWN_LIMIT_S`` for a node that
    ended by itself, what is left of ``STOP_BUDGET_S`` (at least ``LEAST_TEARDOWN_S``) for one
    told to stop at ``stopped_at`` (``time.monotonic()``)."""
    if stopped_at is None:
        return TEARDOWN_LIMIT_S
    left = STOP_BUDGET_S - (time.monotonic() - stopped_at)
    return min(TEARDOWN_LIMIT_S, max(LEAST_TEARDOWN_S, left))


def watch_teardown(limit_s: float = TEARDOWN_LIMIT_S) -> None:
    """From now until the process exits (or :func:`cancel_teardown_watch`): once the process
    has made no progress for ``limit_s`` although it could have (:mod:`ato_ros.stall`) or
    ``TEARDOWN_WALL_LIMIT_S`` have passed, write every thread's stack to stderr and exit with
    code 1. A node starved of CPU by other processes (the recorder at nice 19 on a loaded
    machine) is slow, not hung, and is left to finish."""
    global _teardown_watch
    cancel_teardown_watch()
    faulthandler.dump_traceback_later(TEARDOWN_WALL_LIMIT_S, exit=True)
    stop = _teardown_watch = threading.Event()
    watch = StallWatch()

    def watchdog() -> None:
        while not stop.wait(WATCH_PERIOD_S):
            if watch.update() > limit_s:
                print(f'Timeout: the teardown made no progress for {limit_s:g} s '
                      '(stalled, not waiting for a CPU); every thread:', file=sys.stderr,
                      flush=True)
                faulthandler.dump_traceback(all_threads=True)
                os._exit(1)

    threading.Thread(target=watchdog, name='teardown watchdog', daemon=True).start()


def cancel_teardown_watch() -> None:
    """Stop :func:`watch_teardown`'s limits (a test that tears a node down in its own
    process)."""
    global _teardown_watch
    faulthandler.cancel_dump_traceback_later()
    if _teardown_watch is not None:
        _teardown_watch.set()
        _teardown_watch = None


def tear_down(executor, node: RunNodeHooks | Sequence[RunNodeHooks],
              limit_s: float | None = None) -> None:
    """Shut the executor down (it lets go of every entity while the context is still valid),
    then destroy the node (or each of the nodes), under :func:`watch_teardown`'s limits
    (``limit_s`` without progress, default ``TEARDOWN_LIMIT_S``). The caller shuts rclpy
    down."""
    limit_s = TEARDOWN_LIMIT_S if limit_s is None else limit_s
    watch_teardown(limit_s)
    executor.shutdown(timeout_sec=limit_s)
    for each in (node if isinstance(node, (list, tuple)) else (node,)):
        each.destroy_node()


def parameter_files(args: Sequence[str]) -> list[str]:
    """The files of the ``--params-file`` options in the ``--ros-args`` parts of a command
    line (each part ends at ``--`` or at the end)."""
    files, in_ros_args = [], False
    words = iter(args)
    for word in words:
        if word == '--ros-args':
            in_ros_args = True
        elif word == '--':
            in_ros_args = False
        elif in_ros_args and word == '--params-file':
            files.append(next(words, ''))
    return files


def refused_command_line(args=None) -> str | None:
    """Why a node's command line is refused before rclpy starts (None if it is not): a
    parameters file refused by :mod:`ato_common.files` (deep nesting, an alias bomb, a key given
    twice: rcl would silently keep the last value) or ROS arguments rcl cannot parse (rcl refuses
    YAML aliases in a parameters file)."""
    from rclpy.impl.implementation_singleton import rclpy_implementation
    from rclpy.utilities import remove_ros_args

    from ato_common.files import load_yaml
    from ato_common.validation import ConfigError
    argv = list(sys.argv if args is None else args)
    try:
        for path in parameter_files(argv):
            load_yaml(path)
        remove_ros_args(argv)
    except ConfigError as error:
        return f'--params-file {error}'
    except rclpy_implementation.RCLInvalidROSArgsError as error:
        return ' '.join(str(error).split())
    return None


def help_requested(args=None) -> bool:
    """Whether the command line (without its ``--ros-args`` part) asks for ``-h``/``--help``."""
    from rclpy.utilities import remove_ros_args
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    return '-h' in argv or '--help' in argv


def node_usage(package: str, executable: str, doc: str | None, params: Iterable) -> str:
    """``--help`` of a node: how to start it, the first paragraph of its module docstring and
    every declared parameter (:class:`ato_ros.params.Param`) with its type, default, range or
    valid values, whether it may change at run time, and its description."""
    lines = [f'usage: {ros_command(f"run {package} {executable}")} [-h] '
             '[--ros-args -p NAME:=VALUE ...]', '']
    summary = (doc or '').strip().split('\n\n')[0]
    lines += [textwrap.fill(' '.join(summary.split()), 100), '', 'parameters:']
    for p in params:
        kind = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}[type(p.default)]
        facts = [kind, f'default {p.default!r}']
        if p.minimum is not None or p.maximum is not None:
            facts.append(f'range [{p.minimum:g}, {p.maximum:g}]')
        if p.choices:
            facts.append('one of: ' + ', '.join(p.choices))
        facts.append('fixed at start-up' if p.read_only else 'may change at run time')
        lines.append(f"  {p.name} ({'; '.join(facts)})")
        lines.append(textwrap.fill(p.description, 100, initial_indent=' ' * 6,
                                   subsequent_indent=' ' * 6))
    return '\n'.join(lines)


def run_node(make_node: Callable[[], RunNodeHooks], args=None,
             usage: Callable[[], str] | None = None) -> int:
    """Entry point body of every node: init, build, spin until shutdown or the node asks to stop
    (``node.finished`` becomes True), clean up. SIGINT and SIGTERM end it cleanly with exit 0
    (or the node's ``exit_code``); a configuration error is printed and gives exit 2 before
    anything is published. The node must declare the hooks (:class:`RunNodeHooks`): any other
    object is a TypeError naming its class.

    Teardown order: the node's own outputs first (``node.close_outputs()``, e.g. the recorder's
    file, with no time limit), then, under the limits of :func:`watch_teardown` (a node told to
    stop: what is left of ``STOP_BUDGET_S``, :func:`teardown_limit_s`), the executor (it lets go
    of every entity while the context is still valid), the node, the context.

    ``usage``: the text ``-h``/``--help`` prints (then the node exits 0 without starting). A
    command line :func:`refused_command_line` refuses is printed and gives exit 2."""
    return run_nodes((make_node,), args, usage)


def _built(makers: Sequence[Callable[[], RunNodeHooks]]) -> list[Any] | int:
    """The nodes, built in order (several in one process share their step recorders), or the
    exit code 2 of a configuration error, printed."""
    from ato_common.validation import ConfigError
    nodes = []
    with shared_step_recorders(len(makers) > 1):
        for make_node in makers:
            try:
                node = make_node()
            except ConfigError as error:
                print(f'error: {error}', file=sys.stderr)
                return 2
            except (rclpy.exceptions.InvalidParameterValueException,
                    rclpy.exceptions.InvalidParameterTypeException) as error:
                # a --ros-args or --params-file value the parameter's descriptor refuses
                print(f'error: {error}', file=sys.stderr)
                return 2
            if not isinstance(node, RunNodeHooks):  # rclpy.shutdown below lets go of it
                raise TypeError(f'{type(node).__module__}.{type(node).__qualname__} does not '
                                'declare the hooks run_node calls (finished, exit_code, '
                                'close_outputs): inherit ato_ros.lifecycle.RunNodeHooks')
            nodes.append(node)
    return nodes


def run_nodes(makers: Sequence[Callable[[], RunNodeHooks]], args=None,
              usage: Callable[[], str] | None = None) -> int:
    """:func:`run_node` for several nodes in one process on one executor (the composed stack,
    ``ato_bringup.composed``): built in the order given, spun together until any of them is
    finished; each one's outputs are closed in that order; the exit code is the first non-zero
    ``exit_code`` among them (0 if none)."""
    refused = refused_command_line(args)
    if refused is not None:
        print(f'error: {refused}', file=sys.stderr)
        return 2
    if usage is not None and help_requested(args):
        print(usage())
        return 0
    faulthandler.enable()  # a fatal signal or SIGABRT writes every thread's stack to stderr
    rclpy.init(args=args, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    stop: dict[str, float | None] = {'at': None}  # when a stop was asked for

    def on_signal(signum, frame):
        if stop['at'] is None:
            stop['at'] = time.monotonic()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    try:
        nodes = _built(makers)
        if isinstance(nodes, int):
            return nodes
        executor = make_executor()
        for node in nodes:
            executor.add_node(node)
        while rclpy.ok() and stop['at'] is None and not any(n.finished for n in nodes):
            executor.spin_once(timeout_sec=0.05)
        stopped_at = stop['at']
        reason = '' if stopped_at is None else ' on signal'
        for node in nodes:
            node.get_logger().info('shutting down' + reason)
        for node in nodes:
            node.close_outputs()
        tear_down(executor, nodes, teardown_limit_s(stopped_at))
        return next((int(n.exit_code) for n in nodes if n.exit_code), 0)
    finally:
        if rclpy.ok():
            rclpy.shutdown()
        # From here the process only tears down. A second SIGINT, as Ctrl-C in a launch sends one
        # to the group and launch forwards another, must not kill it half-way with the
        # interpreter's default handler.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
