"""``ato launch ato_bringup ato.launch.py [name:=value ...]``: the launch file's stack without the
``launch`` package (the PyPI wheels have none).

The arguments, the nodes and their parameters come from ``ato_bringup.launch_arguments``, which
the launch file reads too; the nodes are watched as the launch file's handlers watch them: a
node that ends with 0 (the plant at ``end_time_s``) ends the launch with 0, one that fails ends
it with 1 naming the node and its exit; Ctrl-C (SIGINT, SIGTERM or SIGHUP to ``ato launch``)
stops every node and ends with 0. Arguments that cannot make a run end it with 2 before any node
starts (``ros2 launch`` can only exit with 1 then). Each node's output is printed with its name
in front, as launch's ``output='screen'`` does.

Stopping: one node at a time (the order they were started in), SIGINT, then SIGTERM after
``SIGTERM_TIMEOUT_S`` and SIGKILL after as long again, as launch escalates; one at a time because
Fast DDS 2.14 can deadlock deleting a participant while discovery reports a peer leaving (see
``ato_bringup.stack.Stack.stop``). The nodes run in sessions of their own, so a Ctrl-C in the
terminal reaches ``ato launch`` alone and the nodes are stopped in order; each node is also told
to end (SIGTERM) if ``ato launch`` itself dies.
"""

from __future__ import annotations

import ctypes
import os
import selectors
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ato_bringup.launch_arguments import (
    COMPOSED,
    NODES,
    LaunchRefused,
    StackLaunch,
    arguments,
    resolve,
)
from ato_bringup.processes import NoExecutable, describe_exit, executable_path
from ato_ros.middleware import with_middleware_defaults

LAUNCH_FILE = ('ato_bringup', 'ato.launch.py')
#: launch's escalation: SIGINT, then SIGTERM after this long, then SIGKILL after as long again
SIGTERM_TIMEOUT_S = 5.0
#: wall time between stopping one node and the next (discovery settles)
SETTLE_S = 0.3
#: how long the output of stopped nodes is read to its end at the most, s
DRAIN_S = 2.0
PR_SET_PDEATHSIG = 1


def log(message: str) -> None:
    print(f'[ato launch] {message}', file=sys.stderr, flush=True)


def _die_with_parent() -> None:  # pragma: no cover - runs in the child before exec
    """In the child: SIGTERM when ``ato launch`` dies (Linux), so no node is left running."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


@dataclass
class Child:
    """A node's process and the part of its output line not yet printed."""

    name: str
    process: subprocess.Popen
    pending: bytes = b''

    def print_lines(self, data: bytes, final: bool = False) -> None:
        """Print each whole line of the output, with the node's name in front; ``final``: the
        output has ended, print what is left too."""
        lines = (self.pending + data).split(b'\n')
        self.pending = lines.pop()  # the line not ended yet ('' after a newline)
        if final and self.pending:
            lines.append(self.pending)
            self.pending = b''
        out = sys.stdout.buffer
        for line in lines:
            out.write(f'[{self.name}] '.encode() + line + b'\n')
        out.flush()


