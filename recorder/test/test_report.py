"""The report reads the suite's topics by the conventions' names, in the namespace the stack ran
in: found when the recording holds one, chosen with --namespace when it holds several."""

import math
from dataclasses import replace

import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Header

from ato_common.conventions import TOPICS
from ato_common.types import Command, Reference, ReferencePoint, TrainState
from ato_ros.messages import command_to_msg, reference_to_msg, state_to_msg
from recorder.bag import BagError, BagWriter
from recorder.report import load_run, main, namespaces_of, resolve_topics

SECONDS = 11  # one sample a second: moving at 10 m/s, then stopped at the end of the curve


def write_run(writer: BagWriter, namespace: str, lag_m: float) -> None:
    """A run in ``namespace`` whose train lags its reference by ``lag_m``."""
    def name(key):
        return TOPICS[key].name if TOPICS[key].name.startswith('/') else \
            f'{namespace}/{TOPICS[key].name}'
    for key in ('state', 'reference', 'command', 'curve'):
        writer.add_topic(name(key), TOPICS[key].type_name)
    curve = Reference(0, tuple(ReferencePoint(float(k), 10.0 * min(k, 9), 10.0 if k < 9 else 0.0,
                                              0.0) for k in range(SECONDS)))
    writer.write(name('curve'), 0, serialize_message(reference_to_msg(curve)))
    for k in range(SECONDS):
        stamp = k * 1_000_000_000
        x_ref = 10.0 * min(k, 9)
        state = TrainState(stamp, ('car_1',), (x_ref - lag_m,), (10.0 if k < 9 else 0.0,),
                           (0.0,), (1000.0,))
        reference = Reference(stamp, (ReferencePoint(float(k), x_ref, state.speeds[0], 0.0),))
        command = Command(stamp, ('car_1',), (1000.0,), f'law{namespace.replace("/", "_")}')
        writer.write(name('state'), stamp, serialize_message(state_to_msg(state)))
        writer.write(name('reference'), stamp, serialize_message(reference_to_msg(reference)))
        writer.write(name('command'), stamp, serialize_message(command_to_msg(command)))


def record(folder, runs: dict[str, float]):
    """A recording of one run per namespace ('' is the root), namespace -> lag."""
    writer = BagWriter(folder)
    for namespace, lag in runs.items():
        write_run(writer, namespace, lag)
    writer.close()
    return folder


@pytest.mark.parametrize('namespace', ['', '/train1', '/fleet/train1'],
                         ids=['root', 'train1', 'nested'])
def test_the_one_namespace_of_the_recording_is_found(tmp_path, namespace):
    bag = record(tmp_path / 'run', {namespace: 0.25})
    assert resolve_topics(bag)['state'] == f'{namespace}/train/state'
    assert resolve_topics(bag)['diagnostics'] == '/diagnostics'   # global by convention
    data = load_run(bag)
    assert len(data.stamps_ns) == SECONDS
    assert data.ref_positions - data.positions == pytest.approx([0.25] * SECONDS)
    assert data.laws == [f'law{namespace.replace("/", "_")}']
    assert [(s.station_position_m, s.time_s) for s in data.stops] == [(90.0, 10.0)]


def test_the_names_come_from_the_conventions(tmp_path, monkeypatch):
    bag = record(tmp_path / 'run', {'/train1': 0.0})
    assert namespaces_of({'/train1/train/state': TOPICS['state'].type_name}) == {'/train1'}
    assert namespaces_of({'/train1/train/state': 'std_msgs/msg/Float64'}) == set()  # type
    monkeypatch.setitem(TOPICS, 'state', replace(TOPICS['state'], name='renamed/state'))
    assert resolve_topics(bag)['state'] == '/train1/renamed/state'


def test_several_namespaces_are_an_error_naming_them_until_one_is_chosen(tmp_path, capsys):
    bag = record(tmp_path / 'run', {'/train1': 0.5, '/train2': 2.0, '': 1.0})
    with pytest.raises(BagError, match=r'several namespaces: /, /train1, /train2; choose one '
                                       r'with --namespace'):
        load_run(bag)
    for chosen, lag in (('/train2', 2.0), ('train1', 0.5), ('/', 1.0)):
        data = load_run(bag, chosen)
        assert data.ref_positions - data.positions == pytest.approx([lag] * SECONDS), chosen
    assert main([str(bag)]) == 2
    assert 'several namespaces: /, /train1, /train2' in capsys.readouterr().err
    assert main([str(bag), '--namespace', '/train2', '--output', str(tmp_path / 'plots')]) == 0
    assert 'law_train2' in capsys.readouterr().out
    assert (tmp_path / 'plots' / 'tracking.png').exists()


