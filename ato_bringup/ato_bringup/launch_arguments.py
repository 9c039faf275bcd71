"""The launch file's arguments and what they start, in one place: ``launch/ato.launch.py`` (a ROS
2 launch) and ``ato launch`` (the suite's own launcher, ``ato_bringup.launcher``, for the PyPI
wheels, which have no ``launch`` package) both read this module, so the two start the same nodes
with the same parameters.

Pure: no rclpy and no launch. :func:`resolve` turns the arguments (text, as on a command line)
into a :class:`StackLaunch`: the scenario loaded, the plant model it needs
(``ato_simulation.applies.plant_model_for``: a train of cars gets the multi-car plant, unless
``model`` names one), the control rate at which the law applies, the simulated time at which the
run ends (by default the scenario's: the end of its target curve plus its settle time), and each
node's parameters. A campaign's row is made again through the graph with the same arguments
(``draw_values``: the plant's truth of one draw; ``gradient_known``, ``gains``, ``envelope``:
the controller's knowledge and configuration). Arguments that cannot make a run (an unknown
value, a malformed scenario, a law that cannot drive the plant it would be given, malformed
draw values, a configuration without gains for the law) raise :class:`LaunchRefused` with the
reason, before any node starts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

from ato_common.conventions import normalised_namespace, stack_remaps
from ato_common.scenario import DEFAULT_SCENARIO, Scenario, load_scenario
from ato_common.validation import ConfigError
from ato_controller_node.gains import GAINS, GainsUnavailable, settings_for
from ato_controller_node.laws import LAWS
from ato_simulation.applies import applicable_rate, plant_model_for
from ato_simulation.plans import cached_plan, run_end_time_s
from train_plant_node.draw_values import parse_draw_values
from train_plant_node.models import MODELS

#: the nodes of the stack, each started as ``<name>/<name>`` with that node name
NODES = ('ato_controller_node', 'profile_node', 'train_plant_node')
#: the composed stack's executable (package, executable): the three nodes in one process
COMPOSED = ('ato_bringup', 'ato_stack')

DEFAULT_CONTROLLER = 'pid'
AUTO_MODEL = 'auto'
SCENARIO_END = 'scenario'
RUN_ON = 'never'
#: the highest control rate the nodes take (``control_rate_hz`` of the plant, ``rate_hz`` of the
#: controller), Hz
MAX_RATE_HZ = 1000.0
#: the plant's wait at its end for its last messages to be acknowledged, under a launcher, s.
#: ``ros2 launch`` escalates a node's SIGINT to SIGTERM after 5 s (``sigterm_timeout``) and logs
#: that as an error: the wait (a peer killed a moment before stays matched until its lease ends,
#: so the wait runs out) and the teardown must end well inside it.
LAUNCH_FINAL_DELIVERY_S = 2.0


@dataclass(frozen=True)
class Argument:
    """A launch argument: name, default (text, as given on a command line), description and,
    for a closed set, the valid values."""

    name: str
    default: str
    description: str
    choices: tuple[str, ...] = ()


def arguments() -> tuple[Argument, ...]:
    """The launch file's arguments, in the order ``--show-args`` lists them."""
    laws = tuple(sorted(LAWS))
    return (
        Argument('controller', DEFAULT_CONTROLLER,
                 'control law, one of the registry (ato_controller_node.laws)', laws),
        Argument('scenario', DEFAULT_SCENARIO,
                 'built-in scenario name or path to a scenario YAML'),
        Argument('model', AUTO_MODEL,
                 f"plant model: {AUTO_MODEL} (the scenario's: multi_car for a train described "
                 'car by car, else point_mass) or one of ' + ', '.join(sorted(MODELS)),
                 (AUTO_MODEL, *sorted(MODELS))),
        Argument('lockstep', 'true', 'lockstep simulated time (false: real time)',
                 ('true', 'false')),
        Argument('rate_hz', '0.0',
                 "control rate, Hz (0: the scenario's, or the first faster rate the law's "
                 'sampled-time design accepts)'),
        Argument('end_time_s', SCENARIO_END,
                 f'simulated time at which the run ends: {SCENARIO_END} (the end of the '
                 f"scenario's target curve plus its settle time), a time in s, or {RUN_ON} "
                 '(run until stopped)'),
        Argument('namespace', '',
                 'push the stack into this namespace, with its own /clock (several stacks in '
                 'one domain)'),
        Argument('composed', 'false',
                 'true: the three nodes in one process on one executor (ato_stack) instead of '
                 'three processes', ('true', 'false')),
        Argument('draw_values', '',
                 "the plant's truth of one draw of a campaign's uncertainty: a JSON object of "
                 'uncertain parameters, e.g. {"mass_factor": 1.08} (\'\': the nominal plant; '
                 'the plant alone reads it)'),
        Argument('gradient_known', 'true',
                 "the controller knows the line's gradient profile (false: a flat line)",
                 ('true', 'false')),
        Argument('gains', GAINS[0], "the laws' configuration (the controller's gains)", GAINS),
        Argument('envelope', 'true', 'the ATO envelope of the controller host, for every law',
                 ('true', 'false')),
    )


