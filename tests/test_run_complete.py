"""Issue 31, defect 1, without a recording: a run whose monitor missed steps (it fell behind
the loop further than the middleware keeps for it) gives no summary of part of the run; it
fails with a non-zero status naming the steps it lacks."""

from ato_bringup import runner
from ato_bringup.runner import RunFailed, run_lockstep
from ato_bringup.stack import StackConfig


def test_a_run_whose_monitor_missed_steps_fails_naming_them(tmp_path, domain_id):
    def lose(stack):  # what a monitor that fell too far behind never gets
        for stamp in [k for k in stack.monitor.samples if 30e9 <= k <= 60e9]:
            del stack.monitor.samples[stamp]
    config = StackConfig(scenario='short_line', end_time_s=100.0, domain_id=domain_id,
                         log_dir=tmp_path / 'logs', monitor='lean')
    try:
        run_lockstep(config, actions={70.0: lose})
    except RunFailed as error:
        message = str(error)
    else:
        raise AssertionError('the run gave a summary of part of itself')
    assert 'the run monitor missed 301 of the run\'s 1001 steps (30.0 s to 60.0 s (301 ' \
           'steps)) and the run was not recorded' in message, message


def test_the_steps_a_run_publishes_are_every_control_period_to_the_end():
    from ato_common.scenario import load_scenario
    config = StackConfig(scenario='short_line', end_time_s=0.95)
    assert runner.expected_steps(config, load_scenario('short_line')) == [
        0, 100_000_000, 200_000_000, 300_000_000, 400_000_000, 500_000_000, 600_000_000,
        700_000_000, 800_000_000, 900_000_000, 1_000_000_000]