def test_a_namespace_without_the_topics_or_a_recording_without_any_says_where_they_are(
        tmp_path):
    bag = record(tmp_path / 'run', {'/train1': 0.0})
    with pytest.raises(BagError, match=r'in namespace /train9; it holds them in /train1'):
        load_run(bag, '/train9')
    from std_msgs.msg import String
    other = BagWriter(tmp_path / 'other')
    other.add_topic('/chatter', 'std_msgs/msg/String')
    other.write('/chatter', 1, serialize_message(String(data='hello')))
    other.close()
    with pytest.raises(BagError, match=r"none of the suite's topics \(train/state, "
                                       r'ato/reference, .*\) in any namespace; it has /chatter'):
        load_run(tmp_path / 'other')


def test_labels_name_the_quantity_and_its_unit():
    from recorder.report_plots import label
    assert label('integral_action_mps2') == 'integral action (m/s²)'
    assert label('mass_kg') == 'mass (kg)'
    assert label('davis_b_n_per_mps') == 'davis b (N/(m/s))'
    assert label('speed_error_mps') == 'speed error (m/s)'
    assert label('gain') == 'gain'


def test_the_report_marks_atp_and_watchdog_events_and_plots_every_actuator(tmp_path, capsys):
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from std_msgs.msg import Float64

    from ato_ros.messages import actuator_forces_to_msg, diagnostic_status, to_time
    writer = BagWriter(tmp_path / 'run')
    write_run(writer, '', 0.0)
    for key in ('permitted_speed', 'distance_to_go', 'actuators_commanded',
                'actuators_applied', 'diagnostics'):
        writer.add_topic('/' + TOPICS[key].name.lstrip('/'), TOPICS[key].type_name)
    plant = [('normal', False), ('normal', False), ('service brake', False),
             ('service brake', True), ('normal', False)] + [('normal', False)] * 6
    for k in range(SECONDS):
        stamp = k * 1_000_000_000
        writer.write('/ato/permitted_speed', stamp, serialize_message(Float64(data=20.0)))
        writer.write('/ato/distance_to_go', stamp, serialize_message(Float64(data=90.0 - k)))
        writer.write('/train/actuators/commanded', stamp, serialize_message(
            actuator_forces_to_msg(stamp, ['unit_1', 'unit_2'], [1000.0, 2000.0])))
        writer.write('/train/actuators/applied', stamp, serialize_message(
            actuator_forces_to_msg(stamp, ['unit_1', 'unit_2'], [900.0, 0.0])))
        watchdog, atp = plant[k]
        status = diagnostic_status('train_plant_node: simulation', 'train', DiagnosticStatus.OK,
                                   'running', {'watchdog': watchdog, 'atp_intervention': atp,
                                               'estimate.x': 1.0})
        writer.write('/diagnostics', stamp, serialize_message(
            DiagnosticArray(header=Header(stamp=to_time(stamp)), status=[status])))
    writer.close()
    data = load_run(tmp_path / 'run')
    assert [(t, kind) for t, kind, _ in data.events] == [
        (2.0, 'watchdog: service brake'), (3.0, 'ATP intervention'), (4.0, 'ATP released'),
        (4.0, 'watchdog: normal')]
    assert sorted(data.actuators_applied) == ['unit_1', 'unit_2']
    assert [f for _, f in data.actuators_applied['unit_2']] == [0.0] * SECONDS
    assert [v for _, v in data.permitted] == [20.0] * SECONDS
    assert main([str(tmp_path / 'run'), '--output', str(tmp_path / 'plots')]) == 0
    out = capsys.readouterr().out
    assert 'ATP intervention' in out and 'watchdog: service brake' in out
    for name in ('tracking', 'errors', 'distance_to_go', 'stops', 'commands', 'actuators',
                 'energy'):
        assert (tmp_path / 'plots' / f'{name}.png').exists(), name


