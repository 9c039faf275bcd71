"""The bench's own tools (bench/bench.py): the CPU burner that shows what a second process of
the recorder's size costs the lockstep loop, and the share of a core a process used."""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))

import bench  # noqa: E402


def stat_fields(pid: int) -> list[str]:
    """/proc/<pid>/stat after the command name (which may hold spaces): field 3 on."""
    return Path(f'/proc/{pid}/stat').read_text().rpartition(')')[2].split()


def test_the_burner_runs_at_the_recorders_priority_and_is_gone_after_its_block():
    with bench.burner(0.2) as pid:
        deadline = time.monotonic() + 30  # the interpreter starts, then sets its nice
        while int(stat_fields(pid)[16]) != 19 and time.monotonic() < deadline:  # field 19
            time.sleep(0.01)
        assert int(stat_fields(pid)[16]) == 19
        assert stat_fields(pid)[0] != 'Z'
    assert not Path(f'/proc/{pid}').exists()  # killed and reaped


def test_cpu_share_is_the_core_a_process_used_in_the_steady_window():
    run = bench.GraphRun(overall=100.0, steady=200.0, steps=9294, startup_s=1.0, teardown_s=0.2,
                         cpu_ms_per_step={'recorder': 0.15, 'plant': 0.3}, count=0)
    # 200x with 0.1 s steps: 2000 steps per second of wall time, 0.15 ms each
    assert abs(bench.cpu_share(run, 'recorder') - 0.3) < 1e-12
    assert abs(bench.cpu_share(run, 'plant') - 0.6) < 1e-12


def test_the_tuning_section_replaces_its_own_section_only(tmp_path):
    page = tmp_path / 'page.md'
    page.write_text('# Benchmarks\n\nintro\n\n## Planning\n\nplans\n')
    section = bench.tuning_section()
    assert section[0] == bench.TUNING_HEADING and section[-1].startswith('| ')
    bench.replace_section(page, bench.TUNING_HEADING, section)  # appended
    bench.replace_section(page, bench.TUNING_HEADING, [bench.TUNING_HEADING, '', 'new'])
    assert page.read_text() == '# Benchmarks\n\nintro\n\n## Planning\n\nplans\n\n## Tuning\n\nnew\n'
    page.write_text('# B\n\n## Tuning\n\nold\n\n## Planning\n\nplans\n')
    bench.replace_section(page, bench.TUNING_HEADING, [bench.TUNING_HEADING, '', 'new'])
    assert page.read_text() == '# B\n\n## Tuning\n\nnew\n\n## Planning\n\nplans\n'


def run_at(steady: float, recorder_ms: float = 0.0) -> 'bench.GraphRun':
    return bench.GraphRun(overall=steady, steady=steady, steps=9294, startup_s=1.0,
                          teardown_s=0.2, cpu_ms_per_step={'recorder': recorder_ms}, count=0)


def test_the_recording_verdict_gives_the_median_pair_and_the_range_of_the_pairs():
    without = [run_at(250.0)] * 3
    # 5 %, 8 % and 12 % slower: the median pair is 8 %, within the goal
    recorded = [run_at(237.5), run_at(230.0), run_at(220.0)]
    verdicts = bench.recording_verdicts(without, recorded, [run_at(150.0, 0.08)])
    (composed,) = [v for v in verdicts if v.startswith('- composed')]
    assert '+8.0 % slower' in composed and 'from +5.0 to +12.0 %' in composed
    # three pairs, one beyond the goal: the median's interval reaches across it
    assert composed.endswith(': met (the interval of the median reaches across 10 %)')
    verdicts = bench.recording_verdicts(without, [run_at(220.0)] * 3, [run_at(150.0, 0.08)])
    (composed,) = [v for v in verdicts if v.startswith('- composed')]
    assert '+12.0 % slower' in composed and composed.endswith(': NOT met')
    assert 'interval of the median +12.0 to +12.0 %' in composed  # every pair the same


def test_the_recording_verdict_says_when_the_interval_of_the_median_reaches_past_the_goal():
    """The goal is the median's; its bootstrap interval says how surely: a median within the
    goal from pairs spread across it is met, and the verdict says the interval reaches past it."""
    without = [run_at(250.0)] * 9
    spread = [run_at(250.0 * (1 - c / 100)) for c in (2, 4, 6, 8, 9, 11, 13, 15, 17)]
    (composed,) = [v for v in bench.recording_verdicts(without, spread, [run_at(150.0, 0.08)])
                   if v.startswith('- composed')]
    assert '+9.0 % slower' in composed
    low, high = bench.median_interval([2, 4, 6, 8, 9, 11, 13, 15, 17])
    assert low < 9.0 < high and low >= 2 and high <= 17
    assert f'interval of the median {low:+.1f} to {high:+.1f} %' in composed
    assert composed.endswith(': met (the interval of the median reaches across 10 %)')
    tight = [run_at(250.0 * (1 - c / 100)) for c in (5.0, 5.2, 5.4, 5.5, 5.6, 5.8, 6.0, 6.1, 6.3)]
    (composed,) = [v for v in bench.recording_verdicts(without, tight, [run_at(150.0, 0.08)])
                   if v.startswith('- composed')]
    assert composed.endswith(': met')
    assert bench.median_interval([3.0, 3.0, 3.0]) == (3.0, 3.0)
    assert bench.median_interval([1.0, 2.0]) == (1.5, 1.5)  # too few for an interval
