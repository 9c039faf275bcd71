"""The command line that works here, for the tools' own messages.

With a full ROS 2 install the ``ros2`` command runs the suite's executables (``ros2 run``,
``ros2 launch``, ``ros2 param``...). With the PyPI wheels there is no ``ros2``: the suite's own
launcher ``ato`` (``scripts/bin/ato``, on PATH after ``. scripts/env.sh``) takes the same
arguments. A message that tells the user what to type names the one that is on PATH.
"""

from __future__ import annotations

import shutil


def ros_cli() -> str:
    """``ros2`` where it is on PATH, else the suite's ``ato``."""
    return 'ros2' if shutil.which('ros2') else 'ato'


def ros_command(arguments: str) -> str:
    """``ros2 <arguments>`` or ``ato <arguments>`` (:func:`ros_cli`), e.g.
    ``ros_command('run recorder recover runs/x/bag')``."""
    return f'{ros_cli()} {arguments}'
