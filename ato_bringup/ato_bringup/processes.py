"""The suite's executables as processes: where ``ros2 run`` finds them and how an exit reads.

No rclpy: the launchers (``ato run``, ``ato launch``) use this before anything heavy is
imported.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path


class NoExecutable(FileNotFoundError):
    """A package or an executable of it that the ament index does not give."""


def executable_path(package: str, executable: str) -> str:
    """``<prefix>/lib/<package>/<executable>`` of the package's ament prefix, as ``ros2 run``
    finds it; NoExecutable naming what is missing."""
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix
    try:
        prefix = get_package_prefix(package)
    except (PackageNotFoundError, ValueError):
        raise NoExecutable(f"package '{package}' not found in the ament index "
                           '(AMENT_PREFIX_PATH): build ros_ws first (make setup) and source '
                           'scripts/env.sh') from None
    path = Path(prefix) / 'lib' / package / executable
    if not os.access(path, os.X_OK):
        found = sorted(p.name for p in (Path(prefix) / 'lib' / package).glob('*')
                       if os.access(p, os.X_OK) and p.is_file())
        raise NoExecutable(f'{path} is not an executable of {package} (its executables: '
                           f'{", ".join(found) or "none"}): build ros_ws first (make setup)')
    return str(path)


def describe_exit(code: int) -> str:
    """``code 2``, ``code -9 (killed by SIGKILL)``: an exit status as Popen gives it."""
    if code < 0:
        try:
            return f'code {code} (killed by {signal.Signals(-code).name})'
        except ValueError:
            return f'code {code} (killed by signal {-code})'
    return f'code {code}'
