"""ato_stack: the plant, the profile and the controller in one process, on one executor.

    ros2 run ato_bringup ato_stack --ros-args --params-file stack.yaml
    ros2 run ato_bringup ato_stack --record -o runs/my_run --ros-args --params-file stack.yaml
    ros2 launch ato_bringup ato.launch.py composed:=true

This is what ROS 2 composition does for C++ components, done for the suite's Python nodes:
rclcpp component containers load only C++ components (shared libraries with a registered
``rclcpp_components`` factory), so rclpy nodes cannot go into one. The three nodes are the same
classes the separate executables run, built in one rclpy context and spun by one executor
(``ato_ros.lifecycle.run_nodes``); their messages still go through the middleware (rclpy has no
intra-process transport), as standard messages on the same topics, but a step's messages no
longer wake three processes. Each node keeps its own name, parameters, services and
diagnostics: per-node parameters come from a parameters file with a section per node
(``/**/train_plant_node: {ros__parameters: {...}}``; a ``-p name:=value`` applies to all three).

``--record`` adds the recorder to the process (``recorder.node``; what follows ``--record`` up to
``--ros-args`` are the recorder's own options, ``-o FOLDER`` among them; the recorder's time is
the simulated time of the step records, as ``--sim-time``). It takes the per-step messages of the
loop nodes from them directly, without the middleware, and writes them at once with the Foxglove
SDK's compiled MCAP writer, on the loop's thread (``recorder.node`` says why); the other topics
(the diagnostics, the target curve, ...) it subscribes to as a recorder in its own process does.
It is built after the loop nodes and its bag is closed after theirs have handed on their last
steps.

The process ends when any of the nodes is finished (the plant at ``end_time_s``; the profile or
the controller refusing another scenario's plant) or on SIGINT/SIGTERM; its exit code is the
first non-zero one of the nodes (0 for a run that reached its end). A lockstep run composed
gives the same state sequence, bit for bit, as the same run in three processes
(``tests/test_lockstep_graph.py``).
"""

from __future__ import annotations

import sys
from typing import Callable

from ato_ros.interrupts import quiet_until_running

NODES = ('train_plant_node', 'profile_node', 'ato_controller_node')


def usage() -> str:
    from ato_common.commands import ros_command
    from ato_controller_node import node as controller
    from ato_ros.lifecycle import node_usage
    from profile_node import node as profile
    from train_plant_node import node as plant
    parts = [__doc__.strip().split('\n\n')[0], '',
             'usage: ato_stack [--record RECORDER_OPTIONS...] [--ros-args ...]', '',
             f'--record: record in the process ({ros_command("run recorder recorder --help")} '
             'lists the options)', '']
    for name, module, params in (
            ('train_plant_node', plant, plant.PARAMS), ('profile_node', profile, profile.PARAMS),
            ('ato_controller_node', controller,
             controller.NODE_PARAMS + tuple(controller.gain_params()))):
        parts += [f'--- {name} (a section /**/{name} of the parameters file) ---',
                  node_usage(name, name, module.__doc__, params), '']
    return '\n'.join(parts)


def main(args=None) -> int:
    quiet_until_running()  # a stop while importing ends the process cleanly
    from rclpy.utilities import remove_ros_args

    from ato_common.validation import ConfigError
    from ato_controller_node.node import AtoControllerNode
    from ato_ros.lifecycle import RunNodeHooks, help_requested, run_nodes
    from profile_node.node import ProfileNode
    from train_plant_node.node import TrainPlantNode
    argv = remove_ros_args(args if args is not None else sys.argv)[1:]
    # The plant first: its latched identity is there when the others subscribe.
    makers: list[Callable[[], RunNodeHooks]] = [TrainPlantNode, ProfileNode,
                                                AtoControllerNode]
    recorder = None
    if argv and argv[0] == '--record' and not help_requested(args):
        from recorder.node import InProcessRecorder
        try:
            recorder = InProcessRecorder(argv[1:])
        except ConfigError as error:
            print(f'error: {error}', file=sys.stderr)
            return 2
        makers.append(recorder)  # last: the loop nodes' step recorders exist
    elif argv and not help_requested(args):
        print(f'error: unknown arguments {" ".join(argv)} (ato_stack takes --record and '
              '--ros-args)', file=sys.stderr)
        return 2
    try:
        return run_nodes(makers, args, usage=usage)
    finally:
        if recorder is not None:
            recorder.release()


if __name__ == '__main__':
    raise SystemExit(main())
