"""The ATO stack: plant, profile and controller, in lockstep simulated time by default.

    ros2 launch ato_bringup ato.launch.py controller:=luo_xu scenario:=short_line
    ros2 launch ato_bringup ato.launch.py namespace:=train1 end_time_s:=300   # beside others
    ato launch ato_bringup ato.launch.py scenario:=mao_4car controller:=mao_multibody_rigid

(``ato launch``: the suite's launcher for the PyPI wheels, which have no ``ros2``; the same
arguments, nodes and parameters.) The arguments and what they start are defined once, in
``ato_bringup.launch_arguments`` (``ros2 launch ... --show-args`` lists them): controller,
scenario, model (``auto``: the scenario's, multi_car for a train described car by car), lockstep,
rate_hz (0: the scenario's, or the first faster rate the law accepts), end_time_s (default: the
scenario's end; ``never``: run until Ctrl-C), namespace (push the stack into it, with a /clock of
its own, so several stacks run side by side in one domain) and composed (true: the three nodes in
one process on one executor, ``ato_stack``, with the same names, topics and results; Python
nodes cannot be loaded into an rclcpp component container, which takes only C++ components, so
the suite composes them itself: ``ato_bringup.composed``). Arguments that cannot make a run (a
law that cannot drive the plant it would be given, a malformed scenario) are refused with the
reason before any node starts; ``ros2 launch`` then exits with 1 (``ato launch``: 2).

Any node's exit ends the launch. A node that ends with code 0 (the plant at end_time_s) shuts the
launch down with that reason; one that fails (any other code) is reported as an error naming
the node and its exit code, and ``ros2 launch`` then exits with 1 (the handler raises
:class:`NodeFailed`: launch logs an exception in a handler as an error, shuts everything down
and returns 1, the only way a launch file sets its exit code). Once the launch is shutting down
(Ctrl-C, or a node's end) the nodes' exits are expected and the launch ends with its own code:
0 after Ctrl-C.

The nodes get the suite's middleware settings (``ato_ros.middleware``: Fast DDS over shared
memory only, a reliable writer's heartbeat every 0.1 s) unless the environment sets its own.
"""

import os
import tempfile

import yaml
from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    EmitEvent,
    LogInfo,
    OpaqueFunction,
    RegisterEventHandler,
    SetEnvironmentVariable,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from ato_bringup.launch_arguments import COMPOSED, NODES, LaunchRefused, arguments, resolve
from ato_ros.middleware import middleware_defaults


class NodeFailed(RuntimeError):
    """A node of the stack exited with a non-zero code: the launch ends with 1."""


def exit_handler(name: str):
    """What the launch does when node ``name`` exits: (event, context) -> actions."""
    def on_exit(event, context):
        if context.is_shutdown:
            return None  # the launch is stopping (Ctrl-C, another node's end): expected
        code = event.returncode
        if code == 0:
            reason = f'{name} ended (exit code 0): the run is over, stopping the stack'
            return [LogInfo(msg=reason), EmitEvent(event=Shutdown(reason=reason))]
        raise NodeFailed(f'{name} exited with code {code}: the run has failed, stopping the '
                         'stack (its output above says why)')
    return on_exit


def typed(parameters: dict) -> dict:
    """A node's parameters for launch_ros, which reads a plain text value as YAML (a scenario
    named ``on`` would become true): text is passed as text."""
    return {name: ParameterValue(value, value_type=str) if isinstance(value, str) else value
            for name, value in parameters.items()}


def stack(context):
    """The three nodes in the namespace, each watched: its exit ends the launch (composed: the
    one process, watched the same way)."""
    try:
        launch = resolve(context.launch_configurations)
    except LaunchRefused as error:  # launch logs it as an error and exits with 1
        raise LaunchRefused(f'ato.launch.py: {error}') from None
    entities = [LogInfo(msg=note) for note in launch.notes]
    # /clock into the namespace too (ato_common.conventions.stack_remaps): every use_sim_time
    # node follows the /clock it hears, so stacks side by side need a clock each.
    remappings = launch.remappings()
    if launch.composed:
        with tempfile.NamedTemporaryFile('w', prefix='ato_stack_', suffix='.yaml',
                                         delete=False) as handle:
            yaml.safe_dump(launch.parameter_sections(), handle)
        package, executable = COMPOSED
        # No name: it would rename all three nodes of the process to one.
        node = Node(package=package, executable=executable, namespace=launch.namespace,
                    output='screen', parameters=[handle.name], remappings=remappings)
        return entities + [node, RegisterEventHandler(OnProcessExit(
            target_action=node, on_exit=exit_handler(f'{executable} (the composed stack)')))]
    # The profile and the controller follow the stamps of /clock and of the messages in
    # lockstep: no use_sim_time (it would cost each a /clock subscription taking every step).
    parameters = launch.parameters()
    for name in NODES:
        node = Node(package=name, executable=name, name=name, namespace=launch.namespace,
                    output='screen', parameters=[typed(parameters[name])],
                    remappings=remappings)
        entities += [node, RegisterEventHandler(OnProcessExit(target_action=node,
                                                              on_exit=exit_handler(name)))]
    return entities


def generate_launch_description():
    # The suite's middleware settings for the nodes on one host, unless the user set their own
    # (ato_ros.middleware: shared memory only, heartbeats every 0.1 s).
    environment = [SetEnvironmentVariable(name, value)
                   for name, value in middleware_defaults(os.environ).items()]
    declared = [DeclareLaunchArgument(a.name, default_value=a.default, description=a.description,
                                      **({'choices': list(a.choices)} if a.choices else {}))
                for a in arguments()]
    return LaunchDescription([*environment, *declared, OpaqueFunction(function=stack)])
