"""ato: the suite's command line where there is no ``ros2`` (the PyPI wheels), with the
arguments of the ``ros2`` commands the documentation shows.

    ato run <package> <executable> [args...]        # as ros2 run: <prefix>/lib/<package>/<exe>
    ato launch ato_bringup ato.launch.py [name:=value ...]   # the launch file's stack
    ato param list|get|set <node> [name] [value]    # the node's parameter services
    ato topic list [-t] | echo <topic> [--once]
    ato node list [-a]
    ato conformance --controller-command CMD        # checks an ATO node against the contract
    ato scorecard --controller-command CMD --campaign FILE  # the node through a campaign

``. scripts/env.sh`` puts it on PATH (``scripts/bin/ato``). With a full ROS 2 install ``ros2``
does the same (``ato conformance`` and ``ato scorecard`` have no ros2 counterpart: ``ros2 run
ato_bringup conformance``, ``ros2 run ato_bringup scorecard``).
"""

from __future__ import annotations

import sys

from ato_ros.interrupts import quiet_until_running

COMMANDS = ('run', 'launch', 'param', 'topic', 'node', 'conformance', 'scorecard')


def run(argv: list[str]) -> int:
    """``ato run [--prefix PREFIX] <package> <executable> [args...]``: replaces this process
    with the executable, as ``ros2 run`` runs it."""
    import argparse
    import os
    import shlex

    from ato_bringup.processes import NoExecutable, executable_path
    parser = argparse.ArgumentParser(prog='ato run', description='run an executable of a '
                                     'package, found as ros2 run finds it')
    parser.add_argument('--prefix', default='', help='prefix command, e.g. "gdb -ex run --args"')
    parser.add_argument('package')
    parser.add_argument('executable')
    parser.add_argument('argv', nargs=argparse.REMAINDER, help='its arguments')
    args = parser.parse_args(argv)
    try:
        path = executable_path(args.package, args.executable)
    except NoExecutable as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    command = [*shlex.split(args.prefix), path, *args.argv]
    os.execvp(command[0], command)
    return 1  # pragma: no cover - execvp does not return


def main(argv: list[str] | None = None) -> int:
    # A Ctrl-C while importing, or while a graph command waits or echoes: exit 0 at once.
    quiet_until_running(say=False)
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ('-h', '--help') or argv[0] not in COMMANDS:
        print(__doc__.strip(), file=sys.stdout if argv else sys.stderr)
        if argv and argv[0] not in ('-h', '--help'):
            print(f'\nerror: unknown command {argv[0]!r}: one of {", ".join(COMMANDS)}',
                  file=sys.stderr)
        return 0 if argv and argv[0] in ('-h', '--help') else 2
    command, rest = argv[0], argv[1:]
    if command == 'run':
        return run(rest)
    if command == 'launch':
        from ato_bringup import launcher
        return launcher.main(rest)
    if command == 'conformance':
        from ato_bringup import conformance
        return conformance.main(rest)
    if command == 'scorecard':
        from ato_bringup import scorecard
        return scorecard.main(rest)
    from ato_bringup import graph_cli
    return graph_cli.main(command, rest)


if __name__ == '__main__':
    raise SystemExit(main())