def test_the_html_report_holds_the_summary_and_every_plot(tmp_path):
    import base64
    from html.parser import HTMLParser

    bag = record(tmp_path / 'run', {'': 0.25})
    assert main([str(bag), '--output', str(tmp_path / 'plots')]) == 0
    pngs = sorted(p.stem for p in (tmp_path / 'plots').glob('*.png'))

    class Page(HTMLParser):
        images, cells, in_cell = {}, [], False

        def handle_starttag(self, tag, attrs):
            attrs = dict(attrs)
            if tag == 'img':
                self.images[attrs['alt']] = attrs['src']
            self.in_cell = tag in ('th', 'td')

        def handle_data(self, data):
            if self.in_cell:
                self.cells.append(data)

    page = Page()
    page.feed((tmp_path / 'plots' / 'report.html').read_text())
    assert sorted(page.images) == pngs and 'tracking' in pngs
    for name, src in page.images.items():
        prefix = 'data:image/png;base64,'
        assert src.startswith(prefix), name
        assert base64.b64decode(src[len(prefix):]) == (tmp_path / 'plots' /
                                                       f'{name}.png').read_bytes()
    assert 'position error, max (m)' in page.cells and '0.2500' in page.cells
    assert 'stopping error, stop at 90 m (m)' in page.cells


def test_a_multi_car_run_is_plotted_per_car(tmp_path):
    writer = BagWriter(tmp_path / 'run')
    for key in ('state', 'reference', 'command', 'curve'):
        writer.add_topic('/' + TOPICS[key].name, TOPICS[key].type_name)
    for k in range(SECONDS):
        stamp = k * 1_000_000_000
        state = TrainState(stamp, ('car_1', 'car_2'), (10.0 * k, 10.0 * k - 25.0),
                           (10.0, 10.0 - 0.1 * k), (0.0, 0.0), (1000.0, -500.0))
        reference = Reference(stamp, (ReferencePoint(float(k), 10.0 * k, 10.0, 0.0),))
        writer.write('/train/state', stamp, serialize_message(state_to_msg(state)))
        writer.write('/ato/reference', stamp, serialize_message(reference_to_msg(reference)))
        writer.write('/ato/command', stamp, serialize_message(command_to_msg(
            Command(stamp, ('car_1',), (500.0,), 'pid'))))
    writer.close()
    data = load_run(tmp_path / 'run')
    assert data.cars == ['car_1', 'car_2']
    assert data.car_positions[:, 1] - data.car_positions[:, 0] == pytest.approx([-25.0] * 11)
    assert data.car_speeds[-1, 1] == pytest.approx(9.0)
    assert data.car_forces[0].tolist() == [1000.0, -500.0]
    assert main([str(tmp_path / 'run'), '--output', str(tmp_path / 'plots')]) == 0
    assert (tmp_path / 'plots' / 'cars.png').exists()


def test_the_summary_counts_what_went_wrong_with_the_first_occurrence():
    from dataclasses import replace

    from ato_common.metrics import RunMetrics
    from recorder.report import event_rows, summary_rows
    metrics = RunMetrics(rms_speed_error_kmh=0.1, max_speed_error_kmh=0.2,
                         rms_position_error_m=0.1, max_position_error_m=0.2,
                         stop_errors_m={'A': 0.01, 'B': -0.8}, traction_energy_kwh=1.0,
                         simulated_time_s=100.0, samples=1000)
    events = [(12.5, 'ATP intervention', 'overspeed'), (20.0, 'ATP released', ''),
              (31.0, 'ATP intervention', 'overspeed'), (40.0, 'watchdog: service_brake', ''),
              (41.0, 'watchdog: normal', '')]
    rows = dict(event_rows(metrics, events))
    assert rows['ATP interventions'] == '2, first at 12.5 s'
    assert rows['watchdog brakes'] == '1, first at 40.0 s'
    assert rows['stop errors beyond 0.5 m'] == '1: B -0.80 m'
    clean = dict(summary_rows(replace(metrics, stop_errors_m={'A': 0.01}), ['pid']))
    assert clean['ATP interventions'] == '0' and clean['stop errors beyond 0.5 m'] == '0'


def test_each_stack_of_a_recording_has_its_own_events(tmp_path):
    """Two stacks side by side on the one /diagnostics: the report of one takes only the
    statuses of its own nodes (named after their fully qualified names)."""
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

    from ato_ros.messages import diagnostic_status, to_time
    writer = BagWriter(tmp_path / 'run')
    for namespace in ('/train1', '/train2'):
        write_run(writer, namespace, 0.0)
    writer.add_topic('/diagnostics', TOPICS['diagnostics'].type_name)
    for k in range(SECONDS):
        stamp = k * 1_000_000_000
        statuses = [diagnostic_status(f'{ns}/train_plant_node: simulation', 'train',
                                      DiagnosticStatus.OK, 'running',
                                      {'watchdog': 'normal',
                                       'atp_intervention': k >= start})
                    for ns, start in (('train1', 3), ('train2', 6))]
        writer.write('/diagnostics', stamp, serialize_message(
            DiagnosticArray(header=Header(stamp=to_time(stamp)), status=statuses)))
    writer.close()
    for namespace, start in (('/train1', 3.0), ('/train2', 6.0)):
        data = load_run(tmp_path / 'run', namespace)
        assert [(t, kind) for t, kind, _ in data.events] == [(start, 'ATP intervention')]


