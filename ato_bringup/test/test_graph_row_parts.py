"""The parts of a campaign row made again through the graph (ato_bringup.graph_row) that need no
graph: what the nodes are given (the plant the draw's truth, the controller its knowledge part
and the row's settings), how a JSON text reaches a node on its command line, how agreement is
judged, and how ``run_scenario`` and the campaign command take the new options."""

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from ato_bringup import graph_row, run_scenario
from ato_bringup.graph_row import (
    LAW_STATUS,
    PLANT_STATUS,
    agree,
    comparison,
    graph_config,
    graph_run,
)
from ato_bringup.stack import Sample, ros_args, yaml_text
from ato_campaigns import campaign as campaign_command
from ato_campaigns.engine import METRICS, parse_campaign, task_of
from ato_common.scenario import load_scenario
from ato_common.uncertainty import KNOWLEDGE_PARAMETERS, PLANT_PARAMETERS

CAMPAIGN = {'name': 'parts', 'seed': 3, 'draws': 2, 'scenarios': ['short_line'],
            'laws': [{'law': 'pid', 'label': 'pid_flat', 'gradient': 'hidden',
                      'settings': {'kp_position': 0.3, 'grade_feedforward': False}}],
            'configurations': ['published'], 'envelope': False, 'end_time_s': 30}


def test_the_plant_gets_the_draw_s_truth_and_the_controller_only_its_knowledge(tmp_path):
    campaign = parse_campaign(CAMPAIGN, 'parts', tmp_path)
    task = task_of(campaign, 'short_line', campaign.laws[0], 1)
    config = graph_config(task, 30.0, tmp_path, 7)
    drawn = json.loads(config.plant_params['draw_values'])
    assert set(drawn) == set(PLANT_PARAMETERS)
    assert drawn == {k: task['values'][k] for k in PLANT_PARAMETERS}  # every double exactly
    assert not set(KNOWLEDGE_PARAMETERS) & set(drawn)
    controller = config.controller_params
    assert controller['gradient_known'] is False and controller['envelope'] is False
    assert controller['gains'] == 'published'
    assert controller['pid.kp_position'] == 0.3 and controller['pid.grade_feedforward'] is False
    assert not any(k in json.dumps(controller) for k in PLANT_PARAMETERS)  # no truth in it
    assert config.plant_params['control_rate_hz'] == controller['rate_hz'] == task['rate_hz']
    assert (config.controller, config.model, config.end_time_s) == ('pid', 'point_mass', 30.0)
    assert config.record_to == tmp_path / 'bag'
    assert config.diagnostics_period_s == pytest.approx(1.0 / task['rate_hz'])


@pytest.mark.parametrize('text', ['{"mass_factor": 1.05, "wind_mps": -2.5}', '', '[1, 2]',
                                  "it's", 'short_line', '/tmp/a b.yaml', '1.5', 'true'])
def test_text_on_the_command_line_reads_back_as_the_same_text(text):
    value = yaml_text(text)
    assert yaml.safe_load(value) == text  # rcl reads the value of -p name:=value as YAML
    assert ros_args({'draw_values': text}) == ['--ros-args', '-p', f'draw_values:={value}']
    if text == 'short_line':
        assert value == text  # plain names as they were


def test_agreement_is_within_the_stated_tolerance_and_nan_agrees_with_nan():
    assert agree(1.0, 1.0 + 1e-12) and agree(0.0, 1e-12) and agree(math.nan, math.nan)
    assert not agree(1.0, 1.0 + 1e-6) and not agree(math.nan, 0.0)
    assert agree('ok', 'ok') and not agree('ok', 'stop error')
    row = {'status': 'ok', 'reason': '', **dict.fromkeys(METRICS, 1.0)}
    other = dict(row, rms_speed_error_kmh=1.5, saturated_fraction=math.nan)
    verdicts = {key: verdict for key, *_, verdict in comparison(row, other)}
    assert verdicts['rms_speed_error_kmh'] == 'DIFFERS'
    assert verdicts['saturated_fraction'] == 'not compared (not on the wire)'
    assert verdicts['status'] == verdicts['traction_energy_kwh'] == 'agree'


