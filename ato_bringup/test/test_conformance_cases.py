"""The conformance harness's judges on made-up observations: each case fails on the fault it
is about, with evidence naming it, and passes a clean run."""

import math

from ato_bringup.conformance_cases import (
    Epoch,
    Observation,
    Schedule,
    Sent,
    judge,
    report,
    variant_document,
)
from ato_common.contract import CASES

PERIOD = 100_000_000
ACTUATORS = ('traction',)


def clean_epoch(steps: int, end_s: float) -> Epoch:
    epoch = Epoch(end_s=end_s)
    for k in range(steps):
        stamp = k * PERIOD
        epoch.states[stamp] = 1
        epoch.truth[stamp] = (float(k), 1.0)
        epoch.reference[stamp] = (float(k), 1.0)
        epoch.commands.append(Sent(stamp, 'law', ACTUATORS, (1.0,), float(k)))
    epoch.plant = {'wrong_stamp_commands': '0', 'rejected_commands': '0'}
    epoch.plans = [(0, 'planned'), (20 * PERIOD, 'resumed: the train stood behind')]
    return epoch


def clean_observation() -> Observation:
    schedule = Schedule(200.0)
    main = clean_epoch(2001, 200.0)
    observation = Observation(ACTUATORS, PERIOD, schedule, main, clean_epoch(201, 20.0))
    observation.original_positions = {k: v[0] + 500.0 for k, v in main.truth.items()}
    observation.stop_sent_s, observation.stop_exit, observation.stop_took_s = 1e6, 0, 0.3
    observation.stop_stalled_s = 0.3
    observation.other_scenario, observation.other_commands, observation.other_exit = 'x', 0, 2
    return observation


def verdicts(observation):
    return {r.name: r.passed for r in judge(observation)}


def test_a_clean_run_passes_every_case_and_the_report_says_so():
    results = judge(clean_observation())
    assert [r.name for r in results] == list(CASES)
    assert all(r.passed for r in results), report(results, 'clean')
    assert report(results, 'clean').endswith(f'{len(CASES)} of {len(CASES)} cases passed')


def test_each_fault_fails_its_case():
    o = clean_observation()
    o.main.commands = [c for c in o.main.commands if c.stamp_ns != 50 * PERIOD]
    o.restarted.commands.append(Sent(7, 'law', ACTUATORS, (1.0,), 0.0))  # a stamp no state had
    o.main.states[60 * PERIOD] = 2  # the step sent again ...
    o.main.commands.append(Sent(60 * PERIOD, 'law', ACTUATORS, (2.0,), 0.0))  # ... stepped twice
    o.restarted.stalled = 'the plant stood at the step of 0.0 s'
    o.other_commands, o.other_exit = 3, None
    o.stop_exit, o.stop_took_s, o.stop_stalled_s = 0, 7.0, 6.5
    o.after_stop = [Sent(0, '', ACTUATORS, (0.0,), o.stop_sent_s + 0.01)]
    for k in o.main.truth:  # the train follows the first plan, not the stream
        o.main.truth[k] = (o.original_positions[k], 1.0)
    sensor = [c for c in o.main.commands if 150.0 <= c.stamp_ns / 1e9 < 160.0]
    o.main.commands.remove(sensor[0])
    o.main.commands.append(Sent(sensor[0].stamp_ns, 'law', ACTUATORS, (math.nan,), 0.0))
    results = {r.name: r for r in judge(o)}
    assert not any(r.passed for r in results.values()), report(list(results.values()), 'faults')
    assert 'first unanswered at 5.0 s' in results['answers_every_step'].evidence
    assert 'which no state had' in results['stamps'].evidence
    assert 'a re-sent step at 6.0 s got another command' in results['rate'].evidence
    o.main.states[60 * PERIOD] = 1  # once sent, twice answered: a command on its own timer
    assert 'more commands than states at 6.0 s' in {r.name: r for r in judge(o)}['rate'].evidence
    assert '3 commands' in results['refuses_other_scenario'].evidence
    assert 'stood at the step' in results['survives_restart'].evidence
    assert 'after 7.00 s of wall time, 6.50 s of it without progress' in \
        results['stops_when_told'].evidence
    assert '1 commands after the stop signal' in results['no_command_after_shutdown'].evidence
    assert '0.0 m from the first plan' in results['follows_replanned_reference'].evidence
    assert '1 non-finite commands' in results['failed_sensor'].evidence


def test_a_stop_is_timed_without_the_time_the_machine_kept_the_node_waiting_for_a_cpu():
    """A node on a loaded machine that takes 9 s of wall time to end, runnable all along (it
    waited for a CPU), stops within the limit; one that slept 6 s of them does not, nor one
    past the bound of wall time however busy."""
    from ato_bringup.conformance_cases import STOP_LIMIT_S, STOP_WALL_FACTOR
    o = clean_observation()
    o.stop_took_s, o.stop_stalled_s = 9.0, 0.4
    assert verdicts(o)['stops_when_told'] is True
    o.stop_stalled_s = STOP_LIMIT_S + 1.0
    assert verdicts(o)['stops_when_told'] is False
    o.stop_took_s, o.stop_stalled_s = STOP_WALL_FACTOR * STOP_LIMIT_S + 1.0, 0.0
    assert verdicts(o)['stops_when_told'] is False
    o.stop_exit, o.stop_took_s = None, STOP_WALL_FACTOR * STOP_LIMIT_S + 1.0
    result = {r.name: r for r in judge(o)}['stops_when_told']
    assert result.passed is False and result.evidence.startswith('still running')


def test_a_situation_the_harness_could_not_bring_about_is_not_run():
    o = clean_observation()
    o.main.plans = [(0, 'planned')]  # no replan
    o.other_stalled = 'the plant of the other scenario published no step'
    results = {r.name: r for r in judge(o)}
    assert results['follows_replanned_reference'].passed is None
    assert results['refuses_other_scenario'].verdict == 'NOT RUN'
    assert 'not passed: refuses_other_scenario, follows_replanned_reference' in report(
        list(results.values()), 'x')


def test_the_variant_adds_the_test_conditions_and_keeps_the_rest():
    document = {'name': 'short_line', 'train': {'preset': 'crh3_luo_xu'},
                'plant': {'failures': [{'actuator': 'traction', 'kind': 'stuck', 'start_s': 500,
                                        'force_n': 1.0}],
                          'sensors': {'seed': 3, 'speed': {'noise_std': 0.01}}}}
    variant = variant_document(document, ('car_2', 'car_3'), Schedule(200.0))
    assert variant['name'] == 'short_line' and variant['train'] == document['train']
    failures = variant['plant']['failures']
    assert failures[0] == document['plant']['failures'][0]
    assert [(f['actuator'], f['kind'], f['start_s'], f['end_s']) for f in failures[1:]] == [
        ('car_2', 'loss', 0.0, 20.0), ('car_3', 'loss', 0.0, 20.0)]
    speed = variant['plant']['sensors']['speed']
    assert (speed['noise_std'], speed['failed_from_s'], speed['failed_until_s']) == (
        0.01, 150.0, 160.0)
    assert variant['plant']['sensors']['seed'] == 3
    assert document['plant']['failures'][1:] == []  # the document itself is left as it was