def journey_run(tmp_path, windows, identity_of=None):
    """A recording of a train running a TTOBench sample track at 20 m/s, its scenario file
    with a journey of ``windows`` at its start, middle and end, and the plant's identity of
    ``identity_of`` (default: that scenario)."""
    import json
    from pathlib import Path

    from std_msgs.msg import String
    tmp_path.mkdir(parents=True, exist_ok=True)

    from ato_common.identity import scenario_identity
    from ato_common.scenario import load_scenario
    samples = Path(__file__).resolve().parents[2] / 'tests' / 'data' / 'ttobench'
    track = json.loads((samples / 'tracks' / '00_reference.json').read_text())
    length = track['stops']['values'][-1]
    journey = {'metadata': {'id': f"{track['metadata']['id']}_J",
                            'associated track': track['metadata']['id'],
                            'library version': 'TTOBench v1.5'},
               'timing points': {'units': {'position': 'm', 'lower time constraint': 's',
                                           'upper time constraint': 's',
                                           'lower speed constraint': 'km/h',
                                           'upper speed constraint': 'km/h'},
                                 'values': [[0, *windows[0], 0, 0],
                                            [length / 2, *windows[1], None, None],
                                            [length, *windows[2], 0, 0]]}}
    (tmp_path / 'j.json').write_text(json.dumps(journey))
    scenario_file = tmp_path / 'journey.yaml'
    scenario_file.write_text(
        f"name: journey\ntrain: {{ttobench: {samples / 'trains' / 'CN_Beijing_Subway.json'}}}\n"
        f"line: {{ttobench: {samples / 'tracks' / '00_reference.json'}}}\n"
        f"journey: {{ttobench: {tmp_path / 'j.json'}}}\n"
        'planning: {max_acceleration_mps2: 0.5, service_deceleration_mps2: 0.5, '
        'max_jerk_mps3: 0.5}\n')
    writer = BagWriter(tmp_path / 'run')
    for key in ('state', 'reference', 'command', 'curve', 'identity'):
        writer.add_topic('/' + TOPICS[key].name, TOPICS[key].type_name)
    writer.write('/train/identity', 0, serialize_message(String(data=scenario_identity(
        load_scenario(str(identity_of or scenario_file))))))
    seconds = int(length / 20.0) + 2
    for k in range(seconds):
        stamp, x = k * 1_000_000_000, min(20.0 * k, length)
        v = 20.0 if x < length else 0.0
        state = TrainState(stamp, ('car_1',), (x,), (v,), (0.0,), (1000.0,))
        reference = Reference(stamp, (ReferencePoint(float(k), x, v, 0.0),))
        writer.write('/train/state', stamp, serialize_message(state_to_msg(state)))
        writer.write('/ato/reference', stamp, serialize_message(reference_to_msg(reference)))
        writer.write('/ato/command', stamp, serialize_message(command_to_msg(
            Command(stamp, ('car_1',), (1000.0,), 'pid'))))
    writer.close()
    return tmp_path / 'run', scenario_file, length


def test_the_journey_windows_the_run_missed_are_reported(tmp_path, capsys):
    """With the scenario (checked against the plant's recorded identity), the report lists the
    timing points the run passed outside their windows."""
    bag, scenario_file, length = journey_run(tmp_path, [(0, 5), (None, 10), (None, None)])
    assert main([str(bag), '--scenario', str(scenario_file), '--output',
                 str(tmp_path / 'plots')]) == 0
    out = capsys.readouterr().out
    passing = math.ceil(length / 2 / 20.0)
    assert f'missed time windows   1, first at {passing:.1f} s' in out
    assert f'passing at {passing:.1f} s, outside [-, 10] s' in out
    assert 'missed time windows' in (tmp_path / 'plots' / 'report.html').read_text()


