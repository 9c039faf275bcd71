"""The conformance harness's main run starts the plant only once the harness hears the node's
commands: a publisher's messages sent before the harness's subscription is matched never reach
it, so on a loaded machine the harness counted steps the plant had seen answered as unanswered
(make test-stress: "1259 of 2001 steps answered; the first unanswered at 0.0 s")."""

from types import SimpleNamespace

from ato_bringup import conformance
from ato_bringup.conformance_cases import Schedule

MATCHED_AFTER = 3  # spins of the harness before the node's publisher is matched


class Process:
    def __init__(self, code):
        self.returncode = code

    def poll(self):
        return self.returncode

    def send_signal(self, signal):
        self.returncode = 0

    @property
    def pid(self):
        return 0


class FakeStack:
    """Just enough of ``ato_bringup.stack.Stack``: the graph matches the node's publisher of
    ato/command after ``matched_after`` spins (None: never); the plant ends at once."""

    matched_after: int | None = MATCHED_AFTER

    def __init__(self, config):
        self.events: list[str] = []
        self.spins = 0
        self.processes: dict[str, Process] = {}
        stack = self

        class Subscription:
            def __init__(self, name):
                self.name = name

            def get_publisher_count(self):
                after = stack.matched_after
                return int(self.name.endswith('command') and after is not None
                           and stack.spins >= after)

        self.node = SimpleNamespace(create_subscription=lambda _type, name, *a, **k:
                                    Subscription(name))
        self.executor = SimpleNamespace(spin_once=lambda timeout_sec=None: None)
        FakeStack.last = self

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def start(self, order=('controller', 'profile', 'plant')):
        for name in order:
            self.start_process(name, {})

    def start_process(self, name, params, *args, **kwargs):
        self.events.append(f'{name} (spin {self.spins})')
        self.processes[name] = Process(0 if name == 'plant' else None)

    def node_params(self):
        return {'plant': {}}

    def spin_until(self, predicate, timeout_s):
        for _ in range(100):
            if predicate():
                return True
            self.spins += 1
        return False

    def spin_for(self, seconds):
        self.spins += 1


def test_the_plant_starts_once_the_harness_hears_the_node(monkeypatch, tmp_path):
    monkeypatch.setattr(conformance, 'Stack', FakeStack)
    args = SimpleNamespace(log_dir=tmp_path, controller_command='my_ato')
    conformance.main_run(args, 'short_line', Schedule(20.0), 0)
    events = FakeStack.last.events
    assert events[:2] == ['controller (spin 0)', 'profile (spin 0)'], events
    assert events[2] == f'plant (spin {MATCHED_AFTER})', events


def test_a_node_never_heard_is_named_and_the_run_starts_all_the_same(monkeypatch, tmp_path,
                                                                      capsys):
    """A node that creates its publisher late (or never) is not waited for without end: the
    harness says so and starts the plant after ``MATCH_S``."""
    monkeypatch.setattr(conformance, 'Stack', FakeStack)
    monkeypatch.setattr(FakeStack, 'matched_after', None)
    args = SimpleNamespace(log_dir=tmp_path, controller_command='my_ato')
    conformance.main_run(args, 'short_line', Schedule(20.0), 0)
    assert [event.split()[0] for event in FakeStack.last.events[:3]] == [
        'controller', 'profile', 'plant']
    assert 'no publisher of ato/command matched within 60 s' in capsys.readouterr().err