class LaunchRefused(ValueError):
    """The arguments cannot make a run; the message says why."""


@dataclass(frozen=True)
class StackLaunch:
    """What a launch of the stack starts: resolved from the arguments by :func:`resolve`."""

    scenario: str  # as given: the nodes load it themselves
    controller: str
    model: str
    rate_hz: float
    end_time_s: float  # 0: run until stopped (the plant's own convention)
    lockstep: bool
    namespace: str  # normalised: '/' is the root
    composed: bool
    notes: tuple[str, ...] = field(default=())  # what was decided that the arguments left open
    draw_values: str = ''  # the plant's truth of a draw (checked: train_plant_node.draw_values)
    gradient_known: bool = True
    gains: str = GAINS[0]
    envelope: bool = True

    def parameters(self) -> dict[str, dict[str, object]]:
        """Each node's parameters."""
        common = {'scenario': self.scenario, 'lockstep': self.lockstep}
        return {
            'ato_controller_node': {**common, 'controller': self.controller,
                                    'rate_hz': self.rate_hz, 'gains': self.gains,
                                    'envelope': self.envelope,
                                    'gradient_known': self.gradient_known},
            'profile_node': dict(common),
            'train_plant_node': {**common, 'model': self.model, 'control_rate_hz': self.rate_hz,
                                 'end_time_s': self.end_time_s,
                                 'final_delivery_timeout_s': LAUNCH_FINAL_DELIVERY_S,
                                 'draw_values': self.draw_values},
        }

    def parameter_sections(self) -> dict[str, dict]:
        """A parameters file's content with a section per node (``/**/<node>``): what the
        composed process takes (one file; each node reads its own section)."""
        return {f'/**/{name}': {'ros__parameters': values}
                for name, values in self.parameters().items()}

    def remappings(self) -> list[tuple[str, str]]:
        """The topic remappings of every node: ``/clock`` into the namespace (the namespace
        itself is the node's ``namespace``)."""
        return [(source, target) for source, target in stack_remaps(self.namespace)
                if source != '__ns']


def _rate(text: str) -> float:
    try:
        rate = float(text)
    except ValueError:
        raise LaunchRefused(f'rate_hz:={text}: not a number of Hz') from None
    if not 0.0 <= rate <= MAX_RATE_HZ:
        raise LaunchRefused(f'rate_hz:={text}: must be from 0 (the scenario\'s) to '
                            f'{MAX_RATE_HZ:g} Hz')
    return rate