def test_a_scenario_that_is_not_the_recorded_plant_s_is_refused_and_none_is_not_checked(
        tmp_path, capsys):
    bag, scenario_file, _ = journey_run(tmp_path, [(0, 5), (None, 10), (None, None)],
                                        identity_of='short_line')
    assert main([str(bag), '--scenario', str(scenario_file)]) == 2
    err = capsys.readouterr().err
    assert 'the plant simulates scenario short_line' in err
    assert 'the report was given journey' in err
    # the plant's built-in scenario is found by its name (short_line has no journey)
    assert main([str(bag), '--output', str(tmp_path / 'plots')]) == 0
    assert 'missed time windows' not in capsys.readouterr().out
    # a scenario from a file, not given: the windows are not checked, and the report says so
    bag, _, _ = journey_run(tmp_path / 'file', [(0, 5), (None, 10), (None, None)])
    assert main([str(bag), '--output', str(tmp_path / 'plots2')]) == 0
    assert 'missed time windows   not checked (the scenario is unknown: --scenario)' in \
        capsys.readouterr().out


STOPPING_LINE = '''name: stopping_line
description: 90 m, a halt at 50 m
source: test
train:
  preset: crh3_luo_xu
line:
  name: stopping_line
  length_m: 100
  stations:
    - {name: Origin, position_m: 0, dwell_s: 0}
    - {name: Halt, position_m: 50, dwell_s: 3}
    - {name: End, position_m: 90, dwell_s: 0}
  speed_limits:
    - {start_m: 0, speed_kmh: 100}
  gradients:
    - {start_m: 0, per_mille: 0}
planning:
  max_acceleration_mps2: 0.4
  service_deceleration_mps2: 0.5
  max_jerk_mps3: 0.1
run:
  controller_rate_hz: 1
  settle_time_s: 1
'''
#: position of the target (and of a train that follows it exactly) each second: 10 m/s from
#: Origin, 3 s at Halt (5 to 8 s), on to End (12 s), standing there
STOPPING_POSITIONS = (0, 10, 20, 30, 40, 50, 50, 50, 50, 60, 70, 80, 90, 90, 90)


def stopping_run(tmp_path, lag_m: float = 0.0):
    """A recording of ``STOPPING_LINE`` (identity, target curve, a train ``lag_m`` behind),
    with the provenance run_scenario's recorder writes."""
    from std_msgs.msg import String

    from ato_common.identity import scenario_identity
    from ato_common.scenario import load_scenario
    scenario = tmp_path / 'stopping.yaml'
    scenario.write_text(STOPPING_LINE)
    writer = BagWriter(tmp_path / 'run', custom_data={
        'log_time': 'stamp', 'recorded_utc': '2026-12-03 12:00 UTC',
        'suite_commit': 'abc123def456'})
    for key in ('state', 'reference', 'command', 'curve', 'identity'):
        writer.add_topic('/' + TOPICS[key].name, TOPICS[key].type_name)
    writer.write('/train/identity', 0, serialize_message(String(
        data=scenario_identity(load_scenario(str(scenario))))))
    speeds = [10.0 if b > a else 0.0 for a, b in zip(STOPPING_POSITIONS,
                                                      STOPPING_POSITIONS[1:])] + [0.0]
    curve = Reference(0, tuple(ReferencePoint(float(k), x, v, 0.0) for k, (x, v) in
                               enumerate(zip(STOPPING_POSITIONS, speeds))))
    writer.write('/ato/reference/curve', 0, serialize_message(reference_to_msg(curve)))
    for k, (x, v) in enumerate(zip(STOPPING_POSITIONS, speeds)):
        stamp = k * 1_000_000_000
        state = TrainState(stamp, ('car_1',), (x - lag_m,), (v,), (0.0,), (1000.0 * v,))
        reference = Reference(stamp, (ReferencePoint(float(k), x, v, 0.0),))
        writer.write('/train/state', stamp, serialize_message(state_to_msg(state)))
        writer.write('/ato/reference', stamp, serialize_message(reference_to_msg(reference)))
        writer.write('/ato/command', stamp, serialize_message(command_to_msg(
            Command(stamp, ('car_1',), (1000.0 * v,), 'pid'))))
    writer.close()
    return tmp_path / 'run', scenario


