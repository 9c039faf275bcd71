"""The contract an ATO node honours to drive the suite's plant in place of its controller:
topics, types, QoS, stamps, lockstep pairing, identity, liveness and shutdown, versioned.

The topics, their types and QoS are those of ``ato_common.conventions.TOPICS`` (named here by
their keys); the clauses are text. The reference page (``ato_tools.reference_pages``:
``reference/ato-contract.md``) is generated from this module and fills the ``{name}`` fields of
the clauses with the current values of the nodes' parameters; the conformance harness
(``ato conformance``, ``ato_bringup.conformance``) checks the :data:`CASES`, each against its
clauses. A change that a conforming node could fail is a new major version; a clarification
or a new optional topic a new minor one.
"""

from __future__ import annotations

from dataclasses import dataclass

#: the contract's version (major.minor)
CONTRACT_VERSION = '1.2'  # 1.1: the gradient_known parameter (PARAMETERS); 1.2: read the
# identity before the first command (a clarification)

#: the topics an ATO node reads (keys of ``conventions.TOPICS``), and what for
INPUTS = {
    'state_measured': 'what the train\'s sensors measure, one message per control step',
    'reference': 'the target now and a preview, one message per control step',
    'identity': 'the scenario the plant simulates, once (latched)',
}
#: the topics an ATO node publishes
OUTPUTS = {'command': 'one command per control step, stamped with the step'}
#: topics it may read, not needed
OPTIONAL_INPUTS = {
    'clock': 'simulated time in lockstep (the stamps of the inputs carry it already)',
    'curve': 'the whole first plan, for display: never to be tracked (the reference replans)',
}


#: the parameters a node is started with (``--ros-args -p name:=value``, every one, always; the
#: clauses 'start' and 'knowledge' say what they mean): name -> (ROS type, the value when the
#: stack was not told one; None: always told). A node declares those it uses (rclpy and rclcpp
#: ignore an override of a parameter the node does not declare).
PARAMETERS: dict[str, tuple[str, object]] = {
    'scenario': ('string', None),
    'gradient_known': ('bool', True),
}


@dataclass(frozen=True)
class Clause:
    key: str
    title: str
    text: str  # Markdown; ``{name}`` fields are filled with the nodes' parameter values


