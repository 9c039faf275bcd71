"""Issue 14, defects 4 and 5: the summary shows ATP interventions, watchdog brakes, missed
journey windows and stopping errors beyond the platform tolerance (counts and first
occurrence), the exit code is 0 only for a clean run or with --no-fail-on-events; one command
runs a scenario file offline."""

import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from ato_common.metrics import RunMetrics
from ato_common.run_events import (
    ATP,
    EVENTS_EXIT_CODE,
    JOURNEY,
    LATE_AFTER_S,
    PLANT_STATUS,
    STATUSES,
    STOP,
    WATCHDOG,
    RunEvents,
    arrival_times,
    exit_code,
    journey_events,
    late_arrivals,
    merge,
    plant_atp_events,
    run_status,
    safety_events,
    stop_events,
)
from ato_common.scenario import parse_scenario
from ato_simulation import run_offline
from ato_simulation.loop import run_offline as run_offline_loop

SAMPLES = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'
PERIOD_NS = 100_000_000


def status(t_s, atp=False, count=0, watchdog='normal', message='running'):
    return (int(t_s * 1e9), PLANT_STATUS, {'atp_intervention': str(atp),
                                           'atp_interventions': str(count),
                                           'watchdog': watchdog}, message)


def test_safety_events_count_onsets_and_keep_the_first():
    diagnostics = [
        status(0.0), status(10.0, True, 1, message='ATP emergency brake intervention: 171 km/h'),
        status(11.0, True, 1, message='ATP emergency brake intervention: 165 km/h'),
        status(12.0, False, 1), status(20.0, True, 2, message='ATP again'),
        status(21.0, False, 2),
        status(30.0, False, 2, 'service brake', 'command watchdog: service brake'),
        status(30.2, False, 2, 'emergency brake', 'command watchdog: emergency brake'),
        status(31.0, False, 2), status(32.0, False, 2),
        (int(40e9), 'controller', {'atp_intervention': 'True'}, 'not the plant'),
    ]
    events = safety_events(reversed(diagnostics))  # order of arrival does not matter
    assert events.count(ATP) == 2 and events.count(WATCHDOG) == 1
    assert events.first(ATP).time_s == 10.0
    assert events.first(ATP).detail == 'ATP emergency brake intervention: 171 km/h'
    assert events.first(WATCHDOG).detail == 'command watchdog: service brake'
    assert not events.clean
    # a counter above the onsets seen (a status lost) counts
    assert safety_events([status(0.0), status(5.0, False, 3)]).count(ATP) == 3
    assert safety_events([status(0.0), status(5.0)]).clean


def metrics(stop_errors):
    return RunMetrics(10, 100.0, 0.0, 0.0, 0.0, 0.0, stop_errors, 1.0)


def test_stop_errors_beyond_the_tolerance_are_events():
    stations = [('A', 0.0, 0.0), ('B', 1000.0, 90.0), ('C', 2000.0, 200.0), ('D', 3000.0, 300.0)]
    events = stop_events(metrics({'A': 0.0, 'B': 0.5, 'C': -0.51, 'D': math.nan}), stations)
    assert events.count(STOP) == 2
    assert events.first(STOP).detail.startswith('C: stopped -0.510 m')
    missing = stop_events(metrics({'A': 0.0, 'B': 0.1}), stations[:3], tolerance_m=0.5)
    assert missing.count(STOP) == 1
    assert 'the run ended before the stop' in missing.first(STOP).detail
    assert stop_events(metrics({'A': 0.0, 'B': 0.1}), stations[:2]).clean


