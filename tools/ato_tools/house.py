"""Facts of the repository that the tooling and the house tests share: where it is and which
packages the suite has (the links in ``ros_ws/src``, which ``make setup`` builds)."""

from __future__ import annotations

from pathlib import Path

#: the repository root (this file is tools/ato_tools/house.py)
REPOSITORY = Path(__file__).resolve().parents[2]

#: the suite's ament packages, as colcon builds them (``scripts/setup.sh`` reads the same list)
PACKAGES = tuple(sorted(p.name for p in (REPOSITORY / 'ros_ws' / 'src').iterdir()
                        if p.is_symlink()))