def _end_time(text: str, scenario: Scenario) -> tuple[float, str]:
    """(the plant's end_time_s, a note) for the argument ``text``."""
    value = text.strip().lower()
    if value == RUN_ON:
        return 0.0, 'the run goes on until it is stopped (end_time_s:=never)'
    if value == SCENARIO_END:
        end = run_end_time_s(scenario, cached_plan(scenario))
        return end, f"the run ends at the scenario's end, {end:.1f} s of simulated time"
    try:
        end = float(text)
    except ValueError:
        end = float('nan')
    if not (end > 0.0 and math.isfinite(end)):
        raise LaunchRefused(f'end_time_s:={text}: give a time in s (> 0), {SCENARIO_END} (the '
                            f"scenario's end, the default) or {RUN_ON} (run until stopped)")
    return end, ''


def _law_and_rate(law: str, scenario: Scenario, model: str, asked_hz: float
                  ) -> tuple[float, str]:
    """(control rate, note) at which ``law`` drives ``scenario`` on ``model``; LaunchRefused
    naming why it cannot."""
    rate, reason = applicable_rate(law, scenario, model, asked_hz or None)
    if rate is None:
        raise LaunchRefused(f'controller {law} cannot drive scenario {scenario.name} on the '
                            f'{model} plant: {reason}')
    if rate > MAX_RATE_HZ:
        raise LaunchRefused(f'controller {law} applies to scenario {scenario.name} only at '
                            f'{rate:g} Hz, above the nodes\' {MAX_RATE_HZ:g} Hz: it runs in the '
                            'offline loop only (run_offline)')
    note = '' if asked_hz or rate == scenario.run.controller_rate_hz else (
        f'{law} runs at {rate:g} Hz (its sampled-time design refuses the scenario\'s '
        f'{scenario.run.controller_rate_hz:g} Hz)')
    return rate, note


def resolve(values: Mapping[str, str], external: bool = False) -> StackLaunch:
    """The stack that the arguments ``values`` (name -> text; missing ones take their
    defaults, names that are not arguments are ignored) start; LaunchRefused with the reason
    if they cannot make a run. ``external``: an ATO node of the user's drives the plant instead
    of the suite's controller (``controller`` is not checked; the rate is the one asked for, or
    the scenario's)."""
    given = {a.name: str(values.get(a.name, a.default)) for a in arguments()}
    for argument in arguments():
        if argument.choices and given[argument.name] not in argument.choices:
            raise LaunchRefused(f'{argument.name}:={given[argument.name]}: not one of '
                                + ', '.join(argument.choices))
    lockstep, composed = given['lockstep'] == 'true', given['composed'] == 'true'
    asked_hz = _rate(given['rate_hz'])
    try:
        namespace = normalised_namespace(given['namespace'])
        scenario = load_scenario(given['scenario'])
    except (ValueError, ConfigError) as error:  # ConfigError names the file and the field
        raise LaunchRefused(str(error)) from None
    model = given['model']
    notes = []
    if model == AUTO_MODEL:
        model = plant_model_for(scenario)
        if model != 'point_mass':
            notes.append(f'plant model {model} (scenario {scenario.name} describes its train '
                         'car by car)')
    if external:
        rate, note = asked_hz or scenario.run.controller_rate_hz, ''
    else:
        rate, note = _law_and_rate(given['controller'], scenario, model, asked_hz)
    try:
        end_time_s, end_note = _end_time(given['end_time_s'], scenario)
    except ConfigError as error:  # the target curve cannot be planned
        raise LaunchRefused(str(error)) from None
    notes += [n for n in (note, end_note) if n]
    try:
        parse_draw_values(given['draw_values'])
        if not external:  # a law without gains in the configuration: refused by its node
            settings_for(given['controller'], given['gains'], scenario.train.name)
    except (ValueError, GainsUnavailable) as error:  # each names what is wrong (ConfigError too)
        raise LaunchRefused(str(error)) from None
    return StackLaunch(given['scenario'], given['controller'], model, rate, end_time_s,
                       lockstep, namespace, composed, tuple(notes), given['draw_values'],
                       given['gradient_known'] == 'true', given['gains'],
                       given['envelope'] == 'true')
