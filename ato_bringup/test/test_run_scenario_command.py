"""run_scenario's command line: two runs started in the same second get folders of their own;
the events option and the stop tolerance's check; the topics a live view already reads."""

import pytest

from ato_bringup import run_scenario
from ato_bringup.run_scenario import unique_run_dir


def test_runs_of_the_same_second_get_distinct_folders(tmp_path):
    first = unique_run_dir(tmp_path / 'runs', '20260101-120000-short_line-pid')
    second = unique_run_dir(tmp_path / 'runs', '20260101-120000-short_line-pid')
    assert first != second and first.is_dir() and second.is_dir()
    assert second.name == '20260101-120000-short_line-pid-2'


def test_run_scenario_has_the_option_and_the_tolerance_check():
    assert run_scenario.parse_args(['--no-fail-on-events']).no_fail_on_events
    assert run_scenario.parse_args([]).stop_tolerance == 0.5
    with pytest.raises(SystemExit):
        run_scenario.parse_args(['--stop-tolerance', '-1'])



def test_run_scenario_waits_for_the_readers_of_the_topics_a_view_already_reads(tmp_path,
                                                                               capsys):
    """``--watched-by``: the keys reach StackConfig.watched_by (each node then waits for those
    readers too); a key of no waited topic, or one named twice, is refused naming it."""
    args = run_scenario.parse_args(['--watched-by', 'state, reference,diagnostics',
                                    '--log-dir', str(tmp_path)])
    config, _ = run_scenario.configure(args)
    assert config.watched_by == ('state', 'reference', 'diagnostics')
    assert run_scenario.parse_args([]).watched_by == ()
    for wrong, said in (('state,clock', 'clock: not a topic the loop waits for readers of'),
                        ('state,state', 'state,state: a topic named twice')):
        with pytest.raises(SystemExit) as stopped:
            run_scenario.parse_args(['--watched-by', wrong])
        assert stopped.value.code == 2 and said in capsys.readouterr().err