def test_run_scenario_takes_a_draw_and_the_controller_s_configuration(tmp_path):
    args = run_scenario.parse_args(['--draw-values', '{"mass_factor": 1.1}', '--gradient',
                                    'hidden', '--gains', 'tuned', '--no-envelope',
                                    '--log-dir', str(tmp_path)])
    config, launch = run_scenario.configure(args)
    assert config.plant_params['draw_values'] == '{"mass_factor": 1.1}'
    assert config.controller_params | {'rate_hz': 0} == {
        'rate_hz': 0, 'gains': 'tuned', 'envelope': False, 'gradient_known': False}


def test_run_scenario_refuses_bad_draw_values_before_anything_starts(capsys, tmp_path):
    code = run_scenario.run(run_scenario.parse_args(
        ['--draw-values', '{"mass_factor": NaN}', '--log-dir', str(tmp_path / 'run')]))
    assert code == 2
    assert 'draw_values: not JSON' in capsys.readouterr().err


def test_the_campaign_command_hands_a_row_through_ros_to_the_graph_rerun(monkeypatch):
    calls = []
    monkeypatch.setattr(campaign_command.subprocess, 'call', lambda command: calls.append(
        command) or 0)
    argv = ['--draw', '1', '--law', 'pid', '--through', 'ros']
    assert campaign_command.main(argv) == 0
    assert calls[0][1:] == ['-m', 'ato_bringup.graph_row', *argv]
    for wrong in (['--through', 'ros', '--serial'], [*argv, '--save', 'run.npz']):
        with pytest.raises(SystemExit):
            campaign_command.parse_args(wrong)


def _sample(k: int) -> Sample:
    return Sample(positions=(10.0 * k,), speeds=(1.0 * k,), forces=(100.0 * k,),
                  ref_position=10.0 * k, ref_speed=1.0 * k)


def test_the_graph_run_reads_safety_saturation_and_faults_from_the_per_step_diagnostics():
    stamps = [k * 100_000_000 for k in range(5)]
    plant = {0: ('0', 'normal'), 2: ('1', 'service brake'), 3: ('1', 'normal')}
    law = [('False', '0'), ('True', '0'), ('True', '1'), ('False', '1'), ('False', '2')]
    diagnostics = [(stamps[k], PLANT_STATUS, {'atp_interventions': n, 'watchdog': w}, '')
                   for k, (n, w) in plant.items()]
    diagnostics += [(stamps[k], LAW_STATUS, {'law': 'pid', 'saturated': s, 'faults': f},
                     f'fault {k}' if f != '0' else 'pid running')
                    for k, (s, f) in enumerate(law)]
    outcome = SimpleNamespace(scenario=load_scenario('short_line'), diagnostics=diagnostics,
                              samples=[(k, _sample(i)) for i, k in enumerate(stamps)])
    measured = np.arange(5.0)
    lagging = graph_run(outcome, measured, None, every_step=True, instant=False)
    assert list(lagging.forces) == [0.0, 100.0, 200.0, 300.0, 400.0]  # the step's own truth
    instant = graph_run(outcome, measured, None, every_step=True, instant=True)
    assert list(instant.forces) == [100.0, 200.0, 300.0, 400.0, 400.0]  # the next step's
    assert lagging.atp_interventions == 1 and lagging.atp_times_s == (0.2,)
    assert lagging.watchdog_events == 1  # the steps published under the watchdog's brake
    assert list(lagging.saturated) == [False, True, True, False, False]
    assert lagging.faults == ['', '', 'fault 2', '', 'fault 4']
    assert lagging.laws == ['pid'] * 5 and list(lagging.measured_positions) == list(measured)
    assert graph_run(outcome, measured, None, every_step=False, instant=False
                     ).saturated.size == 0


def test_a_row_that_is_not_in_the_campaign_is_refused_before_anything_runs(capsys):
    assert graph_row.main(['--draw', '0', '--law', 'no_such_law']) == 2
    assert "'no_such_law' is not a law of the campaign" in capsys.readouterr().err
    assert graph_row.main([]) == 2
