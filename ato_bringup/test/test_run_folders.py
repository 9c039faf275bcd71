"""Two run_scenario started in the same second get folders of their own."""

from ato_bringup.run_scenario import unique_run_dir


def test_runs_of_the_same_second_get_distinct_folders(tmp_path):
    first = unique_run_dir(tmp_path / 'runs', '20260101-120000-short_line-pid')
    second = unique_run_dir(tmp_path / 'runs', '20260101-120000-short_line-pid')
    assert first != second and first.is_dir() and second.is_dir()
    assert second.name == '20260101-120000-short_line-pid-2'
