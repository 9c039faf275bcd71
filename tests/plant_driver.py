"""Helpers for tests that drive a lockstep plant themselves, in place of the controller."""

from sensor_msgs.msg import JointState

from ato_ros.messages import qos_profile, to_time, topic


def plant_status(monitor):
    """(stamp, message, values) of every plant diagnostic the monitor received."""
    return [(stamp, message, values) for stamp, name, values, message in monitor.diagnostics
            if name == 'train_plant_node: simulation']


class ControllerStandIn:
    """Answers each lockstep step of a plant under test with a command of the test's choosing."""

    def __init__(self, stack):
        self.stack = stack
        self.publisher = stack.node.create_publisher(JointState, topic('command').name,
                                                     qos_profile(topic('command').qos))

    def answer(self, stamp_ns, efforts, names=('traction',)):
        """Wait for the step ``stamp_ns``, command it, and wait until the plant has advanced."""
        monitor = self.stack.monitor
        assert self.stack.spin_until(lambda: monitor.last_stamp_ns == stamp_ns, 120.0)
        msg = JointState(name=list(names), effort=list(efforts))
        msg.header.stamp = to_time(stamp_ns)
        self.publisher.publish(msg)
        assert self.stack.spin_until(lambda: monitor.last_stamp_ns > stamp_ns, 30.0)
