"""Issue 14, defect 4, through the graph: run_scenario's summary shows the ATP interventions the
plant reported and the stopping error beyond the platform tolerance, with their first
occurrence, and its exit code is 3 unless --no-fail-on-events is given."""

from ato_bringup import run_scenario
from ato_bringup.run_events import EVENTS_EXIT_CODE

STUCK = '''name: stuck
train: {preset: crh3_luo_xu}
line: {name: stuck, length_m: 20000, stations: [{name: A, position_m: 0},
       {name: B, position_m: 12000}], speed_limits: [{start_m: 0, speed_kmh: 160}]}
planning: {max_acceleration_mps2: 0.4, service_deceleration_mps2: 0.5, max_jerk_mps3: 0.3}
plant:
  failures:
    - {actuator: traction, kind: stuck, start_s: 60, end_s: 200, force_n: 3.0e+5}
'''


def test_the_summary_shows_what_went_wrong_and_the_exit_code_says_so(tmp_path, domain_id,
                                                                      capfd):
    scenario = tmp_path / 'stuck.yaml'
    scenario.write_text(STUCK)
    args = ['--scenario', str(scenario), '--controller', 'pid', '--no-record',
            '--domain-id', str(domain_id), '--log-dir', str(tmp_path / 'logs')]
    assert run_scenario.main(args) == EVENTS_EXIT_CODE
    printed = capfd.readouterr().out
    atp = next(line for line in printed.splitlines() if line.startswith('ATP interventions'))
    assert not atp.endswith(' 0') and 'first at ' in atp
    assert 'ATP emergency brake intervention' in atp  # the plant's own message
    # the ATP's stop supervision holds the train at B, so the stop itself may be in tolerance
    assert '\nstop errors           ' in printed
    assert 'NOT CLEAN' in printed
    args[-1] = str(tmp_path / 'logs2')
    assert run_scenario.main(args + ['--no-fail-on-events']) == 0