def test_the_report_tells_the_journey(tmp_path, capsys):
    """Issue 31, defect 6: the scenario and the train by name, each station by name with its
    planned and actual arrival, departure and dwell and its stopping error, the energy, and
    where the run comes from; the same in report.html."""
    bag, scenario = stopping_run(tmp_path, lag_m=0.25)
    assert main([str(bag), '--scenario', str(scenario), '--output', str(tmp_path / 'out')]) == 0
    from recorder.report import build_report, stop_rows
    report = build_report(bag, scenario=str(scenario))
    late = replace(report.data, speeds=report.data.speeds.copy())
    late.speeds[5] = 0.5  # still rolling at 5 s: it arrives at 6 s
    assert stop_rows(late, report.metrics)[0][3] == '6.0'
    out = capsys.readouterr().out
    assert 'scenario              stopping_line\n' in out
    assert 'train                 crh3_luo_xu' in out
    assert f'recording             {bag}\n' in out
    assert 'recorded at           2026-12-03 12:00 UTC' in out
    assert 'suite commit of the run abc123def456' in out
    assert 'report made at' in out
    # the target and the train 0.25 m behind it stand still at Halt from 5 s to 7 s (at 8 s
    # they have the speed they leave with), at End from 12 s to the end of the run
    assert ('station Halt at 50.0 m: arrival 5.0 s (planned 5.0), departure 7.0 s (planned '
            '7.0), dwell 2.0 s (planned 2.0), stopping error -0.250 m') in out
    assert ('station End at 90.0 m: arrival 12.0 s (planned 12.0), departure - s (planned -), '
            'dwell - s (planned -)') in out
    assert 'stop at' not in out  # stations by name
    assert 'traction energy' in out
    assert 'stop errors beyond 0.5 m 0\n' in out  # the label and its value apart
    page = (tmp_path / 'out' / 'report.html').read_text()
    for text in ('id="journey"', 'stopping_line', 'crh3_luo_xu', 'id="stations"', 'Halt',
                 'abc123def456', 'traction energy, gross (kWh)', 'id="windows"'):
        assert text in page, text


def test_the_energies_the_metrics_have_are_shown():
    from dataclasses import dataclass

    from ato_common.metrics import RunMetrics
    from recorder.report import energy_rows
    metrics = RunMetrics(samples=2, simulated_time_s=1.0, rms_speed_error_kmh=0.0,
                         max_speed_error_kmh=0.0, rms_position_error_m=0.0,
                         max_position_error_m=0.0, stop_errors_m={}, traction_energy_kwh=3.0)
    # ato_common.metrics gives all four (net = gross - regenerated where not given)
    assert energy_rows(metrics) == [('traction energy, gross (kWh)', '3.00'),
                                    ('braking energy (kWh)', '0.00'),
                                    ('regenerated energy (kWh)', '0.00'),
                                    ('net energy (kWh)', '3.00')]

    @dataclass(frozen=True)
    class Fuller(RunMetrics):  # as ato_common.metrics gives them, once it does
        braking_energy_kwh: float = 1.5
        regenerated_energy_kwh: float = 0.5
        net_energy_kwh: float = 2.5
    fuller = Fuller(**metrics.__dict__)
    assert [label for label, _ in energy_rows(fuller)] == [
        'traction energy, gross (kWh)', 'braking energy (kWh)', 'regenerated energy (kWh)',
        'net energy (kWh)']


def test_the_timetable_windows_are_listed_met_or_missed(tmp_path, capsys):
    bag, scenario_file, length = journey_run(tmp_path, [(0, 5), (None, 10), (None, None)])
    assert main([str(bag), '--scenario', str(scenario_file), '--output',
                 str(tmp_path / 'plots')]) == 0
    out = capsys.readouterr().out
    passing = math.ceil(length / 2 / 20.0)
    assert 'timing point 0 at 0.0 m: departure at 0.0 s, window [0.0, 5.0] s: met' in out
    assert (f'timing point 1 at {length / 2:.1f} m: passing at {passing:.1f} s, window '
            '[-, 10.0] s: missed') in out
    page = (tmp_path / 'plots' / 'report.html').read_text()
    assert page.count('<td>met</td>') == 2 and page.count('<td>missed</td>') == 1


def test_the_tracking_legend_covers_no_curve(tmp_path):
    """The legends of the tracking plot sit beside its axes: none covers the start of a
    curve (nor any other part of the plotting area)."""
    from recorder.report import build_report
    from recorder.report_plots import tracking_figure
    bag, scenario = stopping_run(tmp_path)
    fig = tracking_figure(build_report(bag, scenario=str(scenario)).data)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for axis in fig.axes:
        legend = axis.get_legend().get_window_extent(renderer)
        area = axis.get_window_extent(renderer)
        assert not legend.overlaps(area), (legend, area)
        for line in axis.get_lines()[:3]:
            start = axis.transData.transform(line.get_xydata()[:3])
            assert not any(legend.contains(x, y) for x, y in start)
