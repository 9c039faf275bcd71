"""ato_stack: the plant, the profile and the controller in one process, on one executor.

    ros2 run ato_bringup ato_stack --ros-args --params-file stack.yaml
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

The process ends when any of the nodes is finished (the plant at ``end_time_s``; the profile or
the controller refusing another scenario's plant) or on SIGINT/SIGTERM; its exit code is the
first non-zero one of the nodes (0 for a run that reached its end). A lockstep run composed
gives the same state sequence, bit for bit, as the same run in three processes
(``tests/test_lockstep_graph.py``).
"""

from __future__ import annotations

from ato_ros.interrupts import quiet_until_running

NODES = ('train_plant_node', 'profile_node', 'ato_controller_node')


def usage() -> str:
    from ato_controller_node import node as controller
    from ato_ros.lifecycle import node_usage
    from profile_node import node as profile
    from train_plant_node import node as plant
    parts = [__doc__.strip().split('\n\n')[0], '']
    for name, module, params in (
            ('train_plant_node', plant, plant.PARAMS), ('profile_node', profile, profile.PARAMS),
            ('ato_controller_node', controller,
             controller.NODE_PARAMS + tuple(controller.gain_params()))):
        parts += [f'--- {name} (a section /**/{name} of the parameters file) ---',
                  node_usage(name, name, module.__doc__, params), '']
    return '\n'.join(parts)


def main(args=None) -> int:
    quiet_until_running()  # a stop while importing ends the process cleanly
    from ato_controller_node.node import AtoControllerNode
    from ato_ros.lifecycle import run_nodes
    from profile_node.node import ProfileNode
    from train_plant_node.node import TrainPlantNode
    # The plant first: its latched identity is there when the others subscribe.
    return run_nodes((TrainPlantNode, ProfileNode, AtoControllerNode), args, usage=usage)


if __name__ == '__main__':
    raise SystemExit(main())