@dataclass
class Launch:
    """The running stack: its processes, their output, the stop request."""

    children: list[Child] = field(default_factory=list)
    selector: selectors.BaseSelector = field(default_factory=selectors.DefaultSelector)
    stop_signal: str = ''

    def on_signal(self, signum, frame) -> None:
        name = signal.Signals(signum).name
        if self.stop_signal:
            log(f'{name} again: the nodes are being stopped already')
        else:
            self.stop_signal = name

    def start(self, name: str, command: list[str], env: dict[str, str]) -> None:
        process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                   stdin=subprocess.DEVNULL, env=env, start_new_session=True,
                                   preexec_fn=_die_with_parent)
        child = Child(name, process)
        assert process.stdout is not None  # stdout=PIPE
        os.set_blocking(process.stdout.fileno(), False)
        self.selector.register(process.stdout, selectors.EVENT_READ, child)
        self.children.append(child)
        log(f'{name}: started with pid {process.pid}')

    def pump(self, timeout_s: float) -> None:
        """Print what the nodes wrote, waiting up to ``timeout_s`` for it."""
        for key, _ in self.selector.select(timeout_s):
            child = key.data
            try:
                data = os.read(key.fd, 65536)
            except BlockingIOError:
                continue
            if data:
                child.print_lines(data)
            else:
                self.selector.unregister(key.fileobj)
                child.print_lines(b'', final=True)

    def ended(self) -> Child | None:
        return next((c for c in self.children if c.process.poll() is not None), None)

    def wait(self, child: Child, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while child.process.poll() is None:
            if time.monotonic() > deadline:
                return False
            self.pump(0.05)
        return True

    def stop(self, child: Child) -> None:
        """SIGINT, then SIGTERM, then SIGKILL, as launch escalates (each logged)."""
        escalation = ((signal.SIGINT, SIGTERM_TIMEOUT_S), (signal.SIGTERM, SIGTERM_TIMEOUT_S),
                      (signal.SIGKILL, SIGTERM_TIMEOUT_S))
        previous = None
        for sent, timeout_s in escalation:
            if child.process.poll() is not None:
                return
            if previous is not None:
                log(f'error: {child.name} did not end {timeout_s:g} s after {previous.name}: '
                    f'sending {sent.name}')
            child.process.send_signal(sent)
            previous = sent
            if self.wait(child, timeout_s):
                return

    def stop_all(self) -> None:
        for child in self.children:
            if child.process.poll() is None:
                self.pump(SETTLE_S)
                self.stop(child)
                code = child.process.returncode
                if code not in (0, None):
                    log(f'{child.name} exited with {describe_exit(code)} while stopping')
        # what they wrote last (bounded: a process of theirs could hold the pipe open)
        deadline = time.monotonic() + DRAIN_S
        while self.selector.get_map() and time.monotonic() < deadline:
            self.pump(0.1)

    def watch(self) -> int:
        """Until a node ends or a stop is asked for: the launch's exit code (0 or 1)."""
        while True:
            self.pump(0.1)
            if self.stop_signal:
                log(f'{self.stop_signal}: stopping the stack')
                return 0
            child = self.ended()
            if child is not None:
                code = child.process.returncode
                if code == 0:
                    log(f'{child.name} ended (exit code 0): the run is over, stopping the '
                        'stack')
                    return 0
                log(f'error: {child.name} exited with {describe_exit(code)}: the run has '
                    'failed, stopping the stack (its output above says why)')
                return 1


def node_commands(stack: StackLaunch, parameters_file: Path) -> list[tuple[str, list[str]]]:
    """(name, command line) of each process, as launch_ros would start it."""
    ros_args = ['-r', f'__ns:={stack.namespace}', '--params-file', str(parameters_file)]
    for source, target in stack.remappings():
        ros_args += ['-r', f'{source}:={target}']
    if stack.composed:
        package, executable = COMPOSED
        return [(executable, [executable_path(package, executable), '--ros-args', *ros_args])]
    return [(name, [executable_path(name, name), '--ros-args', '-r', f'__node:={name}',
                    *ros_args]) for name in NODES]


def show_arguments() -> str:
    lines = ["Arguments (pass arguments as '<name>:=<value>'):", '']
    for a in arguments():
        choices = f" Valid choices are: {list(a.choices)}" if a.choices else ''
        lines += [f"    '{a.name}':", f'        {a.description}.{choices}',
                  f"        (default: '{a.default}')", '']
    return '\n'.join(lines)


USAGE = ('usage: ato launch ato_bringup ato.launch.py [name:=value ...] [-s | --show-args]\n\n'
         "The suite's launch file without the launch package: the same arguments, nodes and "
         'parameters (ato_bringup.launch_arguments).')


def parse(argv: list[str]) -> tuple[dict[str, str], bool] | str:
    """(argument values, show the arguments) of a command line, or what is wrong with it."""
    words = [w for w in argv if w not in ('-s', '--show-args')]
    show = len(words) != len(argv)
    if len(words) < 2 or tuple(words[:2]) != LAUNCH_FILE:
        return ('ato launch runs the suite\'s launch file only: ato launch ato_bringup '
                'ato.launch.py [name:=value ...] (the launch package is not installed here; '
                'with a full ROS 2 install, ros2 launch runs any launch file)')
    values, names = {}, {a.name for a in arguments()}
    for word in words[2:]:
        name, separator, value = word.partition(':=')
        if not separator:
            return f'{word!r}: arguments are given as name:=value'
        if name not in names:
            return f'{name!r} is not an argument of ato.launch.py: ' + ', '.join(sorted(names))
        values[name] = value
    return values, show


def main(argv: list[str]) -> int:
    if argv and argv[0] in ('-h', '--help'):
        print(USAGE)
        return 0
    parsed = parse(argv)
    if isinstance(parsed, str):
        print(f'error: {parsed}', file=sys.stderr)
        return 2
    values, show = parsed
    if show:
        print(show_arguments())
        return 0
    try:
        stack = resolve(values)
    except LaunchRefused as error:
        print(f'error: ato.launch.py: {error}', file=sys.stderr)
        return 2
    for note in stack.notes:
        log(note)
    return run(stack)


def run(stack: StackLaunch) -> int:
    """Start the stack's processes, watch them, stop them: the launch's exit code."""
    launch = Launch()
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, launch.on_signal)
    env = with_middleware_defaults({**os.environ, 'PYTHONUNBUFFERED': '1'})
    with tempfile.TemporaryDirectory(prefix='ato_launch_') as folder:
        parameters_file = Path(folder) / 'parameters.yaml'
        parameters_file.write_text(yaml.safe_dump(stack.parameter_sections()))
        try:
            for name, command in node_commands(stack, parameters_file):
                if launch.stop_signal:
                    break
                launch.start(name, command, env)
        except NoExecutable as error:
            log(f'error: {error}')
            launch.stop_all()
            return 1
        try:
            return launch.watch()
        finally:
            launch.stop_all()
