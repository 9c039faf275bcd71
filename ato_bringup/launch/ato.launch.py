"""The ATO stack: plant, profile and controller, in lockstep simulated time by default.

    ros2 launch ato_bringup ato.launch.py controller:=luo_xu scenario:=short_line

Arguments: controller (a law of ``ato_controller_node.laws.LAWS``; launch refuses any other
name before it starts a node), scenario (built-in name or YAML path), lockstep (true: the plant owns
/clock and the other nodes use it), rate_hz (control rate; 0: the scenario's), end_time_s (the
plant ends the run there and the launch shuts down; 0: run until Ctrl-C).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from ato_controller_node.laws import LAWS


def generate_launch_description():
    controller = LaunchConfiguration('controller')
    scenario = LaunchConfiguration('scenario')
    lockstep = ParameterValue(LaunchConfiguration('lockstep'), value_type=bool)
    rate_hz = ParameterValue(LaunchConfiguration('rate_hz'), value_type=float)
    end_time_s = ParameterValue(LaunchConfiguration('end_time_s'), value_type=float)

    plant = Node(package='train_plant_node', executable='train_plant_node',
                 name='train_plant_node', output='screen',
                 parameters=[{'scenario': scenario, 'lockstep': lockstep,
                              'control_rate_hz': rate_hz, 'end_time_s': end_time_s}])
    profile = Node(package='profile_node', executable='profile_node', name='profile_node',
                   output='screen',
                   parameters=[{'scenario': scenario, 'lockstep': lockstep,
                                'use_sim_time': lockstep}])
    ato = Node(package='ato_controller_node', executable='ato_controller_node',
               name='ato_controller_node', output='screen',
               parameters=[{'scenario': scenario, 'controller': controller,
                            'lockstep': lockstep, 'rate_hz': rate_hz,
                            'use_sim_time': lockstep}])
    return LaunchDescription([
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
        ato, profile, plant,
        # The plant ends the run: take the rest of the stack down with it.
        RegisterEventHandler(OnProcessExit(target_action=plant,
                                           on_exit=[EmitEvent(event=Shutdown(
                                               reason='the plant ended the run'))])),
    ])
