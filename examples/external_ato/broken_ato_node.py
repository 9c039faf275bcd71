#!/usr/bin/env python3
"""A deliberately broken ATO node: ``p_ato_node.py`` with five defects, one per case of the
contract that the conformance harness must catch (``tests/test_conformance.py``).

    ato conformance --controller-command "python3 examples/external_ato/broken_ato_node.py"

It still answers every step, stamps and lays out its commands right, once per step, and stops
when told, so those cases pass; these fail:

- ``refuses_other_scenario``: it never reads train/identity and drives any plant;
- ``survives_restart``: it takes a state stamped before its last step for a stale message and
  drops it, so a restarted plant waits for ever;
- ``failed_sensor``: it passes a NaN measurement into its law and commands NaN;
- ``follows_replanned_reference``: it tracks the latched first plan (ato/reference/curve) at the
  state's run time instead of the streamed reference;
- ``no_command_after_shutdown``: on SIGINT it publishes a last "safe" zero command.
"""

import signal
import sys
import time

import rclpy
from p_ato_node import LATCHED, PAtoNode
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory


class BrokenAtoNode(PAtoNode):
    def __init__(self):
        super().__init__()
        self.identified = True  # defect: any plant will do, from the first state
        self.curve = None
        self.create_subscription(JointTrajectory, 'ato/reference/curve', self.on_curve, LATCHED)

    def on_identity(self, msg) -> None:
        pass  # defect: never read

    def on_curve(self, msg: JointTrajectory) -> None:
        self.curve = msg

    def try_step(self, stamp: int) -> None:
        if 0 <= stamp < self.last_stamp:
            return  # defect: "stale", and a restarted plant is never answered
        super().try_step(stamp)

    def target(self, reference, point):
        """Defect: the first plan's curve at the state's run time, whatever was replanned."""
        if self.curve is None:
            return reference.points[0]
        now = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
        return min(self.curve.points, key=lambda p: abs(
            p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 - now))

    def force(self, position: float, speed: float, target) -> float:
        p = {name: self.get_parameter(name).value for name in ('mass_kg', 'kv', 'kx')}
        # defect: no check of the measurement, a NaN goes straight into the command
        return p['mass_kg'] * (target.accelerations[0] + p['kv'] * (target.velocities[0] - speed)
                               + p['kx'] * (target.positions[0] - position))


def main() -> int:
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    node = BrokenAtoNode()
    while not stop:
        rclpy.spin_once(node, timeout_sec=0.1)
    # defect: a last "safe" command after being told to stop
    actuators = list(node.get_parameter('actuators').value)
    node.command_pub.publish(JointState(name=actuators, effort=[0.0] * len(actuators)))
    time.sleep(0.2)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
