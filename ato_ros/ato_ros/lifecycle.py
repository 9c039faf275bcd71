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
import time
from typing import Callable, Iterable, Sequence

import rclpy
import rclpy.exceptions
import rclpy.signals

from ato_common.commands import ros_command
from ato_ros.publishing import shared_step_recorders


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
# context takes longer than this (a rare middleware hang), every thread's Python stack is written
# to stderr and the process exits with code 1, instead of waiting for its supervisor's SIGKILL.
TEARDOWN_LIMIT_S = 5.0
# A node told to stop (SIGINT, SIGTERM) is gone within this much wall time: a launch escalates
# SIGINT to SIGTERM after 5 s (``sigterm_timeout``) and logs it as an error. Closing the outputs
# (the plant's wait for its last messages' acknowledgement, ``final_delivery_timeout_s``) takes
# its part first; the teardown gets what is left, at least ``LEAST_TEARDOWN_S`` (a teardown
# takes a few tenths of a second).
STOP_BUDGET_S = 4.0
LEAST_TEARDOWN_S = 1.0


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
    """The time the teardown may take: ``TEARDOWN_LIMIT_S`` for a node that ended by itself,
    what is left of ``STOP_BUDGET_S`` (at least ``LEAST_TEARDOWN_S``) for one told to stop at
    ``stopped_at`` (``time.monotonic()``)."""
    if stopped_at is None:
        return TEARDOWN_LIMIT_S
    left = STOP_BUDGET_S - (time.monotonic() - stopped_at)
    return min(TEARDOWN_LIMIT_S, max(LEAST_TEARDOWN_S, left))


def tear_down(executor, node: RunNodeHooks | Sequence[RunNodeHooks],
              limit_s: float | None = None) -> None:
    """Shut the executor down (it lets go of every entity while the context is still valid),
    then destroy the node (or each of the nodes), within ``limit_s`` (default
    ``TEARDOWN_LIMIT_S``): past it, faulthandler writes every thread's stack to stderr and the
    process exits with code 1. The caller shuts rclpy down."""
    limit_s = TEARDOWN_LIMIT_S if limit_s is None else limit_s
    faulthandler.dump_traceback_later(limit_s, exit=True)
    executor.shutdown(timeout_sec=limit_s)
    for each in (node if isinstance(node, (list, tuple)) else (node,)):
        each.destroy_node()


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
    file, with no time limit), then, within ``TEARDOWN_LIMIT_S`` (a node told to stop: what is
    left of ``STOP_BUDGET_S``, :func:`teardown_limit_s`), the executor (it lets go of
    every entity while the context is still valid), the node, the context.

    ``usage``: the text ``-h``/``--help`` prints (then the node exits 0 without starting)."""
    return run_nodes((make_node,), args, usage)


def _built(makers: Sequence[Callable[[], RunNodeHooks]]) -> list[RunNodeHooks] | int:
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
