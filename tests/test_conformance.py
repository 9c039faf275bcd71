"""The conformance harness (issue 32): the suite's own controller passes every case of the ATO
node contract, the minimal example node written from the contract page passes them too, and the
deliberately broken example fails exactly the cases of its five defects, naming them."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ato_bringup.processes import executable_path
from ato_common.contract import CASES

EXAMPLES = Path(__file__).resolve().parents[1] / 'examples' / 'external_ato'
BROKEN = {'refuses_other_scenario', 'survives_restart', 'no_command_after_shutdown',
          'follows_replanned_reference', 'failed_sensor'}


def conformance(command: str, tmp_path: Path, domain_id: int) -> tuple[int, dict, str]:
    results = tmp_path / 'results.json'
    done = subprocess.run([sys.executable, '-m', 'ato_bringup.conformance',
                           '--controller-command', command, '--log-dir', str(tmp_path / 'logs'),
                           '--domain-id', str(domain_id), '--json', str(results)],
                          capture_output=True, text=True, timeout=900)
    verdicts = {case['name']: case['passed'] for case in json.loads(results.read_text())['cases']}
    return done.returncode, verdicts, done.stdout + done.stderr


@pytest.mark.parametrize('command', [
    'suite', f'{sys.executable} {EXAMPLES / "p_ato_node.py"}'])
def test_a_conforming_node_passes_every_case(command, tmp_path, domain_id):
    if command == 'suite':
        command = executable_path('ato_controller_node', 'ato_controller_node')
    code, verdicts, output = conformance(command, tmp_path, domain_id)
    assert code == 0, output
    assert verdicts == dict.fromkeys(CASES, True), output
    assert f'{len(CASES)} of {len(CASES)} cases passed' in output


def test_the_broken_example_fails_the_cases_of_its_defects(tmp_path, domain_id):
    code, verdicts, output = conformance(f'{sys.executable} {EXAMPLES / "broken_ato_node.py"}',
                                         tmp_path, domain_id)
    assert code == 1, output
    assert {name for name, passed in verdicts.items() if passed is False} == BROKEN, output
    assert {name for name, passed in verdicts.items() if passed} == set(CASES) - BROKEN, output
    assert 'not passed: ' + ', '.join(name for name in CASES if name in BROKEN) in output
