"""Command line: a scenario YAML running a TTOBench track with a TTOBench train.

    python -m ato_common.scenario_from_ttobench TRACK TRAIN [--journey J] [--dwell S] > s.yaml
    ros2 run ato_common scenario_from_ttobench TRACK TRAIN ...

The mapping is :func:`ato_common.ttobench.scenario_data`; the result is checked by
:func:`ato_common.scenario.parse_scenario` before it is printed. The tool sits apart from the
TTOBench reader because it needs the scenario parser, which itself reads TTOBench files.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import yaml

from ato_common.scenario import parse_scenario
from ato_common.ttobench import scenario_data
from ato_common.validation import ConfigError


def main(argv=None) -> int:
    """Print a scenario YAML running TRACK with TRAIN (save it, edit the planning limits, run it
    with SCENARIO=file)."""
    parser = argparse.ArgumentParser(prog='scenario_from_ttobench', description=main.__doc__)
    parser.add_argument('track')
    parser.add_argument('train')
    parser.add_argument('--journey')
    parser.add_argument('--dwell', type=float, default=30.0, help='dwell at intermediate stops, s')
    args = parser.parse_args(argv)
    try:
        data = scenario_data(Path(args.track).resolve(), Path(args.train).resolve(),
                             Path(args.journey).resolve() if args.journey else None, args.dwell)
        parse_scenario(data)  # every file valid before anything is written
    except ConfigError as error:
        print(f'error: {error}', file=sys.stderr)
        return 2
    yaml.safe_dump(data, sys.stdout, sort_keys=False)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
