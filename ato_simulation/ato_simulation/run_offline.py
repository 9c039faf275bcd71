"""run_offline: one closed-loop run of a scenario (a built-in name or a YAML file) on the cores,
without ROS (ato_simulation.loop), with the summary of run_scenario: errors, stopping errors,
energy, and what went wrong (ATP interventions, missed journey windows, stopping errors beyond
the platform tolerance, each with its count and first occurrence).

    ros2 run ato_bringup run_offline --scenario my_line.yaml --controller pid
    python -m ato_simulation.run_offline --scenario short_line

Exit code: 0 for a clean run (or any completed run with --no-fail-on-events), 3 for a run with
such events, 1 for a run that fails, 2 for bad input (the scenario, a law that cannot drive its
train). An offline run has no command watchdog (its controller answers every period).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

from ato_common.knowledge import knowledge_of
from ato_common.metrics import format_summary
from ato_common.run_events import PLATFORM_TOLERANCE_M, final_exit_code, run_events, stations_of
from ato_common.scenario import DEFAULT_SCENARIO, builtin_scenarios, load_scenario
from ato_common.validation import ConfigError
from ato_controller_node.laws import LAWS
from ato_simulation.loop import run_offline
from train_plant_node.models import MODELS

DEFAULT_LAW = 'pid'


def parse_args(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--scenario', default=DEFAULT_SCENARIO,
                        help=f"built-in ({', '.join(builtin_scenarios())}) or a YAML file")
    parser.add_argument('--controller', default=DEFAULT_LAW, choices=sorted(LAWS),
                        help=f'the law (default {DEFAULT_LAW})')
    parser.add_argument('--model', default='point_mass', choices=sorted(MODELS),
                        help='the plant model (default point_mass)')
    parser.add_argument('--no-fail-on-events', action='store_true',
                        help='exit with 0 even if the run had ATP interventions, missed journey '
                             'windows or stopping errors beyond the tolerance (default: 3)')
    parser.add_argument('--stop-tolerance', type=float, default=PLATFORM_TOLERANCE_M,
                        metavar='M', help='the platform tolerance of a stopping error, m '
                                          f'(default {PLATFORM_TOLERANCE_M:g})')
    parser.add_argument('--json', type=Path, default=None, metavar='FILE',
                        help='also write the metrics and the events to FILE as JSON')
    args = parser.parse_args(argv)
    if not (args.stop_tolerance >= 0.0 and math.isfinite(args.stop_tolerance)):
        parser.error(f'--stop-tolerance: must be a finite number >= 0 m, got '
                     f'{args.stop_tolerance}')
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    try:
        scenario = load_scenario(args.scenario)
        knowledge = knowledge_of(scenario)
        reason = LAWS[args.controller](knowledge, 1.0 / scenario.run.controller_rate_hz
                                       ).fits(knowledge)
        if reason:
            raise ConfigError(f'{args.controller} cannot drive {scenario.name}: {reason}')
        print(f'running {args.scenario} with {args.controller} offline (no ROS), plant '
              f'{args.model}', file=sys.stderr)
        started = time.monotonic()
        run = run_offline(scenario, args.controller, model=args.model)
        wall = time.monotonic() - started
    except ConfigError as error:  # a scenario, a train file, a plan that cannot be made
        print(f'error: {error}', file=sys.stderr)
        return 2
    except (ValueError, RuntimeError) as error:
        print(f'error: the run failed: {type(error).__name__}: {error}', file=sys.stderr)
        return 1
    metrics = run.metrics()
    events = run_events(scenario, metrics, stations_of(run.plan), run.times_s, run.positions,
                        atp_times_s=run.atp_times_s, tolerance_m=args.stop_tolerance)
    print(format_summary(metrics, scenario.name, ', '.join(sorted(set(run.laws))), wall))
    print(events.format())
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({
            'scenario': scenario.name, 'controller': args.controller, 'model': args.model,
            'metrics': dataclasses.asdict(metrics), 'clean': events.clean, 'counts': events.counts,
            'events': [{'kind': e.kind, 'time_s': None if math.isnan(e.time_s) else e.time_s,
                        'detail': e.detail} for e in events.events]}, indent=1))
    return final_exit_code(events, not args.no_fail_on_events)


if __name__ == '__main__':
    raise SystemExit(main())
