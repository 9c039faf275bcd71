"""A campaign's row made again through the ROS graph (issue 28's rerun, issue 32's first step):
the plant takes the draw's truth as its ``draw_values`` parameter, the controller only the
knowledge part (``gradient_known``) and the row's settings, and the row computed by the
campaign's own metrics from what was on the wire equals the row made offline
(``ato_bringup.graph_row.TOLERANCE``). Bad draw values are refused at the start with the reason,
and a change at run time is refused with one.

The campaign is tiny: one 3 km leg with a grade (about 170 s of simulated time), one law, two
draws of the default uncertainty (actuator lag and dead time, sensor noise and bias, odometer
errors, wind, load)."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from ato_bringup.graph_row import TOLERANCE, comparison, rerun_through_graph
from ato_bringup.stack import Stack, StackConfig
from ato_campaigns.engine import load_campaign, rerun
from ato_ros.stall import wait_for_exit

pytestmark = pytest.mark.integration

LINE = """name: graph_row_line
description: one 3 km leg with a grade (a tiny campaign's scenario, test)
source: suite (test)
train: {preset: crh3_luo_xu}
line:
  name: graph_row_line
  length_m: 3500
  stations:
    - {name: A, position_m: 0}
    - {name: B, position_m: 3000}
  speed_limits:
    - {start_m: 0, speed_kmh: 120}
  gradients:
    - {start_m: 0, per_mille: 0}
    - {start_m: 800, per_mille: 10}
    - {start_m: 2000, per_mille: 0}
planning: {max_acceleration_mps2: 0.4, service_deceleration_mps2: 0.5, max_jerk_mps3: 0.3,
           speed_margin_kmh: 5}
"""

CAMPAIGN = """name: graph_row_tiny
seed: 11
draws: 2
scenarios: [line.yaml]
laws:
  - {law: pid, label: pid_flat, gradient: hidden, settings: {kp_position: 0.3}}
  - {law: pid}
configurations: [published]
"""


@pytest.fixture
def campaign(tmp_path):
    (tmp_path / 'line.yaml').write_text(LINE)
    path = tmp_path / 'tiny.yaml'
    path.write_text(CAMPAIGN)
    return load_campaign(path)


def test_a_row_made_again_through_the_graph_is_the_offline_row(campaign, tmp_path, domain_id):
    offline, graph, notes, folder = rerun_through_graph(
        campaign, 'pid_flat', 1, out=tmp_path / 'out', domain_id=domain_id, progress=False)
    assert notes == []
    rows = comparison(offline, graph)
    differ = [(key, a, b) for key, _, a, b, verdict in rows if verdict != 'agree']
    assert not differ, f'the graph differs from the offline row ({TOLERANCE}): {differ}'
    # a whole journey with a stop, judged on every metric: none vacuous
    assert offline['status'] in ('ok', 'stop error', 'late')
    assert all(math.isfinite(graph[k]) for k in (
        'stop_error_m', 'odometer_stop_error_m', 'arrival_error_s', 'traction_energy_kwh',
        'saturated_fraction', 'rms_speed_error_kmh'))
    assert graph['p_actuator_dead_time_s'] > 0.0 and graph['p_gradient_known'] == 0.0
    assert (folder / 'bag').is_dir()
    # the controller was told the flat line and ran the entry's gain: the same draw with the
    # grades known and the published gains gives another run
    known, _ = rerun(campaign, 'pid', 1)
    assert known['rms_speed_error_kmh'] != offline['rms_speed_error_kmh']


def plant_and_controller(tmp_path, domain_id, draw_values: str) -> Stack:
    return Stack(StackConfig(scenario='short_line', domain_id=domain_id, monitor='',
                             log_dir=tmp_path / 'logs',
                             plant_params={'draw_values': draw_values}))


def test_the_plant_refuses_bad_draw_values_at_start_naming_what_is_wrong(tmp_path, domain_id):
    with plant_and_controller(tmp_path, domain_id, '{"mass_factor": 7, "wind_mps": 1}') as stack:
        params = stack.node_params()
        process = stack.start_process('plant', params['plant'])
        wait_for_exit(process, 60.0, 600.0)
        assert process.returncode == 2
        log = stack.log_tail('plant')
        assert 'draw_values.mass_factor: must be a finite number in [0.5, 2]' in log


def test_the_draw_and_the_knowledge_are_fixed_at_start_a_change_is_refused_with_the_reason(
        tmp_path, domain_id):
    with plant_and_controller(tmp_path, domain_id, '{"mass_factor": 1.1}') as stack:
        params = stack.node_params()
        stack.start_process('plant', params['plant'])
        stack.start_process('controller', {**params['controller'], 'gradient_known': False})
        plant = stack.set_parameters('train_plant_node', {'draw_values': '{}'}, timeout_s=120.0)
        controller = stack.set_parameters('ato_controller_node', {'gradient_known': True},
                                          timeout_s=120.0)
        # read-only parameters (their descriptors say so): rclpy refuses with the reason
        assert not plant[0].successful
        assert plant[0].reason == 'Trying to set a read-only parameter: draw_values.'
        assert not controller[0].successful
        assert controller[0].reason == 'Trying to set a read-only parameter: gradient_known.'
        assert 'the truth of the draw {"mass_factor": 1.1}' in stack.log_tail('plant')
        for name in ('plant', 'controller'):
            assert stack.processes[name].poll() is None, stack.log_tail(name)
        assert stack.stop() == {'plant': 0, 'controller': 0}


def test_the_campaign_command_reruns_a_row_through_ros_and_says_it_agrees(campaign, tmp_path):
    """The command a user types (the campaign module hands the row to ato_bringup.graph_row in a
    process of its own, which takes a free DDS domain)."""
    out = tmp_path / 'out'
    result = subprocess.run(
        [sys.executable, '-m', 'ato_campaigns.campaign', '--campaign', campaign.origin,
         '--draw', '0', '--law', 'pid_flat', '--through', 'ros', '--out', str(out)],
        capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'the graph gives the offline row' in result.stderr
    lines = [line for line in result.stdout.splitlines() if line.startswith('rms_speed')]
    assert lines and lines[0].endswith('agree')