def journey_scenario(tmp_path, windows):
    track = json.loads((SAMPLES / 'tracks' / '00_reference.json').read_text())
    track_id = track['metadata']['id']
    length = track['stops']['values'][-1]
    journey = {'metadata': {'id': f'{track_id}_J', 'associated track': track_id,
                            'library version': 'TTOBench v1.5'},
               'timing points': {'units': {'position': 'm', 'lower time constraint': 's',
                                           'upper time constraint': 's',
                                           'lower speed constraint': 'km/h',
                                           'upper speed constraint': 'km/h'},
                                 'values': [[0, *windows[0], 0, 0],
                                            [length / 2, *windows[1], None, None],
                                            [length, *windows[2], 0, 0]]}}
    (tmp_path / 'j.json').write_text(json.dumps(journey))
    return parse_scenario({
        'name': 'j', 'train': {'ttobench': str(SAMPLES / 'trains' / 'CN_Beijing_Subway.json')},
        'line': {'ttobench': str(SAMPLES / 'tracks' / '00_reference.json')},
        'journey': {'ttobench': str(tmp_path / 'j.json')},
        'planning': {'max_acceleration_mps2': 0.5, 'service_deceleration_mps2': 0.5,
                     'max_jerk_mps3': 0.5}}), length


def test_journey_windows_missed_by_the_run_are_events(tmp_path):
    scenario, length = journey_scenario(tmp_path, [(0, 5), (None, 50), (100, 200)])
    times = [0.0, 5.0, 10.0, 60.0, 150.0, 160.0]
    positions = [0.0, 0.0, 1.0, length / 2 + 1, length - 0.2, length]
    events = journey_events(scenario, times, positions)
    # departure at 5 s (in its window); passing at 60 s (after 50: missed); arrival at 150 s
    assert events.count(JOURNEY) == 1
    assert events.first(JOURNEY).time_s == 60.0
    assert 'passing at 60.0 s, outside [-, 50] s' in events.first(JOURNEY).detail
    # never arriving is a missed window too
    short = journey_events(scenario, times[:4], positions[:4])
    assert short.count(JOURNEY) == 2 and 'no arrival in the run' in short.events[-1].detail
    # a departure before the earliest time
    early, _ = journey_scenario(tmp_path, [(10, None), (None, None), (None, None)])
    assert journey_events(early, times, positions).count(JOURNEY) == 1


def test_the_offline_events_are_the_interventions_the_plant_made():
    """A drive stuck at full traction from 60 to 200 s: the plant's ATP brakes and holds its
    brake while the train interface reports the faulty drive, then releases it; the offline
    run's events are exactly those."""
    run = run_offline_loop(parse_scenario(yaml.safe_load(STUCK), 'stuck.yaml'), 'pid',
                           end_time_s=300.0)
    assert run.atp_interventions >= 1
    # held to standstill until the fault ends at 200 s, then driven on
    standing = (run.times_s > run.atp_times_s[0] + 60.0) & (run.times_s < 199.0)
    assert standing.any() and np.all(run.speeds[standing] == 0.0)
    assert run.speeds[-1] > 1.0
    assert len(run.atp_times_s) == run.atp_interventions
    assert list(run.atp_times_s) == sorted(run.atp_times_s)
    assert 60.0 < run.atp_times_s[0] < 200.0
    events = plant_atp_events(run.atp_times_s)
    assert events.count(ATP) == run.atp_interventions
    assert events.first(ATP).time_s == run.atp_times_s[0]


def test_the_exit_code_is_zero_only_when_clean_or_asked():
    clean = safety_events([status(0.0)])
    dirty = safety_events([status(0.0), status(1.0, True, 1)])
    assert exit_code(clean) == 0 and exit_code(clean, False) == 0
    assert exit_code(dirty) == EVENTS_EXIT_CODE and exit_code(dirty, False) == 0


#: a traction drive stuck at 300 kN from 60 to 200 s (tests/data/synthetic)
STUCK = (Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'synthetic'
         / 'stuck_traction.yaml').read_text()

CLEAN = STUCK.split('plant:')[0]


