"""How the suite's processes set up the middleware on one host (one place for the stack, the
launch file, the benchmark and the tests).

- ``FASTDDS_BUILTIN_TRANSPORTS=SHM``: Fast DDS over shared memory only, about 30 % faster per
  lockstep step than its default UDP plus shared memory on one host; such participants still
  talk to default ones.
- ``FASTRTPS_DEFAULT_PROFILES_FILE``: the suite's Fast DDS profile (``fastdds_profile.xml``
  beside this module): a reliable writer's heartbeat every 0.1 s instead of Fast DDS's 3 s. A
  reader acknowledges what it received on a heartbeat, so a node that waits for its last
  messages to be acknowledged before it exits (``ros.wait_until_delivered``) waited up to 3 s
  per writer; the plant of a lockstep run spent about 2.2 s of each run's teardown there.
  (Fast DDS 2.x, as in Jazzy, reads this variable; Fast DDS 3 reads
  ``FASTDDS_DEFAULT_PROFILES_FILE``.)

Both are defaults: a value the user has set is kept (their own transports or XML profile).
Other RMW implementations ignore both.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

FASTDDS_PROFILE = Path(__file__).with_name('fastdds_profile.xml')

DEFAULTS = {
    'FASTDDS_BUILTIN_TRANSPORTS': 'SHM',
    'FASTRTPS_DEFAULT_PROFILES_FILE': str(FASTDDS_PROFILE),
}


def middleware_defaults(env: Mapping[str, str]) -> dict[str, str]:
    """The variables of ``DEFAULTS`` that ``env`` does not set, with the suite's values."""
    return {name: value for name, value in DEFAULTS.items() if name not in env}


def with_middleware_defaults(env: Mapping[str, str]) -> dict[str, str]:
    """``env`` (a process environment) with the suite's middleware defaults where unset."""
    return {**env, **middleware_defaults(env)}
