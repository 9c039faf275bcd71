"""The ATO stack: plant, profile and controller, in lockstep simulated time by default.

    ros2 launch ato_bringup ato.launch.py controller:=luo_xu scenario:=short_line
    ros2 launch ato_bringup ato.launch.py namespace:=train1 end_time_s:=300   # beside others

Arguments: controller (a law of ``ato_controller_node.laws.LAWS``; launch refuses any other
name before it starts a node), scenario (built-in name or YAML path), lockstep (true: the plant owns
/clock and the other nodes use it), rate_hz (control rate; 0: the scenario's), end_time_s (the
plant ends the run there and the launch shuts down; 0: run until Ctrl-C), namespace (push the
stack into it, with a /clock of its own, so several stacks run side by side in one domain),
composed (true: the three nodes in one process on one executor, ``ros2 run ato_bringup
ato_stack``, with the same names, topics and results; Python nodes cannot be loaded into an
rclcpp component container, which takes only C++ components, so the suite composes them itself:
``ato_bringup.composed``).

Any node's exit ends the launch. A node that ends with code 0 (the plant at end_time_s) shuts the
launch down with that reason; one that fails (any other code) is reported as an error naming
the node and its exit code, and ``ros2 launch`` then exits with 1 (the handler raises
:class:`NodeFailed`: launch logs an exception in a handler as an error, shuts everything down
and returns 1, the only way a launch file sets its exit code).

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
    OpaqueFunction,
    RegisterEventHandler,
    SetEnvironmentVariable,
)
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from ato_common.conventions import normalised_namespace, stack_remaps
from ato_controller_node.laws import LAWS
from ato_ros.middleware import middleware_defaults

NODES = ('ato_controller_node', 'profile_node', 'train_plant_node')


class NodeFailed(RuntimeError):
    """A node of the stack exited with a non-zero code: the launch ends with 1."""


def exit_handler(name: str):
    """What the launch does when node ``name`` exits: (event, context) -> actions."""
    def on_exit(event, context):
        code = event.returncode
        if code == 0:
            return [EmitEvent(event=Shutdown(reason=f'{name} ended (exit code 0): the run is '
                                                    'over, stopping the stack'))]
        raise NodeFailed(f'{name} exited with code {code}: the run has failed, stopping the '
                         'stack (its output above says why)')
    return on_exit


COMPOSED = ('ato_bringup', 'ato_stack')


def composed_parameters(configurations: dict[str, str]) -> dict[str, dict]:
    """A parameters file's content for the composed process: a section per node (the one
    process takes a single file; each node reads its own section)."""
    value = {key: yaml.safe_load(configurations[key])
             for key in ('lockstep', 'rate_hz', 'end_time_s')}
    scenario, lockstep = configurations['scenario'], bool(value['lockstep'])
    parameters = {
        'ato_controller_node': {'scenario': scenario, 'controller': configurations['controller'],
                                'lockstep': lockstep, 'rate_hz': float(value['rate_hz'])},
        'profile_node': {'scenario': scenario, 'lockstep': lockstep},
        'train_plant_node': {'scenario': scenario, 'lockstep': lockstep,
                             'control_rate_hz': float(value['rate_hz']),
                             'end_time_s': float(value['end_time_s'])},
    }
    return {f'/**/{name}': {'ros__parameters': parameters[name]} for name in NODES}


def stack(context):
    """The three nodes in the namespace, each watched: its exit ends the launch (composed: the
    one process, watched the same way)."""
    namespace = normalised_namespace(context.launch_configurations['namespace'])
    # /clock into the namespace too (ato_common.conventions.stack_remaps): every use_sim_time
    # node follows the /clock it hears, so stacks side by side need a clock each.
    remappings = [(source, target) for source, target in stack_remaps(namespace)
                  if source != '__ns']
    if yaml.safe_load(context.launch_configurations.get('composed', 'false')):
        with tempfile.NamedTemporaryFile('w', prefix='ato_stack_', suffix='.yaml',
                                         delete=False) as handle:
            yaml.safe_dump(composed_parameters(context.launch_configurations), handle)
        package, executable = COMPOSED
        # No name: it would rename all three nodes of the process to one.
        node = Node(package=package, executable=executable, namespace=namespace,
                    output='screen', parameters=[handle.name], remappings=remappings)
        return [node, RegisterEventHandler(OnProcessExit(
            target_action=node, on_exit=exit_handler(f'{executable} (the composed stack)')))]
    controller = LaunchConfiguration('controller')
    scenario = LaunchConfiguration('scenario')
    lockstep = ParameterValue(LaunchConfiguration('lockstep'), value_type=bool)
    rate_hz = ParameterValue(LaunchConfiguration('rate_hz'), value_type=float)
    end_time_s = ParameterValue(LaunchConfiguration('end_time_s'), value_type=float)
    # The profile and the controller follow the stamps of /clock and of the messages in
    # lockstep: no use_sim_time (it would cost each a /clock subscription taking every step).
    parameters = {
        'ato_controller_node': {'scenario': scenario, 'controller': controller,
                                'lockstep': lockstep, 'rate_hz': rate_hz},
        'profile_node': {'scenario': scenario, 'lockstep': lockstep},
        'train_plant_node': {'scenario': scenario, 'lockstep': lockstep,
                             'control_rate_hz': rate_hz, 'end_time_s': end_time_s},
    }
    entities = []
    for name in NODES:
        node = Node(package=name, executable=name, name=name, namespace=namespace,
                    output='screen', parameters=[parameters[name]], remappings=remappings)
        entities += [node, RegisterEventHandler(OnProcessExit(target_action=node,
                                                              on_exit=exit_handler(name)))]
    return entities


def generate_launch_description():
    # The suite's middleware settings for the nodes on one host, unless the user set their own
    # (ato_ros.middleware: shared memory only, heartbeats every 0.1 s).
    environment = [SetEnvironmentVariable(name, value)
                   for name, value in middleware_defaults(os.environ).items()]
    return LaunchDescription([
        *environment,
        DeclareLaunchArgument('controller', default_value='pid', choices=sorted(LAWS),
                              description='control law, one of the registry: '
                              + ', '.join(sorted(LAWS))),
        DeclareLaunchArgument('scenario', default_value='short_line',
                              description='built-in scenario name or path to a scenario YAML'),
        DeclareLaunchArgument('lockstep', default_value='true',
                              description='lockstep simulated time (false: real time)'),
        DeclareLaunchArgument('rate_hz', default_value='0.0',
                              description="control rate, Hz (0: the scenario's)"),
        DeclareLaunchArgument('end_time_s', default_value='0.0',
                              description='simulated time at which the run ends (0: never)'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='push the stack into this namespace, with its own '
                                          '/clock (several stacks in one domain)'),
        DeclareLaunchArgument('composed', default_value='false',
                              description='true: the three nodes in one process on one '
                                          'executor (ato_stack) instead of three processes'),
        OpaqueFunction(function=stack),
    ])
