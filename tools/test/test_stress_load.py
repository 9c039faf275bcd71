"""The graph tests' harness (tests/conftest.py): ``--stress-load N`` runs them beside N busy
processes, and a failed graph test shows the end of each process log written while it ran."""

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

CONFTEST = Path(__file__).resolve().parents[2] / 'tests' / 'conftest.py'

GRAPH_TESTS = textwrap.dedent('''
    import os
    import subprocess


    def test_the_busy_processes_run_beside(stress_load):
        ps = subprocess.run(['ps', '-eww', '-o', 'args'], capture_output=True,
                            text=True).stdout
        assert stress_load == 2 and ps.count('range(1_000_000): pass') >= 2


    def test_a_failure_shows_the_logs(tmp_path):
        old = tmp_path / 'old.log'
        old.write_text('written before the test\\n')
        os.utime(old, (0, 0))
        (tmp_path / 'logs').mkdir()
        (tmp_path / 'logs' / 'plant.log').write_text(
            ''.join(f'line {i}\\n' for i in range(100)) + 'the plant said this\\n')
        assert False, 'the graph failed'
''')


def test_stress_load_and_the_logs_of_a_failed_graph_test(tmp_path):
    folder = tmp_path / 'tests'
    folder.mkdir()
    shutil.copy(CONFTEST, folder / 'conftest.py')
    (folder / 'test_graph.py').write_text(GRAPH_TESTS)
    result = subprocess.run([sys.executable, '-m', 'pytest', '-p', 'no:xdist', '-p',
                             'no:cacheprovider', '--rootdir', str(tmp_path), '--stress-load',
                             '2', '--basetemp', str(tmp_path / 'temporary'), str(folder)],
                            capture_output=True, text=True, timeout=300, cwd=tmp_path,
                            env=dict(os.environ))
    out = result.stdout
    assert '1 failed, 1 passed' in out, out + result.stderr
    assert 'process log test_a_failure_shows_the_logs0/logs/plant.log' in out, out
    assert 'the plant said this' in out and 'line 99' in out and 'line 10\n' not in out, out
    assert 'process log test_a_failure_shows_the_logs0/old.log' not in out, out
