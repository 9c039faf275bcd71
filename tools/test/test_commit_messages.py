"""Every commit since the rule came in (CONTRIBUTING.md) has a subject of at most 72 characters,
a blank line, and a body that says why."""

import subprocess

import pytest

from ato_tools.house import REPOSITORY

#: the first commit made under the rule; the history before it is left as it was
RULE_SINCE = '673a711'
SUBJECT_LIMIT = 72


def _git(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(['git', '-C', str(REPOSITORY), *args], capture_output=True, text=True,
                          check=False)


def message_problems(message: str) -> list[str]:
    """What is wrong with one commit message ([] if nothing)."""
    lines = message.rstrip('\n').split('\n')
    problems = []
    if len(lines[0]) > SUBJECT_LIMIT:
        problems.append(f'subject of {len(lines[0])} characters (at most {SUBJECT_LIMIT})')
    if len(lines) < 3 or lines[1].strip() or not any(line.strip() for line in lines[2:]):
        problems.append('no body after a blank line (the body says why)')
    return problems


def test_the_check_finds_a_long_subject_and_a_missing_body():
    assert message_problems('Fix the plant\n\nThe watchdog braked late.\n') == []
    assert message_problems('x' * 73 + '\n\nWhy.\n') == ['subject of 73 characters (at most 72)']
    assert message_problems('Fix the plant\n') == ['no body after a blank line (the body says why)']
    assert message_problems('Fix the plant\nWhy, without a blank line\n') == [
        'no body after a blank line (the body says why)']


def test_every_commit_since_the_rule_has_a_short_subject_and_a_body():
    if _git('cat-file', '-e', f'{RULE_SINCE}^{{commit}}').returncode != 0:
        shallow = _git('rev-parse', '--is-shallow-repository').stdout.strip() == 'true'
        if shallow:
            pytest.skip(f'a shallow clone without {RULE_SINCE}: no history to check')
        pytest.fail(f'{RULE_SINCE} (the commit the rule starts from) is not in the history')
    listed = _git('log', '--format=%h%x00%B%x01', f'{RULE_SINCE}^..HEAD')
    assert listed.returncode == 0, listed.stderr
    bad = []
    for entry in filter(str.strip, listed.stdout.split('\x01')):
        commit, message = entry.strip('\n').split('\x00', 1)
        bad += [f'{commit} {message.splitlines()[0][:60]!r}: {p}'
                for p in message_problems(message)]
    assert not bad, 'commit messages that break the rule:\n' + '\n'.join(bad)
