"""The parts of the scorecard (ato_bringup.scorecard) that need no graph: the external node's
tasks (the baseline's draws and knowledge), where the journey rule ends a run recorded to its
latest end, the plant's watchdog brakes read from its diagnostics, and the arguments."""

import pytest
import yaml

from ato_bringup import scorecard
from ato_bringup.graph_row import PLANT_STATUS, watchdog_brakes
from ato_campaigns.engine import load_campaign
from ato_common.run_events import WATCHDOG
from ato_simulation.plans import JourneyEnd

CAMPAIGN = {'name': 'score_parts', 'seed': 3, 'draws': 3, 'scenarios': ['short_line'],
            'laws': [{'law': 'pid', 'label': 'pid_flat', 'gradient': 'hidden'}, 'luo_xu'],
            'configurations': ['published'], 'baseline': 'pid_flat', 'timeout_s': 60}


@pytest.fixture
def campaign(tmp_path):
    path = tmp_path / 'parts.yaml'
    path.write_text(yaml.safe_dump(CAMPAIGN))
    return load_campaign(path)


def test_the_node_runs_the_baseline_s_draws_with_its_knowledge_and_no_settings(campaign):
    tasks = scorecard.external_tasks(campaign, 'mine')
    baseline = [t for t in campaign.tasks() if t['law'] == campaign.baseline]
    assert [t['draw'] for t in tasks] == [t['draw'] for t in baseline] == [0, 1, 2]
    for mine, base in zip(tasks, baseline):
        assert mine['values'] == base['values']  # the same truth, the same knowledge
        assert mine['values']['gradient_known'] == 0.0  # the baseline entry hides the grades
        assert (mine['law'], mine['law_name'], mine['configuration'], mine['settings']) == (
            'mine/own', 'mine', 'own', {})
        assert mine['model'] == base['model'] and mine['timeout_s'] == 60


JOURNEY = JourneyEnd(stop_m=1000.0, reach_m=50.0, settle_s=5.0, planned_s=10.0, limit_s=30.0)
PERIOD_NS = 1_000_000_000


def samples(arrival_s: float | None, end_s: float = 30.0):
    """A train that moves until ``arrival_s`` and stands at the stop from then (never: None)."""
    times = [float(t) for t in range(int(end_s) + 1)]
    standing = [arrival_s is not None and t >= arrival_s for t in times]
    return (times, [1000.0 if s else 900.0 + t for s, t in zip(standing, times)],
            [0.0 if s else 5.0 for s in standing])


def test_a_train_at_its_stop_at_the_planned_end_ends_there():
    assert scorecard.journey_count(JOURNEY, PERIOD_NS, *samples(8.0)) == 11  # 0 s to 10 s


def test_a_late_train_runs_on_until_it_has_stood_the_settle_time():
    count = scorecard.journey_count(JOURNEY, PERIOD_NS, *samples(17.0))
    times = samples(17.0)[0][:count]
    assert times[-1] - 17.0 >= JOURNEY.settle_s and times[-1] < 17.0 + JOURNEY.settle_s + 5.0


def test_a_train_that_never_arrives_runs_to_the_limit():
    assert scorecard.journey_count(JOURNEY, PERIOD_NS, *samples(None)) == 31


def test_the_plant_s_watchdog_brakes_are_read_from_its_diagnostics_up_to_the_run_s_end():
    def status(t_s, watchdog, atp='False'):
        return (int(t_s * 1e9), PLANT_STATUS, {'watchdog': watchdog, 'atp_intervention': atp},
                f'command watchdog: {watchdog}')
    diagnostics = [status(0, 'normal'), status(5, 'service brake'), status(6, 'normal'),
                   status(8, 'emergency brake', atp='True'), status(9, 'normal'),
                   status(20, 'service brake')]
    brakes = watchdog_brakes(diagnostics, int(10e9))
    assert brakes.count(WATCHDOG) == 2
    assert [e.kind for e in brakes.events] == [WATCHDOG, WATCHDOG]  # the ATP's are the run's
    assert [e.time_s for e in brakes.events] == [5.0, 8.0]


def test_bad_arguments_are_refused(capsys):
    for argv in (['--campaign', 'c.yaml'],
                 ['--controller-command', ' ', '--campaign', 'c.yaml'],
                 ['--controller-command', 'x', '--campaign', 'c.yaml', '--label', 'a/b'],
                 ['--controller-command', 'x', '--campaign', 'c.yaml', '--workers', '0']):
        with pytest.raises(SystemExit) as exit_:
            scorecard.parse_args(argv)
        assert exit_.value.code == 2
    assert scorecard.main(['--controller-command', 'x', '--campaign', 'no_such.yaml']) == 2

