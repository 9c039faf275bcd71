"""The closed loop through the ROS graph, in lockstep simulated time."""

import re

import numpy as np
import pytest

from ato_bringup.runner import run_lockstep
from ato_bringup.stack import StackConfig

PERIOD_NS = 100_000_000
NOISY_PLANT = {'sensor_position_noise_m': 0.2, 'sensor_speed_noise_mps': 0.02, 'seed': 11}


def config(domain_id, tmp_path, name, **kwargs):
    return StackConfig(scenario='short_line', domain_id=domain_id, log_dir=tmp_path / name,
                       **kwargs)


@pytest.fixture(scope='module')
def pid_run(tmp_path_factory, session_domain):
    return run_lockstep(StackConfig(scenario='short_line', domain_id=session_domain,
                                    log_dir=tmp_path_factory.mktemp('pid'),
                                    plant_params=dict(NOISY_PLANT)))


def test_every_step_arrives_in_order_and_nothing_is_lost(pid_run):
    published = int([values for _, name, values, _ in pid_run.diagnostics
                     if name == 'train_plant_node: simulation'][-1]['steps_published'])
    assert pid_run.counts['state'] == published  # re-sent steps at start-up included
    stamps = [k for k, _ in pid_run.samples]
    assert stamps[0] == 0
    assert np.all(np.diff(stamps) == PERIOD_NS)
    assert stamps[-1] / 1e9 >= pid_run.config.end_time_s - 1e-9
    assert all(s.law == 'pid' for _, s in pid_run.samples[:-1])
    assert pid_run.exit_codes == {'plant': 0, 'profile': 0, 'controller': 0}


def test_closed_loop_tracks_the_reference(pid_run):
    m = pid_run.metrics
    assert m.rms_speed_error_kmh < 0.5
    assert m.max_speed_error_kmh < 2.0
    assert m.rms_position_error_m < 0.5
    assert m.max_position_error_m < 2.0
    assert set(m.stop_errors_m) == {'Midway', 'Terminus'}
    assert all(abs(e) < 0.5 for e in m.stop_errors_m.values())
    assert 500.0 < m.traction_energy_kwh < 2000.0


def test_diagnostics_name_the_law_and_report_errors(pid_run):
    law_status = [values for _, name, values, _ in pid_run.diagnostics
                  if name == 'ato_controller_node: law']
    assert law_status and all(v['law'] == 'pid' for v in law_status)
    assert {'speed_error_mps', 'position_error_m', 'estimate.integral_action_mps2'} <= \
        set(law_status[-1])
    plant_status = [values for _, name, values, _ in pid_run.diagnostics
                    if name == 'train_plant_node: simulation']
    assert plant_status and plant_status[-1]['rejected_commands'] == '0'
    assert plant_status[-1]['atp_interventions'] == '0'   # the ATO stays under the curve
    assert plant_status[-1]['watchdog'] == 'normal'


def test_two_lockstep_runs_give_identical_state_sequences(pid_run, tmp_path, domain_id):
    again = run_lockstep(config(domain_id, tmp_path, 'again', plant_params=dict(NOISY_PLANT)))
    assert [k for k, _ in again.samples] == [k for k, _ in pid_run.samples]
    for attribute in ('positions', 'speeds', 'accelerations', 'forces', 'command'):
        a = [getattr(s, attribute) for _, s in pid_run.samples]
        b = [getattr(s, attribute) for _, s in again.samples]
        assert a == b, attribute  # bit-identical floats


def test_composed_lean_run_gives_the_state_sequence_of_separate_processes(pid_run, tmp_path,
                                                                          domain_id):
    """The three nodes in one process (ato_stack) watched by the lean monitor of run_scenario
    (the truth and the reference taken in batches, no command): the same steps, bit for bit,
    as three processes watched by the full monitor, the same metrics, the laws from the
    diagnostics."""
    composed = run_lockstep(config(domain_id, tmp_path, 'composed', composed=True,
                                   monitor='lean', plant_params=dict(NOISY_PLANT)))
    assert composed.exit_codes == {'loop': 0}
    assert set(composed.counts) == {'state', 'reference', 'diagnostics'}  # lean: no command
    assert [k for k, _ in composed.samples] == [k for k, _ in pid_run.samples]
    for attribute in ('positions', 'speeds', 'accelerations', 'forces', 'ref_position',
                      'ref_speed'):
        a = [getattr(s, attribute) for _, s in pid_run.samples]
        b = [getattr(s, attribute) for _, s in composed.samples]
        assert a == b, attribute  # bit-identical floats
    assert composed.metrics == pid_run.metrics
    assert composed.laws == pid_run.laws == ['pid']
    assert composed.window_steps > 0 and composed.window_cpu_s['loop'] > 0.0


def test_controller_swap_mid_run_and_rejected_swaps(tmp_path, domain_id):
    def set_params(values):
        return lambda stack: stack.set_parameters('ato_controller_node', values)

    # the tuned configuration: Luo & Xu's published gains lag the reference by design; in and
    # out of it while cruising (its departure after a dwell is late: ato_simulation's
    # test_luo_xu_as_tuned_departs_on_time_after_a_dwell)
    outcome = run_lockstep(config(domain_id, tmp_path, 'swap',
                                  controller_params={'gains': 'tuned'}), actions={
        100.0: set_params({'controller': 'bogus'}),
        120.0: set_params({'pid.kd_speed': -1.0}),
        140.0: set_params({'rate_hz': 50.0}),
        150.0: set_params({'controller': 'luo_xu'}),
        330.0: set_params({'controller': 'pid'}),
    })
    bogus, gain, rate, luo_xu, pid = (results[0] for results in outcome.parameter_results)
    assert not bogus.successful and re.search(r'valid: (.*, )?luo_xu, (.*, )?pid', bogus.reason)
    assert not gain.successful and gain.reason
    assert not rate.successful and rate.reason
    assert luo_xu.successful and pid.successful

    laws = [(k / 1e9, s.law) for k, s in outcome.samples if s.law]
    before = [law for t, law in laws if t < 150.0]
    during = [law for t, law in laws if 200.0 < t < 330.0]
    assert set(before) == {'pid'}, laws[:5]  # the rejected swaps left the old law running
    assert set(during) == {'luo_xu'}
    assert {law for t, law in laws if t > 380.0} == {'pid'}
    status = [(stamp / 1e9, values['law']) for stamp, name, values, _ in outcome.diagnostics
              if name == 'ato_controller_node: law']
    assert any(t > 150.0 and law == 'luo_xu' for t, law in status)
    m = outcome.metrics
    assert m.max_position_error_m < 2.0 and m.max_speed_error_kmh < 2.0
    # bumpless: no step in the command around the switch larger than the normal variation
    forces = np.array([sum(s.command) for _, s in outcome.samples if s.command])
    assert np.max(np.abs(np.diff(forces))) < 60e3
