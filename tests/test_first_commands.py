"""The README's first commands, as written (issue 27): the block under the "first commands"
marker runs in bash at the repository's root, on the wheels (no ros2: the suite's ato)."""

import os
import re
import subprocess
from pathlib import Path

REPOSITORY = Path(__file__).resolve().parents[1]
MARKER = '<!-- first commands: run as written by tests/test_first_commands.py -->'


def first_commands() -> str:
    readme = (REPOSITORY / 'README.md').read_text()
    assert MARKER in readme, 'the README lost its first commands marker'
    block = re.match(r'\s*```[^\n]*\n(.*?)\n```', readme.split(MARKER, 1)[1], re.S)
    assert block, 'no code block under the first commands marker'
    return block.group(1)


def test_the_readme_s_first_commands_run_as_written(domain_id):
    commands = first_commands()
    assert commands.startswith('. scripts/env.sh') and 'ros2' not in commands
    # a fresh shell: only what a user's login shell has, plus an isolated DDS domain
    env = {key: os.environ[key] for key in ('HOME', 'PATH', 'LANG', 'TMPDIR')
           if key in os.environ}
    env.update(ROS_DOMAIN_ID=str(domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    env['PATH'] = ':'.join(p for p in env['PATH'].split(':')
                           if not p.startswith(str(REPOSITORY)) and '.venv' not in p)
    done = subprocess.run(['bash', '-c', commands], cwd=REPOSITORY, env=env,
                          capture_output=True, text=True, timeout=900)
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    assert 'Set parameter successful' in output
    assert 'Setting parameter failed: ' in output and 'bogus' in output
    assert 'law switched from luo_xu to pid' in output  # the swap happened while it ran
    assert 'train_plant_node ended (exit code 0): the run is over' in output
    assert 'Traceback' not in output
