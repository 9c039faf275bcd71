"""run_node runs only nodes that declare the hooks it calls (RunNodeHooks), and reads them."""

import signal

import pytest
from rclpy.node import Node

from ato_ros.lifecycle import RunNodeHooks, cancel_teardown_watch, run_node, run_nodes


@pytest.fixture(autouse=True)
def restore_the_process():
    """run_node installs its own SIGINT/SIGTERM handlers and ignores both once it tears down,
    and its teardown starts a watchdog that ends the process (watch_teardown: a node's process
    exits right after): both are undone here, or pytest itself would be ended."""
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    cancel_teardown_watch()
    for s, handler in saved.items():
        signal.signal(s, handler)


class UndeclaredNode(Node):
    """Has every attribute run_node reads, but does not declare them."""

    finished = True
    exit_code = 0

    def __init__(self):
        super().__init__('undeclared_node')

    def close_outputs(self) -> None:
        pass


class DoneNode(RunNodeHooks, Node):
    """Finished at once, with an output to close and a non-zero exit status."""

    def __init__(self):
        super().__init__('done_node')
        self.finished = True
        self.exit_code = 3
        self.closed = 0

    def close_outputs(self) -> None:
        self.closed += 1


def test_the_hooks_have_documented_defaults():
    hooks = RunNodeHooks()
    assert hooks.finished is False and hooks.exit_code == 0 and hooks.close_outputs() is None


def test_a_node_that_does_not_declare_the_hooks_is_refused_naming_its_class():
    with pytest.raises(TypeError, match=r'test_run_node\.UndeclaredNode does not declare the '
                                        r'hooks run_node calls.*RunNodeHooks'):
        run_node(UndeclaredNode, args=[])


def test_an_object_that_is_no_node_is_refused_naming_its_class():
    with pytest.raises(TypeError, match=r'builtins\.object does not declare'):
        run_node(object, args=[])


def test_a_declared_node_closes_its_outputs_and_gives_its_exit_code():
    made = []

    def make():
        made.append(DoneNode())
        return made[0]
    assert run_node(make, args=[]) == 3
    assert made[0].closed == 1


class RunningNode(RunNodeHooks, Node):
    """Not finished by itself, exit code 0, counts its closes."""

    def __init__(self, name='running_node'):
        super().__init__(name)
        self.closed = 0

    def close_outputs(self) -> None:
        self.closed += 1


def test_several_nodes_in_one_process_stop_when_one_is_finished_and_each_closes():
    """run_nodes (the composed stack): one node finished ends the spin for all; each closes its
    outputs once; the exit code is the first non-zero one."""
    made = []

    def maker(cls):
        def make():
            made.append(cls())
            return made[-1]
        return make
    assert run_nodes((maker(RunningNode), maker(DoneNode)), args=[]) == 3
    assert [type(n).__name__ for n in made] == ['RunningNode', 'DoneNode']
    assert [n.closed for n in made] == [1, 1]


def test_several_nodes_refuse_one_that_does_not_declare_the_hooks():
    with pytest.raises(TypeError, match=r'test_run_node\.UndeclaredNode does not declare'):
        run_nodes((RunningNode, UndeclaredNode), args=[])
