"""``ato param``, ``ato topic``, ``ato node``: the ``ros2 param``, ``ros2 topic`` and ``ros2 node``
commands the documentation uses, over rclpy, for the PyPI wheels (which have no ros2cli).

    ato param list /ato_controller_node
    ato param get /ato_controller_node controller
    ato param set /ato_controller_node controller luo_xu    # a refusal prints the reason, exit 1
    ato topic list [-t]
    ato topic echo /ato/command [--once] [--qos-history keep_last --qos-depth 10 ...]
    ato node list [-a]

Parameters go through the node's parameter services (``rclpy.parameter_client``); a value is
typed as ``ros2 param set`` types it (YAML: ``true``, ``3``, ``0.5``, else text). ``topic echo``
subscribes to one of the suite's topics with the QoS the suite publishes it with (the per-step
streams reliable and keep-all, ``ato_common.conventions``: every message, the publisher slowed
down to the pace of the printing if need be) and to any other topic with the reliability and
durability its publishers offer, keep-last 10, as ``ros2 topic echo`` does; ``--qos-*`` options
set any of them.
"""

from __future__ import annotations

import argparse
import array
import importlib
import os
import sys
import time
from contextlib import contextmanager
from typing import Iterator

import rclpy
import yaml
from rclpy.node import Node
from rclpy.parameter import get_parameter_value, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from ato_common.conventions import TOPICS
from ato_ros.lifecycle import make_executor
from ato_ros.messages import qos_profile

#: how long the graph is listened to before a list is printed, s (``--spin-time``)
DISCOVERY_S = 1.0
#: how long a node's parameter services or a topic's publishers are waited for, s
WAIT_S = 10.0


@contextmanager
def graph_node() -> Iterator[tuple[Node, object]]:
    """A hidden node (its name starts with ``_``, as ros2cli's) and its executor."""
    context = rclpy.Context()
    rclpy.init(context=context)
    node = Node(f'_ato_cli_{os.getpid()}', context=context, start_parameter_services=False)
    executor = make_executor(context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        if context.ok():
            rclpy.shutdown(context=context)


def spin_until(executor, done, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.05)
    return True


def absolute(name: str) -> str:
    """A node or topic name from the root namespace, as ros2cli expands it."""
    return name if name.startswith('/') else '/' + name


# --- ato param ------------------------------------------------------------------------------
LABELS = {bool: 'Boolean value is:', int: 'Integer value is:', float: 'Double value is:',
          str: 'String value is:'}


def _result(executor, future, what: str, timeout_s: float):
    if not spin_until(executor, future.done, timeout_s):
        raise TimeoutError(f'{what} did not answer within {timeout_s:g} s')
    return future.result()


def param(args: argparse.Namespace) -> int:
    target = absolute(args.node)
    with graph_node() as (node, executor):
        client = AsyncParameterClient(node, target)
        if not spin_until(executor, lambda: client.services_are_ready(), args.timeout):
            print(f'Node not found: {target} (its parameter services did not appear within '
                  f'{args.timeout:g} s)', file=sys.stderr)
            return 1
        if args.verb == 'list':
            names = _result(executor, client.list_parameters(), target, args.timeout)
            for name in sorted(names.result.names):
                print(f'  {name}')
            return 0
        if args.verb == 'get':
            values = _result(executor, client.get_parameters([args.name]), target,
                             args.timeout).values
            value = parameter_value_to_python(values[0]) if values else None
            if value is None:
                print('Parameter not set.', file=sys.stderr)
                return 1
            print(LABELS.get(type(value), 'Value is:'), value)
            return 0
        from rcl_interfaces.msg import Parameter
        request = [Parameter(name=args.name, value=get_parameter_value(args.value))]
        (result,) = _result(executor, client.set_parameters(request), target,
                            args.timeout).results
        if result.successful:
            print('Set parameter successful' + (f': {result.reason}' if result.reason else ''))
            return 0
        print('Setting parameter failed' + (f': {result.reason}' if result.reason else ''),
              file=sys.stderr)
        return 1


# --- ato topic ------------------------------------------------------------------------------
def suite_topic(name: str):
    """The suite's topic of that (absolute) name, or None."""
    return next((t for t in TOPICS.values() if absolute(t.name) == name), None)


def message_class(type_name: str):
    """``std_msgs/msg/String`` -> the rclpy message class."""
    package, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def plain(value):
    """A message as YAML-able data: fields in their order, arrays as lists."""
    if hasattr(value, 'get_fields_and_field_types'):
        return {name: plain(getattr(value, name)) for name in value.get_fields_and_field_types()}
    if isinstance(value, (list, tuple, array.array)) or hasattr(value, 'tolist'):
        items = value.tolist() if hasattr(value, 'tolist') else list(value)
        return [plain(v) for v in items] if isinstance(items, list) else items
    if isinstance(value, bytes):
        return list(value)
    return value


def echo_qos(args: argparse.Namespace, node: Node, name: str) -> QoSProfile:
    """The suite's QoS for its own topics, else what the publishers offer (keep last 10);
    each ``--qos-*`` option overrides its policy."""
    known = suite_topic(name)
    if known is not None:
        qos = qos_profile(known.qos)
    else:
        offered = [info.qos_profile for info in node.get_publishers_info_by_topic(name)]
        reliable = bool(offered) and all(
            q.reliability == ReliabilityPolicy.RELIABLE for q in offered)
        latched = bool(offered) and all(
            q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in offered)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE if reliable
                         else ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                         else DurabilityPolicy.VOLATILE)
    if args.qos_reliability:
        qos.reliability = ReliabilityPolicy[args.qos_reliability.upper()]
    if args.qos_durability:
        qos.durability = DurabilityPolicy[args.qos_durability.upper()]
    if args.qos_history:
        qos.history = HistoryPolicy[args.qos_history.upper()]
    if args.qos_depth is not None:
        qos.depth = args.qos_depth
    return qos


