"""The README documents every topic and every parameter the nodes declare."""

from pathlib import Path

from ato_common.conventions import TOPICS
from ato_controller_node.node import NODE_PARAMS, gain_params
from profile_node.node import PARAMS as PROFILE_PARAMS
from train_plant_node.node import PARAMS as PLANT_PARAMS

README = (Path(__file__).resolve().parents[1] / 'README.md').read_text()


def test_every_topic_is_in_the_readme_with_its_type_and_qos():
    for t in TOPICS.values():
        assert f'| `{t.name}` | `{t.type_name}` | {t.qos.describe()} |' in README, t.name


def test_the_readme_tables_are_the_ones_the_code_prints():
    """Every row of scripts/readme_tables.py's output (types, QoS, units, defaults, ranges,
    descriptions) is in the README as printed: a changed description fails here."""
    import contextlib
    import io
    import runpy
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        runpy.run_path(str(Path(__file__).resolve().parents[1] / 'scripts/readme_tables.py'),
                       run_name='__main__')
    rows = [line for line in printed.getvalue().splitlines() if line.startswith('| `')]
    assert len(rows) > 50
    stale = [row for row in rows if row not in README]
    assert not stale, 'run scripts/readme_tables.py and update the README:\n' + '\n'.join(stale)


def test_every_parameter_is_in_the_readme():
    for p in PLANT_PARAMS + PROFILE_PARAMS + NODE_PARAMS + tuple(gain_params()):
        assert f'| `{p.name}` |' in README, p.name


def test_ci_runs_the_readme_test_command():
    ci = (Path(__file__).resolve().parents[1] / '.ci/run').read_text()
    assert 'make test' in README and 'make test' in ci
