#!/usr/bin/env python3
"""A minimal ATO node of your own, written from the ATO node contract alone
(docs/reference/ato-contract.md): rclpy and common_interfaces messages, nothing of the suite.

    ato run ato_bringup run_scenario \
        --controller-command "python3 examples/external_ato/p_ato_node.py"
    ato conformance --controller-command "python3 examples/external_ato/p_ato_node.py"

Its law: the force that gives the reference's acceleration plus a correction proportional to the
speed and position errors, F = m (a* + kv (v* - v) + kx (x* - x)), within the train's traction
and service brake, shared equally by the actuators. The defaults are the nominal values of the
default scenario's train (short_line: CRH3, Luo & Xu); give your train's as parameters
(``--ros-args -p mass_kg:=... -p actuators:="[car_2, car_3]"``).

What the contract asks, and where it is done here: the scenario named in train/identity is the
one it was started for, else it commands nothing and exits with 2 (``on_identity``; no command
before the identity is read: on a loaded machine the first states can come before it); one command
per step, stamped with the step, when the state and the reference of that stamp are both there,
the same command again for a step sent again (``try_step``); a state stamped before the last
step starts the law again (``restart``); a NaN measurement holds the last force; SIGINT or
SIGTERM end it with 0 and nothing published after (rclpy's signal handling shuts the context
down). It declares the ``gradient_known`` parameter and ignores it: its law uses no gradient
profile.
"""

import json
import math
import sys
from pathlib import Path

import rclpy
import yaml
from builtin_interfaces.msg import Time
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from trajectory_msgs.msg import JointTrajectory

# The contract's QoS: the per-step streams reliable, volatile, keep all; the identity latched.
STREAM = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                    durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
LAW = 'p_example'


def scenario_name(scenario: str) -> str:
    """The name a scenario goes by in the plant's identity: a file's ``name:``, else itself."""
    path = Path(scenario)
    if path.suffix in ('.yaml', '.yml') and path.is_file():
        return str(yaml.safe_load(path.read_text()).get('name', ''))
    return scenario


def nanoseconds(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class PAtoNode(Node):
    def __init__(self):
        super().__init__('p_ato_node')
        self.declare_parameter('scenario', '')
        self.declare_parameter('mass_kg', 510000.0)
        self.declare_parameter('max_traction_n', 300000.0)
        self.declare_parameter('max_brake_n', 459000.0)
        self.declare_parameter('kv', 0.3)   # 1/s
        self.declare_parameter('kx', 0.02)  # 1/s^2
        self.declare_parameter('actuators', ['traction'])
        # The contract's knowledge parameter: whether the line's gradients may be used. This
        # law uses no gradient profile (no feed-forward of the grade: the speed and position
        # feedback absorb it), so it is the same law either way: declared to say so.
        known = self.declare_parameter('gradient_known', True).value
        self.get_logger().info(f'gradient_known={known}: this law uses no gradient profile')
        self.expected = scenario_name(self.get_parameter('scenario').value)
        self.exit_code = 0
        self.done = False
        self.identified = False  # the plant's identity read, and the one expected
        self.states, self.references = {}, {}
        self.last_stamp = -1
        self.last_command = None
        self.last_force = 0.0
        self.command_pub = self.create_publisher(JointState, 'ato/command', STREAM)
        self.create_subscription(JointTrajectory, 'train/state/measured', self.on_state, STREAM)
        self.create_subscription(JointTrajectory, 'ato/reference', self.on_reference, STREAM)
        self.create_subscription(String, 'train/identity', self.on_identity, LATCHED)

    def on_identity(self, msg: String) -> None:
        plant = json.loads(msg.data).get('scenario')
        if plant != self.expected:
            self.get_logger().error(f'the plant simulates {plant}, I was started for '
                                    f'{self.expected}: refusing to drive')
            self.exit_code, self.done = 2, True
            return
        self.identified = True
        for stamp in sorted(self.states):  # the steps that came before it
            self.try_step(stamp)

    def on_state(self, msg: JointTrajectory) -> None:
        stamp = nanoseconds(msg.header.stamp)
        self.states[stamp] = msg
        self.try_step(stamp)

    def on_reference(self, msg: JointTrajectory) -> None:
        stamp = nanoseconds(msg.header.stamp)
        self.references[stamp] = msg
        self.try_step(stamp)

    def try_step(self, stamp: int) -> None:
        if self.done or not self.identified:
            return
        if stamp == self.last_stamp:  # the step sent again: the same command again
            if self.states.pop(stamp, None) is not None and self.last_command is not None:
                self.command_pub.publish(self.last_command)
            return
        if stamp not in self.states or stamp not in self.references:
            return
        if stamp < self.last_stamp:
            self.restart(stamp)
        point = self.states.pop(stamp).points[0]
        target = self.target(self.references.pop(stamp), point)
        self.states = {k: v for k, v in self.states.items() if k > stamp}
        self.references = {k: v for k, v in self.references.items() if k > stamp}
        self.last_force = self.force(point.positions[0], point.velocities[0], target)
        actuators = list(self.get_parameter('actuators').value)
        command = JointState(name=actuators,
                             effort=[self.last_force / len(actuators)] * len(actuators))
        command.header.stamp = Time(sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
        command.header.frame_id = LAW
        self.command_pub.publish(command)
        self.last_stamp, self.last_command = stamp, command

    def target(self, reference: JointTrajectory, point):
        """The target now: the streamed reference's first point (it replans: never the
        latched first plan)."""
        return reference.points[0]

    def force(self, position: float, speed: float, target) -> float:
        """m (a* + kv (v* - v) + kx (x* - x)) within traction and service brake; a NaN
        measurement (a failed sensor) holds the last force."""
        if not (math.isfinite(position) and math.isfinite(speed)):
            return self.last_force
        p = {name: self.get_parameter(name).value
             for name in ('mass_kg', 'kv', 'kx', 'max_traction_n', 'max_brake_n')}
        wanted = p['mass_kg'] * (target.accelerations[0]
                                 + p['kv'] * (target.velocities[0] - speed)
                                 + p['kx'] * (target.positions[0] - position))
        return min(p['max_traction_n'], max(-p['max_brake_n'], wanted))

    def restart(self, stamp: int) -> None:
        self.get_logger().warning(f'state stamped {stamp / 1e9:.3f} s, before my last step: '
                                  'the plant started again, so does the law')
        self.last_stamp, self.last_command, self.last_force = -1, None, 0.0
        self.states = {k: v for k, v in self.states.items() if k <= stamp}
        self.references = {k: v for k, v in self.references.items() if k <= stamp}


def main() -> int:
    rclpy.init()  # its signal handlers: SIGINT and SIGTERM shut the context down
    node = PAtoNode()
    try:
        while rclpy.ok() and not node.done:
            rclpy.spin_once(node, timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return node.exit_code


if __name__ == '__main__':
    sys.exit(main())