def test_the_offline_command_runs_a_file_and_reports_what_went_wrong(tmp_path, capsys):
    (tmp_path / 'stuck.yaml').write_text(STUCK)
    out = tmp_path / 'out.json'
    assert run_offline.main(['--scenario', str(tmp_path / 'stuck.yaml'), '--json',
                             str(out)]) == EVENTS_EXIT_CODE
    printed = capsys.readouterr().out
    assert 'ATP interventions     ' in printed and ', first at ' in printed
    # the ATP's stop supervision holds the train at B, so the stop itself may be in tolerance
    assert '\nstop errors           ' in printed
    assert 'NOT CLEAN' in printed
    saved = json.loads(out.read_text())
    assert saved['clean'] is False and saved['counts'][ATP] >= 1 and STOP in saved['counts']
    assert run_offline.main(['--scenario', str(tmp_path / 'stuck.yaml'),
                             '--no-fail-on-events']) == 0


def test_the_offline_command_runs_a_clean_file_and_refuses_bad_input(tmp_path, capsys):
    (tmp_path / 'clean.yaml').write_text(CLEAN)
    assert run_offline.main(['--scenario', str(tmp_path / 'clean.yaml')]) == 0
    printed = capsys.readouterr().out
    assert 'scenario              stuck' in printed and 'events                clean' in printed
    (tmp_path / 'bad.yaml').write_text(CLEAN.replace('max_jerk_mps3', 'max_jerk'))
    assert run_offline.main(['--scenario', str(tmp_path / 'bad.yaml')]) == 2
    assert 'unknown field max_jerk; did you mean max_jerk_mps3?' in capsys.readouterr().err
    assert run_offline.main(['--scenario', str(tmp_path / 'absent.yaml')]) == 2
    with pytest.raises(SystemExit):
        run_offline.parse_args(['--stop-tolerance', 'nan'])



def test_an_arrival_is_the_start_of_the_last_standstill_at_the_stop():
    # stands 150 m short at 100 s (within its 200 m length), creeps on, stands at the stop
    # from 130 s; never stands at C
    times = [0.0, 90.0, 100.0, 110.0, 120.0, 130.0, 140.0, 150.0]
    positions = [0.0, 9000.0, 9850.0, 9850.0, 9990.0, 10000.0, 10000.0, 15000.0]
    speeds = [0.0, 20.0, 0.0, 0.0, 1.0, 0.0, 0.0, 30.0]
    stops = [('B', 10000.0, 120.0), ('C', 20000.0, 300.0)]
    assert arrival_times(stops, times, positions, speeds, 200.0) == {'B': 130.0, 'C': None}
    # the timetable's arrival at B is 120 s: 10 s late is late, 9 s is not
    assert late_arrivals(stops, times, positions, speeds, 200.0) == [('B', 10.0)]
    assert late_arrivals([('B', 10000.0, 121.0)], times, positions, speeds, 200.0) == []
    assert LATE_AFTER_S == 10.0


def test_a_run_is_ok_only_when_clean_and_its_status_names_the_most_serious():
    clean = merge(RunEvents((), {ATP: 0}), RunEvents((), {STOP: 0}))
    assert run_status(clean) == ('ok', '')
    atp = plant_atp_events([103.4, 150.0])
    stops = stop_events(RunMetrics(10, 100.0, 0, 0, 0, 0, {'B': 0.8}, 1.0),
                        [('B', 10000.0, 120.0)])
    events = merge(atp, stops)
    status, reason = run_status(events, late=[('B', 12.5)])
    assert status == 'ATP intervention'
    assert reason == ('2 ATP interventions (first at 103.4 s); 1 stop errors (first at '
                      '120.0 s); late: B 12.5 s after the timetable (late from 10 s)')
    assert run_status(stops, late=[('B', 12.5)])[0] == 'stop error'
    assert run_status(clean, late=[('B', 12.5)])[0] == 'late'
    assert run_status(clean, held=['nan force', 'nan force']) == (
        'faults', '2 steps held: nan force')
    status, reason = run_status(events, unfinished='stands 3 km short of C')
    assert status == 'did not finish' and reason.startswith(
        'did not finish: stands 3 km short of C; 2 ATP interventions')
    assert STATUSES.index('did not finish') < STATUSES.index('ATP intervention') < \
        STATUSES.index('stop error') < STATUSES.index('late') < STATUSES.index('ok')