def topic_type(node: Node, executor, name: str, timeout_s: float) -> str | None:
    known = suite_topic(name)
    if known is not None:
        return known.type_name
    found: dict[str, list[str]] = {}

    def discovered() -> bool:
        found.update(node.get_topic_names_and_types())
        return name in found
    if not spin_until(executor, discovered, timeout_s):
        return None
    return found[name][0]


def topic(args: argparse.Namespace) -> int:
    with graph_node() as (node, executor):
        if args.verb == 'list':
            spin_until(executor, lambda: False, args.spin_time)
            for name, types in sorted(node.get_topic_names_and_types()):
                print(f'{name} [{", ".join(types)}]' if args.show_types else name)
            return 0
        name = absolute(args.topic)
        type_name = topic_type(node, executor, name, args.timeout)
        if type_name is None:
            print(f'Could not determine the type of {name}: no publisher appeared within '
                  f'{args.timeout:g} s', file=sys.stderr)
            return 1
        received = []

        def on_message(msg) -> None:
            received.append(1)
            print(yaml.safe_dump(plain(msg), sort_keys=False, default_flow_style=False)
                  + '---', flush=True)
        node.create_subscription(message_class(type_name), name, on_message,
                                 echo_qos(args, node, name))
        # until the first message with --once, else until Ctrl-C (ato: a clean exit 0)
        spin_until(executor, lambda: args.once and received, float('inf'))
        return 0


# --- ato node -------------------------------------------------------------------------------
def node_list(args: argparse.Namespace) -> int:
    with graph_node() as (node, executor):
        spin_until(executor, lambda: False, args.spin_time)
        names = sorted(namespace.rstrip('/') + '/' + name
                       for name, namespace in node.get_node_names_and_namespaces()
                       if args.all or not name.startswith('_'))
        for name in names:
            print(name)
        twice = sorted({name for name in names if names.count(name) > 1})
        if twice:  # as ros2 node list warns: parameters, services and logs get mixed up
            print(f'warning: several nodes have the same name: {", ".join(twice)}',
                  file=sys.stderr)
    return 0


def parser(command: str) -> argparse.ArgumentParser:
    """The command line of ``ato <command>`` (param, topic, node)."""
    top = argparse.ArgumentParser(prog=f'ato {command}', description=__doc__.split('\n\n')[0])
    verbs = top.add_subparsers(dest='verb', required=True)
    if command == 'param':
        for verb, extra in (('list', ()), ('get', ('name',)), ('set', ('name', 'value'))):
            sub = verbs.add_parser(verb)
            sub.add_argument('node')
            for name in extra:
                sub.add_argument(name)
            sub.add_argument('--timeout', type=float, default=WAIT_S,
                             help="wait this long for the node's parameter services, s")
    elif command == 'topic':
        listing = verbs.add_parser('list')
        listing.add_argument('-t', '--show-types', action='store_true')
        listing.add_argument('--spin-time', type=float, default=DISCOVERY_S)
        echo = verbs.add_parser('echo')
        echo.add_argument('topic')
        echo.add_argument('--once', action='store_true', help='print the first message, exit')
        echo.add_argument('--timeout', type=float, default=WAIT_S,
                          help="wait this long for a publisher of a topic not the suite's, s")
        echo.add_argument('--qos-reliability', choices=('reliable', 'best_effort'))
        echo.add_argument('--qos-durability', choices=('volatile', 'transient_local'))
        echo.add_argument('--qos-history', choices=('keep_last', 'keep_all'))
        echo.add_argument('--qos-depth', type=int)
    else:
        listing = verbs.add_parser('list')
        listing.add_argument('-a', '--all', action='store_true', help='hidden nodes too')
        listing.add_argument('--spin-time', type=float, default=DISCOVERY_S)
    return top


def main(command: str, argv: list[str]) -> int:
    args = parser(command).parse_args(argv)
    return {'param': param, 'topic': topic, 'node': node_list}[command](args)
