"""Topic names and QoS of the suite: the one place they are defined.

Names of the suite's own topics are relative, so a whole stack can be pushed into a namespace
(``--ros-args -r __ns:=/train1``); ``/clock`` and ``/diagnostics`` are global by ROS convention.
A stack pushed into a namespace beside others also remaps ``/clock`` into it
(:func:`stack_remaps`), since every ``use_sim_time`` node follows whatever ``/clock`` it hears.
The QoS is described here as plain data (no rclpy import) and turned into rclpy profiles by
:func:`ato_ros.messages.qos_profile`.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class QosSpec:
    reliable: bool
    transient_local: bool
    depth: int  # 0: keep all

    def describe(self) -> str:
        history = f'keep last {self.depth}' if self.depth else 'keep all'
        return (f"{'reliable' if self.reliable else 'best effort'}, "
                f"{'transient local' if self.transient_local else 'volatile'}, {history}")


# Lockstep streams: every message matters (a lost one stalls or skews a step, or leaves a hole
# in a recording). A monitor or recorder may lag behind the loop: with reliable keep-all the
# publisher keeps what a reader has not acknowledged (and blocks when its resource limits are
# reached) instead of overwriting it, so nothing is lost.
STREAM = QosSpec(reliable=True, transient_local=False, depth=0)
# Data a late joiner needs (the whole target curve): latched.
LATCHED = QosSpec(reliable=True, transient_local=True, depth=1)
CLOCK = QosSpec(reliable=True, transient_local=False, depth=10)
# A status sent once (a replan, a safety reaction) must reach a run monitor that lags: /diagnostics
# is unkeyed, so a keep-last reader keeps one history for all its publishers, and at a lockstep's
# pace ten statuses of three nodes pass in a few ms of wall time (a monitor on a loaded machine
# lost a replan's status that way). Keep-all, as the streams.
DIAGNOSTICS = QosSpec(reliable=True, transient_local=False, depth=0)
# Only the latest acknowledgement of each recorder matters; several recorders share the topic.
# Transient local: discovery is not symmetric, and a plant that already waits for a recorder
# may match its acknowledgements only after they were sent; it then gets the latest one (each
# recorder keeps its own) instead of waiting for one that no new step record will bring.
ACKNOWLEDGEMENTS = QosSpec(reliable=True, transient_local=True, depth=10)


# How often each topic is published. Per lockstep step the loop needs only the measured state,
# the reference, the command and /clock; on a 2-core machine every other per-step message costs
# CPU in rclpy (about 0.1 ms per publish and per take), so the observation topics are published
# only while someone subscribes (``ato_ros.publishing.Observation``): a recorder or any subscriber
# that keeps its messages (reliable) gets every step, one that only samples (best effort: the
# live view) gets the latest at most every 0.02 s of wall time, and a run nobody
# watches does not pay for them.
EVERY_STEP = 'every control step'
OBSERVED_STEP = ('every control step while it has a subscriber (nothing is published while '
                 'nobody subscribes; at most every 0.02 s of wall time while every subscriber '
                 'only samples: best effort)')
ONCE = 'once at start-up (latched)'


@dataclass(frozen=True)
class Topic:
    name: str
    type_name: str
    qos: QosSpec
    units: str
    publisher: str
    subscribers: str
    description: str
    rate: str = ''  # how often it is published (the topics reference page shows it)


TOPICS = {
    'clock': Topic('/clock', 'rosgraph_msgs/msg/Clock', CLOCK, 's',
                   'train_plant_node (lockstep)',
                   'profile_node (its lockstep ticks), every node with use_sim_time',
                   'simulated time; advances one control period per command',
                   rate=EVERY_STEP + ' (lockstep only)'),
    'state': Topic('train/state', 'trajectory_msgs/msg/JointTrajectory', STREAM,
                   'm, m/s, m/s^2, N', 'train_plant_node',
                   'the run monitor of run_scenario, recorder',
                   'true state of every car: one point, positions/velocities/accelerations/'
                   'effort per car (joint_names = car names, lead car first)',
                   rate=OBSERVED_STEP),
    'state_measured': Topic('train/state/measured', 'trajectory_msgs/msg/JointTrajectory', STREAM,
                            'm, m/s, m/s^2, N', 'train_plant_node', 'ato_controller_node',
                            'what the on-board sensors report, same layout as train/state',
                            rate=EVERY_STEP),
    'reference': Topic('ato/reference', 'trajectory_msgs/msg/JointTrajectory', STREAM,
                       'm, m/s, m/s^2, m/s^3', 'profile_node',
                       'ato_controller_node, run_scenario',
                       'target position/speed/acceleration now (points[0]) and a preview '
                       '(time_from_start); jerk in effort; joint_names = ["train"]',
                       rate=EVERY_STEP + ' (in lockstep one step ahead)'),
    'curve': Topic('ato/reference/curve', 'trajectory_msgs/msg/JointTrajectory', LATCHED,
                   'm, m/s, m/s^2', 'profile_node', 'visualisers, late joiners',
                   'the whole time-parameterised target curve, sampled',
                   rate=ONCE),
    'distance_to_go': Topic('ato/distance_to_go', 'std_msgs/msg/Float64', STREAM, 'm',
                            'profile_node', 'visualisers',
                            'distance from the reference position to the next target (a lower '
                            'speed limit or the next stop)',
                            rate=OBSERVED_STEP),
    'permitted_speed': Topic('ato/permitted_speed', 'std_msgs/msg/Float64', STREAM, 'm/s',
                             'profile_node', 'visualisers',
                             'permitted speed at the reference position (static limits and '
                             'braking curves)',
                             rate=OBSERVED_STEP),
    'command': Topic('ato/command', 'sensor_msgs/msg/JointState', STREAM, 'N',
                     'ato_controller_node', 'train_plant_node, run_scenario',
                     'force per actuated unit in effort (name = actuator names); '
                     'header.frame_id = registry name of the law that produced it',
                     rate=EVERY_STEP),
    'actuators_commanded': Topic('train/actuators/commanded', 'sensor_msgs/msg/JointState', STREAM,
                                 'N', 'train_plant_node', 'recorder, evaluation',
                                 'force per actuated unit as commanded (the held ATO command), '
                                 'effort per name = actuator names; stamped like train/state',
                                 rate=OBSERVED_STEP),
    'actuators_applied': Topic('train/actuators/applied', 'sensor_msgs/msg/JointState', STREAM,
                               'N', 'train_plant_node', 'recorder, evaluation',
                               'force per actuated unit as delivered (limits, lag, rate limit, '
                               'safety brakes and failures applied), same layout',
                               rate=OBSERVED_STEP),
    'identity': Topic('train/identity', 'std_msgs/msg/String', LATCHED, '-', 'train_plant_node',
                      'ato_controller_node, profile_node',
                      'what the plant simulates, once: JSON {"scenario": name, "sha256": hash of '
                      'the resolved scenario} (ato_common.identity)',
                      rate=ONCE),
    'diagnostics': Topic('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', DIAGNOSTICS, '-',
                         'all nodes', 'run_scenario, rqt_robot_monitor',
                         'active law, tracking errors, parameter estimates, rejected input',
                         rate='every 1 s of simulated time per node (the controller: its '
                         'diagnostics_period_s), and at once on a safety change or a rejected '
                         'input'),
    'step_records': Topic('ato/step_records', 'std_msgs/msg/UInt8MultiArray', STREAM, '-',
                          'train_plant_node, profile_node, ato_controller_node', 'recorder',
                          'per-step messages of a node bundled for the recorders (the bytes of '
                          'each message of STEP_RECORDED it published, with its topic, log and '
                          'publish times; layout in ato_ros.step_records)',
                          rate='every 0.8 s of simulated time (at most 0.05 s of wall time) '
                          'while a recorder subscribes'),
    'recorded': Topic('ato/recorded', 'std_msgs/msg/Header', ACKNOWLEDGEMENTS, 's',
                      'recorder', 'train_plant_node',
                      "a recorder's acknowledgement of the namespace's step records: stamp = "
                      'every step record stamped up to it is in its file, frame_id = the '
                      "recorder's node name; in lockstep the plant runs at most "
                      'recorder_lead_s past the oldest acknowledgement (ato_ros.'
                      'RecorderLead)',
                      rate='every 0.6 s of simulated time of step records written'),
}

#: The per-step topics the loop nodes put in their step records (``step_records``): the recorder
#: takes them from there instead of subscribing to each (ato_ros.step_records).
STEP_RECORDED = ('clock', 'state', 'state_measured', 'reference', 'distance_to_go',
                 'permitted_speed', 'command', 'actuators_commanded', 'actuators_applied')

REFERENCE_JOINT = 'train'


def stack_remaps(namespace: str) -> list[tuple[str, str]]:
    """The remappings that push a stack into ``namespace`` with a clock of its own: every node
    of the stack (and its monitor) takes them. The empty namespace (or ``/``) is the root: no
    remapping."""
    ns = normalised_namespace(namespace)
    if ns == '/':
        return []
    return [('__ns', ns), (TOPICS['clock'].name, f'{ns}{TOPICS["clock"].name}')]


def normalised_namespace(namespace: str) -> str:
    """``train1``, ``/train1/`` -> ``/train1``; '' -> ``/``; ValueError naming a bad one."""
    ns = '/' + namespace.strip('/')
    parts = ns[1:].split('/') if ns != '/' else []
    for part in parts:
        if not part or not (part[0].isalpha() or part[0] == '_') or \
                not all(c.isalnum() or c == '_' for c in part):
            raise ValueError(f'namespace {namespace!r}: each part must start with a letter or _ '
                             'and hold only letters, digits and _')
    return ns


def status_in_namespace(name: str, namespace: str) -> str | None:
    """A status ``name`` as its node's own (``train_plant_node: simulation``) if it comes from a
    node of ``namespace`` (``/train1``, ``/`` the root), else None."""
    prefix = namespace.strip('/')
    node_part = name.split(':', 1)[0]
    if not prefix:
        return name if '/' not in node_part else None
    if not name.startswith(prefix + '/'):
        return None
    relative = name[len(prefix) + 1:]
    return relative if '/' not in relative.split(':', 1)[0] else None
