"""A DDS domain that no other run or test session on this machine holds: one exclusive lock
file per domain id in the temporary directory, held for as long as the run lasts.

The integration tests (``tests/conftest.py``) and ``run_scenario`` take their domain here, so
two of them started at the same moment never share one. The lock is released when its holder
ends (also when it is killed: the kernel drops an ``flock`` with the process).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import tempfile
from pathlib import Path
from typing import Iterator

# Fast DDS derives its ports from the domain id: 0..232 are usable; 0 is everybody's default.
FIRST_DOMAIN, LAST_DOMAIN = 1, 232
LOCK_PREFIX = 'ato-ros-domain-'


class NoFreeDomain(RuntimeError):
    """Every domain id is held by another run."""


def lock_path(domain_id: int, lock_dir: Path | None = None) -> Path:
    return Path(lock_dir or tempfile.gettempdir()) / f'{LOCK_PREFIX}{domain_id}.lock'


@contextlib.contextmanager
def free_domain(lock_dir: Path | None = None) -> Iterator[int]:
    """Hold a domain id nobody else holds, for the ``with`` block; the search starts at an
    offset of the process id, so concurrent callers rarely try the same ids first."""
    span = LAST_DOMAIN - FIRST_DOMAIN + 1
    start = os.getpid() % span
    for offset in range(span):
        candidate = FIRST_DOMAIN + (start + offset) % span
        handle = open(lock_path(candidate, lock_dir), 'w')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        try:
            yield candidate
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)
            handle.close()
        return
    raise NoFreeDomain(f'no free ROS domain id in {FIRST_DOMAIN}..{LAST_DOMAIN}: every one is '
                       f'locked by another run ({lock_path(FIRST_DOMAIN, lock_dir).parent}/'
                       f'{LOCK_PREFIX}*.lock)')