CLAUSES = (
    Clause('start', 'Starting',
           'The node is started with `--ros-args -p scenario:=<scenario> -p '
           'gradient_known:=<true|false>` appended to its command line (the scenario: a '
           'built-in scenario\'s name or a scenario file\'s path, the same the plant was given; '
           'also in the environment variable `ATO_SCENARIO`), in the stack\'s namespace '
           '(`-r __ns:=...`) when there is one. Its topics are relative names, so the '
           'namespace applies to them.'),
    Clause('knowledge', 'What the node may know',
           'The nominal train and line of the scenario it was started for (its file, or the '
           'built-in scenario\'s: the train\'s nominal mass, resistance, traction and '
           'brakes, the stations, speed limits and gradients), its inputs, and nothing of the '
           'plant\'s truth (the scenario\'s `plant:` section, a campaign\'s draw). The '
           'parameter `gradient_known` (`bool`, default `true`) says whether it may use the '
           'line\'s gradient profile: when it is `false` (a campaign draw that hides the '
           'gradients from the controller, as from the suite\'s laws) a node that uses the '
           'gradients declares the parameter and takes the line as flat; a node that uses no '
           'gradients may ignore it. The parameters, read once at start, do not change.'),
    Clause('units', 'Units and signs',
           'SI throughout: m, m/s, m/s^2, N, s. A force is positive when it pulls the train '
           'forward (traction) and negative when it holds it back: **a braking force is '
           'negative**. The plant limits each actuator\'s command to its share of the traction '
           'characteristic at the current speed (force and power) and of the emergency brake '
           '(the most negative force), and publishes what it commanded and applied.'),
    Clause('command', 'The command',
           '`sensor_msgs/msg/JointState`: `name` = the train\'s actuators in the order its '
           'scenario declares them (a single-mass train: `["traction"]`; the '
           '[train presets](trains.md) list each train\'s), `effort` = one force per actuator, '
           'N, finite; `position` and `velocity` empty; `header.stamp` = the stamp of the step '
           'it answers; `header.frame_id` = the name of your law (not empty: the run\'s summary '
           'and the recorder name the law by it). A command of the wrong length, with other '
           'names or a non-finite force is rejected and counted by the plant; the previous one '
           'stays in force and the watchdog counts the period as missed.'),
    Clause('state', 'The measured state',
           '`trajectory_msgs/msg/JointTrajectory` with one point: `joint_names` = the cars, '
           'lead car first (a single mass: `["train"]`), `positions`, `velocities`, '
           '`accelerations` and `effort` (the force applied) one value per car, '
           '`time_from_start` = the run time. A failed or dropped-out sensor gives NaN in its '
           'field: the node must still command a finite force (hold its last command, or '
           'brake).'),
    Clause('reference', 'The reference',
           '`trajectory_msgs/msg/JointTrajectory`, `joint_names = ["train"]`: `points[0]` is '
           'the target now (position in `positions`, speed in `velocities`, acceleration in '
           '`accelerations`, jerk in `effort`), the next points a preview at their '
           '`time_from_start`. The profile replans a late train and resumes a train that stood '
           'behind its reference: the reference can jump. Track the reference of each step, '
           'never the latched first plan (`ato/reference/curve`).'),
    Clause('lockstep', 'Lockstep pairing',
           'In lockstep (the default) the plant owns simulated time. At each step t_k it '
           'publishes the measured state stamped t_k and waits for the command stamped t_k; '
           'the profile publishes the reference stamped t_k (often before the state). When you '
           'hold a state and a reference of the same stamp, compute **once** and publish one '
           'command stamped exactly t_k. Do not wait for `/clock`, do not command on a timer, '
           'do not command a stamp you have no state of. Until it gets the command the plant '
           'sends the step again every {resend_period_s} s of wall time: answer a state '
           'sent again with the same command again, without stepping your law a second time. '
           'A command stamped for another step is dropped and counted '
           '(`wrong_stamp_commands`) and the step counts as missed.'),
    Clause('rate', 'Rate',
           'The control period is the step between the stamps (the scenario\'s control rate, '
           'or the rate the plant was given): take it from the stamps, do not assume one. '
           'In real time (`lockstep:=false`) command at the control rate on the latest state '
           'and reference, stamped with the ROS time now (a stamp more than '
           '{command_stamp_tolerance_s} s from the plant\'s now is dropped), and command '
           'nothing on inputs older than a limit of yours (the suite\'s controller: '
           '{stale_after_s} s).'),
    Clause('identity', 'Identity',
           'The plant publishes, latched, what it simulates on `train/identity` '
           '(`std_msgs/msg/String`, JSON `{{"scenario": <name>, "sha256": <hash of the '
           'resolved scenario>}}`). If `scenario` is not the name of the scenario you were '
           'started for (a file\'s `name:`), command nothing, log both names and exit with a '
           'non-zero code (the suite\'s nodes exit with 2); so read it before your first '
           'command (on a loaded machine the first states can come before it). The hash is the '
           'suite\'s own digest: compare it if you compute it the same way, else the name.'),
    Clause('restart', 'A restarted plant',
           'A state stamped before your last step is a new run (the plant was started again): '
           'start your law again from that step (reset integrators and estimates) and answer '
           'it.'),
    Clause('liveness', 'Liveness',
           'Answer each step as soon as its state and reference are there: the lockstep waits '
           'for you (after {command_wait_limit_s} s of wall time without a command the plant '
           'reports the wait as a WARN). Without a valid command for {watchdog_periods} '
           'control periods the plant brakes (service brake), after {emergency_periods} with '
           'the emergency brake, until a valid command comes. Wait for nothing but your '
           'inputs: the plant starts when its observers are there.'),
    Clause('shutdown', 'Shutdown',
           'On SIGINT or SIGTERM, end within {stop_limit_s} s (a launch escalates to SIGTERM '
           'after 5 s) with exit code 0, and publish no command from then on (no final "safe" '
           'command: the plant\'s watchdog owns the train\'s safety when the ATO is gone).'),
)


@dataclass(frozen=True)
class Case:
    title: str
    clauses: tuple[str, ...]  # keys of CLAUSES
    how: str  # what the harness does and what passes


#: the conformance harness's cases, in the order it reports them
CASES = {
    'answers_every_step': Case(
        'answers every step', ('lockstep', 'liveness'),
        'every step of the main run (a scenario variant, in lockstep) gets a command (the '
        'last one, at the run\'s end, may go unanswered)'),
    'stamps': Case(
        'stamps and layout', ('command', 'lockstep', 'units'),
        'each command is stamped with a step its plant sent, names the actuators, has a force '
        'for each and a law name; the plant drops none for its stamp'),
    'rate': Case(
        'one command per step, at the control rate', ('lockstep', 'rate'),
        'no more commands for a stamp than states sent with it, the same command for a step '
        'sent again, stamps one control period apart'),
    'refuses_other_scenario': Case(
        'refuses a plant of another scenario', ('identity',),
        'given a plant (and profile) of another scenario: no command, and the node exits with '
        'a non-zero code'),
    'survives_restart': Case(
        'survives a restarted plant', ('restart',),
        'after the main run\'s plant ends, a new plant starts from 0 s: every step of it is '
        'answered'),
    'stops_when_told': Case(
        'stops when told', ('shutdown',),
        'SIGINT: the node exits with 0 within the limit'),
    'no_command_after_shutdown': Case(
        'no command after shutdown', ('shutdown',),
        'after the plant has ended the node is sent SIGINT: nothing is published on the '
        'command topic from then on'),
    'follows_replanned_reference': Case(
        'follows a replanned reference', ('reference',),
        'the traction is lost at the start: the train stands while its reference leaves, and '
        'the profile plans the leg again from where it stands; afterwards the train is closer '
        '(RMS position) to the streamed reference than half its distance to the first plan'),
    'failed_sensor': Case(
        'behaves under a failed sensor', ('state', 'command'),
        'the speed sensor fails (NaN) for a while: every step is still answered with finite '
        'forces and the plant rejects no command'),
}
