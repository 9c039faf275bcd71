"""The launch file's arguments and what they start (ato_bringup.launch_arguments): one pure
module that the launch file and ``ato launch`` both read."""

import subprocess
import sys

import pytest

from ato_bringup.launch_arguments import (
    LAUNCH_FINAL_DELIVERY_S,
    MAX_RATE_HZ,
    NODES,
    LaunchRefused,
    arguments,
    resolve,
)


def test_the_module_is_pure_python():
    imported = subprocess.run(
        [sys.executable, '-c', 'import sys, ato_bringup.launch_arguments; '
         'print(sorted({m.split(".")[0] for m in sys.modules} & {"rclpy", "launch", '
         '"launch_ros", "rcl_interfaces"}))'], capture_output=True, text=True, check=True)
    assert imported.stdout.strip() == '[]'


def test_the_rate_bound_is_the_nodes_own():
    from ato_controller_node.node import NODE_PARAMS
    from train_plant_node.node import PARAMS
    bounds = {p.maximum for p in (*PARAMS, *NODE_PARAMS) if p.name in ('control_rate_hz',
                                                                         'rate_hz')}
    assert bounds == {MAX_RATE_HZ}


def test_the_defaults_start_the_suite_s_stack_to_the_scenario_s_end():
    stack = resolve({})
    assert (stack.controller, stack.scenario, stack.model) == ('pid', 'short_line', 'point_mass')
    assert stack.lockstep and not stack.composed and stack.namespace == '/'
    assert 900.0 < stack.end_time_s < 1000.0 and stack.rate_hz == 10.0
    parameters = stack.parameters()
    assert set(parameters) == set(NODES)
    assert parameters['train_plant_node']['final_delivery_timeout_s'] == LAUNCH_FINAL_DELIVERY_S
    assert {a.name for a in arguments()} == {'controller', 'scenario', 'model', 'lockstep',
                                             'rate_hz', 'end_time_s', 'namespace', 'composed',
                                             'draw_values', 'gradient_known', 'gains',
                                             'envelope'}
    # the nominal plant, the controller's defaults
    assert parameters['train_plant_node']['draw_values'] == ''
    assert {k: parameters['ato_controller_node'][k] for k in (
        'gains', 'envelope', 'gradient_known')} == {'gains': 'published', 'envelope': True,
                                                    'gradient_known': True}


@pytest.mark.parametrize('values, reason', [
    ({'lockstep': 'yes'}, 'lockstep:=yes: not one of true, false'),
    ({'model': 'rigid'}, 'model:=rigid: not one of auto, multi_car, point_mass'),
    ({'rate_hz': '5000'}, r'rate_hz:=5000: must be from 0'),
    ({'rate_hz': 'fast'}, 'rate_hz:=fast: not a number'),
    ({'end_time_s': '-3'}, 'end_time_s:=-3: give a time in s'),
    ({'namespace': 'train 1'}, 'namespace'),
    ({'scenario': 'no_such_line'}, "scenario 'no_such_line' is neither a built-in"),
    ({'scenario': 'mao_4car', 'controller': 'mao_multibody_nominal'},
     'applies to scenario mao_4car only at 10000 Hz, above the nodes\' 1000 Hz'),
    ({'controller': 'mao_multibody_rigid', 'rate_hz': '20'},
     'mao_multibody_rigid cannot drive scenario short_line on the point_mass plant'),
    ({'draw_values': '{"mass_factor": 9}'}, r'draw_values.mass_factor: must be a finite number'),
    ({'draw_values': '{"gradient_known": 0}'}, 'acts on what the controller knows'),
    ({'gains': 'tuned', 'scenario': 'liu_li_2020', 'controller': 'liu_li'}, 'tuned'),
    ({'envelope': 'off'}, 'envelope:=off: not one of true, false'),
])
def test_arguments_that_cannot_make_a_run_are_refused_with_the_reason(values, reason):
    with pytest.raises(LaunchRefused, match=reason):
        resolve(values)


def test_an_external_ato_node_is_not_checked_as_a_law():
    stack = resolve({'scenario': 'mao_4car', 'controller': 'mao_2017'}, external=True)
    assert stack.model == 'multi_car' and stack.rate_hz == 10.0


def test_a_scenario_file_is_named_with_its_field(tmp_path):
    broken = tmp_path / 'broken.yaml'
    broken.write_text('name: broken\nline: {length_m: -5}\n')
    with pytest.raises(LaunchRefused, match='broken.yaml'):
        resolve({'scenario': str(broken)})
