"""Issue 14, defect 4, through the graph: run_scenario's summary shows the ATP interventions the
plant reported, with their first occurrence, and the stopping errors, and its exit code is 3
unless --no-fail-on-events is given."""

from pathlib import Path

from ato_bringup import run_scenario
from ato_common.run_events import EVENTS_EXIT_CODE

#: a traction drive stuck at 300 kN from 60 to 200 s (tests/data/synthetic)
STUCK = (Path(__file__).resolve().parents[1] / 'tests' / 'data' / 'synthetic'
         / 'stuck_traction.yaml').read_text()


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
