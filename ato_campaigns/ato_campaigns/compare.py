"""compare: every applicable control law on every built-in scenario, offline, side by side.

    python -m ato_campaigns.compare [--out runs/compare] [--jobs 2] [--scenario NAME|FILE ...]
                                  [--law NAME ...] [--gains published|tuned] [--timeout-s 1800]

The comparison is a campaign of one nominal draw (ato_campaigns.engine): the plant is
the controller's nominal model, on a Dask LocalCluster of ``--jobs`` workers; the robustness
of the laws under uncertainty is ``make campaign`` (docs/guide/campaigns.md). ``--scenario``
takes a built-in scenario's name or a scenario file (``make compare SCENARIO=my_line.yaml``).
Every law also runs on the nominal plant with the smallest actuator a campaign draws (the
default uncertainty's least lag and dead time of the traction and brake force, ACTUATOR_DRAW):
the row ``nominal with actuator`` shows what the actuator alone does to the law (a run over a
window, at a faster rate, runs on the nominal plant only).

``--gains`` is the configuration of every law's gains (ato_controller_node.gains, default
``published``: the paper's; ``tuned``: the tuned artefact for the scenario's train, a law without
one is listed as not run, with the reason). Beside each scenario's table the loop margins of
every law in that configuration (ato_campaigns.margins): the phase and delay margin on the
nominal plant (the controller's hold only), the stability with the ``nominal with actuator``
row's actuator and at the default uncertainty's largest actuator draw.

A law applies to a scenario when its ``fits`` accepts the scenario's train and plant and the
plant's sensors do not fail a measurement the law requires (a law without speed measurement
would only hold its last command; a law that estimates the speed does not require it). The plant
model is the scenario's, the same for every law on it: ``multi_car`` when the train has per-car
data (what the 4-car laws need; a single-mass law then sees the lead car), else ``point_mass``.
Each run is the offline closed loop (ato_simulation.loop), on one of ``--jobs`` single-threaded
Dask workers, stopped after ``--timeout-s`` of wall time, at the scenario's control rate; a law
whose sampled-time design refuses that rate (its ``fits`` names the period it needs) runs at the
first of FASTER_RATES_HZ it accepts, and if that makes more than MAX_STEPS steps, over the
scenario's first MAX_STEPS steps only (the table shows the rate and the window; such a run is
not ranked).
The result, ``<out>/compare.md``, has one table per scenario and the plots
``<out>/<scenario>_{tracking,errors,commands,estimates}.png``; ``<out>/compare.json`` holds the
same numbers and the ranking.

A run that raises, produces non-finite values, diverges, has the host hold its command or
exceeds the wall-time limit (status ``timeout``: a law that hangs must not block the comparison)
is listed with its status and reason, never dropped.

Columns (errors are reference minus truth of the lead car at each control instant):
- RMS / max speed error [km/h], RMS position error [m];
- stop error [m]: the largest |position - station| over the scenario's stops (ato_common.metrics);
- traction energy [kWh]: work of the traction force (ato_common.metrics);
- max jerk [m/s^3]: the largest change of the applied total force between control instants,
  divided by the train's mass and the control period, max |F[k+1] - F[k]| / (M dt): the jerk
  that the commands impose on the train (a passenger-comfort figure);
- step p99 [us]: 99th percentile of the host's step time (law, saturation, bumpless), measured
  while the runs share the cores, so it is an upper figure; ``make bench`` measures it alone.

Ranking (``best`` per scenario, and ``best_with_actuator`` on the other plant): among the
whole-scenario runs at the scenario's control rate with status ``ok`` (a clean run that finished
on time: ato_common.run_events) whose stop error is at most STOP_ERROR_LIMIT_M, the lowest RMS
speed error.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import traceback
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from ato_campaigns import margins as loop_margins
from ato_campaigns.engine import execute, finite, judged, motion
from ato_campaigns.provenance import results_page_provenance, write_results_page
from ato_campaigns.run_process import RunDied, RunFailed, RunTimeout, limited
from ato_common import uncertainty
from ato_common.scenario import builtin_scenarios, load_scenario
from ato_controller_node.gains import GAINS, GainsUnavailable, settings_for
from ato_controller_node.laws import LAWS
from ato_simulation.applies import applicable_rate, plant_model_for
from ato_simulation.plans import run_end_time_s
from profile_node.planner import plan_reference

#: the results page of the docs that `make compare` rewrites
DEFAULT_RESULTS_PAGE = Path('docs/results/comparison.md')
DEFAULT_OUT = Path('runs') / 'compare'
#: the ranking's stop accuracy constraint (m): the usual ATO platform-stop tolerance
STOP_ERROR_LIMIT_M = 0.5
#: points kept per curve for the plots
PLOT_POINTS = 3000


#: wall-time limit of one run by default, s: the slowest runs took about 870 s on 2 shared cores
DEFAULT_TIMEOUT_S = 1800.0
#: control steps at most in one run; a law that needs a fast rate on a long scenario runs the
#: scenario's first MAX_STEPS steps (the table says so)
MAX_STEPS = 1_500_000


#: the plants a law runs on: the controller's nominal model, and the same with the smallest
#: actuator of a campaign (ACTUATOR_DRAW)
NOMINAL, WITH_ACTUATOR = 'nominal', 'nominal with actuator'
PLANTS = (NOMINAL, WITH_ACTUATOR)
#: the draw of each plant: every uncertain parameter at its nominal value, and for the
#: actuator row the lag and the dead time at the least the default uncertainty draws
NOMINAL_DRAW = uncertainty.draw(uncertainty.NOMINAL, 0, 0)
ACTUATOR_PARAMETERS = ('actuator_time_constant_s', 'actuator_dead_time_s')
ACTUATOR_DRAW = dict(NOMINAL_DRAW, **{name: uncertainty.DEFAULTS[name].smallest
                                      for name in ACTUATOR_PARAMETERS})
DRAWS = {NOMINAL: NOMINAL_DRAW, WITH_ACTUATOR: ACTUATOR_DRAW}


@dataclass(frozen=True)
class Job:
    scenario: str
    law: str
    model: str
    rate_hz: float
    end_time_s: float | None = None  # None: the whole scenario
    plant: str = NOMINAL  # one of PLANTS
    gains: str = 'published'  # the laws' configuration (ato_controller_node.gains)


def plan_jobs(scenarios: list[str], laws: list[str] | None = None,
              plants: tuple[str, ...] = (NOMINAL,), gains: str = 'published'
              ) -> tuple[list[Job], list[dict]]:
    """The runs to make, and the (scenario, law) pairs that do not apply, with the reason
    (``laws``: only these; default every registered law). A law runs on each of ``plants``
    (the comparison: PLANTS), but over a window (a faster rate) on the nominal plant only, in
    the configuration ``gains``; a law without settings in it (no tuned artefact for the
    scenario's train) is not run, and the reason says so."""
    jobs, skipped = [], []
    for name in scenarios:
        scenario = load_scenario(name)
        model = plant_model_for(scenario)
        duration = run_end_time_s(scenario, plan_reference(scenario))
        for law in sorted(laws or LAWS):
            rate, reason = applicable_rate(law, scenario)
            if rate is not None:
                try:
                    settings_for(law, gains, scenario.train.name)
                except GainsUnavailable as error:
                    rate, reason = None, str(error)
            if rate is None:
                skipped.append({'scenario': name, 'law': law, 'reason': reason})
                continue
            end = MAX_STEPS / rate if duration * rate > MAX_STEPS else None
            jobs += [Job(name, law, model, rate, end, plant, gains)
                     for plant in (plants if end is None else (NOMINAL,))]
    return jobs, skipped


def actuator_text() -> str:
    """The actuator of the ``nominal with actuator`` row, for the tables."""
    return (f'first-order lag {ACTUATOR_DRAW["actuator_time_constant_s"]:g} s and dead time '
            f'{ACTUATOR_DRAW["actuator_dead_time_s"]:g} s of the traction and brake force')


def scenario_label(name: str) -> str:
    """A scenario as the tables, the plots' file names and the ranking name it: a built-in
    scenario by its name, a scenario file by its stem."""
    return name if name in builtin_scenarios() else Path(name).stem


def scenario_argument(text: str) -> str:
    """``--scenario``: a built-in scenario's name, or a scenario file (made absolute: the
    workers may run elsewhere in the tree)."""
    if text in builtin_scenarios():
        return text
    if Path(text).is_file():
        return str(Path(text).resolve())
    raise argparse.ArgumentTypeError(f"'{text}' is neither a built-in scenario "
                                     f"({', '.join(builtin_scenarios())}) nor a scenario file")


def _thin(values: np.ndarray, step: int) -> list:
    return np.asarray(values)[::step].tolist()


def job_fields(job: Job) -> dict:
    """What every result of ``job`` holds, whatever became of the run."""
    return {'scenario': job.scenario, 'law': job.law, 'model': job.model,
            'rate_hz': job.rate_hz, 'end_time_s': job.end_time_s, 'plant': job.plant,
            'gains': job.gains}


def run_job(job: Job) -> dict:
    """One offline run and its figures; never raises (a failure is the result's status)."""
    from ato_simulation.loop import run_offline
    result = dict(job_fields(job),
                  scenario_rate_hz=load_scenario(job.scenario).run.controller_rate_hz)
    started = time.perf_counter()
    try:
        scenario = load_scenario(job.scenario)
        run = run_offline(scenario, job.law, model=job.model, controller_rate_hz=job.rate_hz,
                          end_time_s=job.end_time_s, uncertainty=DRAWS[job.plant],
                          gains=job.gains)
    except Exception as error:  # noqa: BLE001 -- any failure of a law is a result to show
        result.update(status='error', reason=f'{type(error).__name__}: {error}',
                      detail=traceback.format_exc(limit=3), wall_s=time.perf_counter() - started)
        return result
    result['wall_s'] = time.perf_counter() - started
    result.update(figures(run, 1.0 / job.rate_hz))
    step = max(1, run.times_s.size // PLOT_POINTS)
    keys = sorted({k for e in run.estimates for k in e if 'hat' in k})
    result['curves'] = {
        'time_s': _thin(run.times_s, step), 'position_m': _thin(run.positions, step),
        'speed_mps': _thin(run.speeds, step), 'ref_speed_mps': _thin(run.ref_speeds, step),
        'ref_position_m': _thin(run.ref_positions, step), 'force_n': _thin(run.forces, step),
        'estimates': {k: _thin(run.estimate(k), step) for k in keys}}
    return result


def figures(run, dt: float) -> dict:
    """A run's figures in the comparison and its status and reason, judged as a campaign's
    (``ato_campaigns.engine.judged``: ``ok`` only for a clean run that finished on time)."""
    if not finite(run):
        return {'status': 'diverged', 'reason': 'non-finite state or force'}
    metrics = run.metrics()
    stop_error = max((abs(e) for e in metrics.stop_errors_m.values()), default=math.nan)
    jerk = float(np.max(np.abs(motion(run.speeds, dt)[1])))
    return dict(
        judged(run, metrics),
        rms_speed_error_kmh=metrics.rms_speed_error_kmh,
        max_speed_error_kmh=metrics.max_speed_error_kmh,
        rms_position_error_m=metrics.rms_position_error_m,
        stop_error_m=stop_error, stop_errors_m=metrics.stop_errors_m,
        traction_energy_kwh=metrics.traction_energy_kwh, max_jerk_mps3=jerk,
        step_p50_us=float(np.percentile(run.step_times_s, 50) * 1e6),
        step_p99_us=float(np.percentile(run.step_times_s, 99) * 1e6))


def _limited(job: Job, run: Callable[[Job], dict], timeout_s: float | None) -> dict:
    """``run(job)`` within ``timeout_s`` of wall time (ato_campaigns.run_process: on a worker, in
    its run process)."""
    started = time.perf_counter()
    try:
        return limited(partial(run, job), timeout_s)
    except RunTimeout:
        return dict(job_fields(job), status='timeout', wall_s=time.perf_counter() - started,
                    reason=f'exceeded the wall-time limit of {timeout_s:g} s (--timeout-s)')
    except (RunFailed, RunDied) as error:
        return dict(job_fields(job), status='error', wall_s=time.perf_counter() - started,
                    reason=str(error))


def _lost(job: Job, reason: str) -> dict:
    return dict(job_fields(job), status='error', wall_s=math.nan, reason=reason)


def run_all(jobs: list[Job], processes: int, timeout_s: float | None = None,
            run: Callable[[Job], dict] = run_job) -> list[dict]:
    """The result of ``run`` (a module-level function) on every job, in the order the runs end:
    the comparison is a campaign of one nominal draw (ato_campaigns.engine). With
    ``processes`` > 1 or a ``timeout_s``, the runs go to a Dask LocalCluster of ``processes``
    single-threaded workers; a run past ``timeout_s`` of wall time (None: no limit) is stopped
    and its result has status ``timeout``, one whose worker dies is an ``error``. Else the runs
    take turns in this process. A progress bar (tqdm) on stderr shows the rate and the time
    left; in a log (stderr not a terminal) one line per finished run."""
    from tqdm import tqdm
    bar = tqdm(total=len(jobs), unit='run', desc='compare', file=sys.stderr,
               dynamic_ncols=True)
    interactive = sys.stderr.isatty()
    results = []

    def finished(result: dict) -> None:
        results.append(result)
        last = f'{result["law"]} on {result["scenario"]}: {result["status"]}'
        bar.set_postfix_str(last, refresh=False)
        bar.update(1)
        if not interactive:
            bar.write(f'{len(results)}/{len(jobs)} runs: {last}', file=sys.stderr)

    serial = processes <= 1 and timeout_s is None
    try:
        execute(jobs, partial(_limited, run=run, timeout_s=timeout_s), finished, _lost,
                serial=serial, workers=max(processes, 1), allowed_failures=0)
    finally:
        bar.close()
    return results


def law_margins(jobs: list[Job]) -> list[dict]:
    """The loop margins (ato_campaigns.margins) of every (scenario, law) of ``jobs`` with the
    settings of its configuration, at its rate: on the nominal plant, with the actuator of the
    ``nominal with actuator`` row, and at the default uncertainty's largest actuator draw."""
    actuator = loop_margins.Actuator(*(ACTUATOR_DRAW[name] for name in ACTUATOR_PARAMETERS))
    out, seen = [], set()
    for job in jobs:
        if (job.scenario, job.law) in seen:
            continue
        seen.add((job.scenario, job.law))
        scenario = load_scenario(job.scenario)
        settings = settings_for(job.law, job.gains, scenario.train.name)
        row = {'scenario': job.scenario, 'law': job.law, 'gains': job.gains,
               **loop_margins.entry_margins(job.law, scenario, settings, uncertainty.DEFAULTS,
                                            job.rate_hz)}
        if 'phase_margin_deg' in row:
            actuated = loop_margins.loop_margins(loop_margins.law_loop(
                job.law, scenario, settings, job.rate_hz), actuator)
            row.update(actuator_phase_margin_deg=actuated.phase_margin_deg,
                       stable_with_actuator=actuated.stable)
        out.append(row)
    return out


def _margins_table(margins: list[dict], name: str) -> list[str]:
    """The loop margins of a scenario's laws as markdown (empty without any)."""
    rows = [r for r in margins if r['scenario'] == name]
    if not rows:
        return []
    worst = loop_margins.largest_actuator(uncertainty.DEFAULTS).describe()
    lines = [f'Loop margins ({rows[0]["gains"]} gains, linearised about cruise: '
             'ato_campaigns.margins): phase and delay margin on the nominal plant (the hold '
             f'only), phase margin with the actuator of `{WITH_ACTUATOR}`, stability at the '
             f"default uncertainty's largest actuator draw ({worst}) and the largest dead time "
             'the loop tolerates with that lag.', '',
             '| law | phase margin (deg) | delay margin (s) | stable, nominal | phase margin with '
             'the actuator (deg) | stable with it | stable at the largest draw | largest dead '
             'time tolerated (s) |', '|---|---|---|---|---|---|---|---|']
    yes = {True: 'yes', False: 'no'}
    for r in rows:
        if 'phase_margin_deg' not in r:
            lines.append(f'| {r["law"]} | {r["note"]} | | | | | | |')
            continue
        lines.append(f'| {r["law"]} | {_number(r, "phase_margin_deg", ".1f")} | '
                     f'{_number(r, "delay_margin_s", ".3g")} | {yes[r["stable_nominal"]]} | '
                     f'{_number(r, "actuator_phase_margin_deg", ".1f")} | '
                     f'{yes[r["stable_with_actuator"]]} | '
                     f'{yes[r["covers_actuator_draws"]]} | '
                     f'{_number(r, "tolerated_dead_time_s", ".3g")} |')
    return lines + ['']


def best_law(results: list[dict], plant: str = NOMINAL) -> str | None:
    """The ranking on ``plant``: lowest RMS speed error among the runs of the whole scenario at
    its control rate (a law sampled faster is not compared with the others) with status ok
    and a stop error within STOP_ERROR_LIMIT_M."""
    eligible = [r for r in results if r.get('plant', NOMINAL) == plant and r['status'] == 'ok'
                and r.get('end_time_s') is None
                and r.get('rate_hz') == r.get('scenario_rate_hz')
                and not r['stop_error_m'] > STOP_ERROR_LIMIT_M]
    if not eligible:
        return None
    return min(eligible, key=lambda r: r['rms_speed_error_kmh'])['law']


def _number(result: dict, key: str, fmt: str) -> str:
    value = result.get(key)
    return '-' if value is None or (isinstance(value, float) and math.isnan(value)) \
        else format(value, fmt)


def _row(r: dict) -> str:
    """One run's line of a scenario's table."""
    status = r['status'] + (f' ({r["reason"]})' if r.get('reason') else '')
    run = f'{r["model"]}, {r.get("rate_hz", 0):g} Hz'
    if r.get('end_time_s') is not None:
        run += f', first {r["end_time_s"]:g} s'
    return (f'| {r["law"]} | {r.get("plant", NOMINAL)} | {run} | {status.replace("|", "/")} | '
            f'{_number(r, "rms_speed_error_kmh", ".4f")} | '
            f'{_number(r, "max_speed_error_kmh", ".3f")} | '
            f'{_number(r, "rms_position_error_m", ".3f")} | '
            f'{_number(r, "stop_error_m", ".3f")} | '
            f'{_number(r, "traction_energy_kwh", ".0f")} | '
            f'{_number(r, "max_jerk_mps3", ".3f")} | {_number(r, "step_p99_us", ".0f")} | '
            f'{r.get("events") or "-"} |')


def markdown(results: list[dict], skipped: list[dict], scenarios: list[str], stamp: str,
             command: str, plots: bool = True, margins: list[dict] | None = None,
             gains: str = 'published') -> str:
    """The comparison as markdown: the tables, each scenario's loop margins (``margins``:
    law_margins) and links to the plots beside it (``plots``; the results page of the docs
    has none, the plots stay in the output folder). ``gains``: the laws' configuration."""
    load = ', '.join(f'{x:.1f}' for x in os.getloadavg())
    lines = ['# Comparison of the control laws', '',
             f'`{command}`, {stamp}, offline closed loop (ato_simulation.loop), '
             f'{os.cpu_count()} cores, load average {load} at the end (step times grow with '
             f'it). Gains: every law in its `{gains}` configuration.', '',
             f'Plants: `{NOMINAL}` (the controller\'s model: no uncertainty, no actuator '
             f'dynamics) and `{WITH_ACTUATOR}` (the same with the smallest actuator a campaign '
             f'draws: {actuator_text()}; what the actuator alone does). Status: `ok` only for a '
             'clean run that finished on time, else the most serious of what went wrong '
             '(ato_common.run_events). Columns: RMS/max speed error (km/h), RMS position error '
             '(m), worst stop error |x - station| (m), traction energy (kWh), max jerk '
             'from the second difference of the speed (m/s^3), host step time p99 (us, '
             'measured while the runs share the cores), events (ATP interventions, missed '
             'journey windows and stop errors beyond the platform tolerance, each with its '
             'first occurrence). Best, on each plant: '
             'lowest RMS speed error among the `ok` runs over the whole scenario at its control '
             f'rate with a stop error <= {STOP_ERROR_LIMIT_M} m (a law that needs a faster rate '
             'is listed, not ranked).', '']
    for name in scenarios:
        rows = sorted((r for r in results if r['scenario'] == name),
                      key=lambda r: (r['law'], PLANTS.index(r.get('plant', NOMINAL))))
        best = ', '.join(f'{plant}: **{best_law(rows, plant) or "none"}**' for plant in PLANTS)
        lines += [f'## {scenario_label(name)}', '', f'Best: {best}', '',
                  '| law | plant | model, rate | status | RMS speed err | max speed err | '
                  'RMS pos err | stop err | energy | max jerk | step p99 | events |',
                  '|---|---|---|---|---|---|---|---|---|---|---|---|']
        lines += [_row(r) for r in rows]
        for s in skipped:
            if s['scenario'] == name:
                lines.append(f'| {s["law"]} | - | - | not applicable ({s["reason"]}) '
                             '| - | - | - | - | - | - | - | - |')
        lines.append('')
        lines += _margins_table(margins or [], name)
        if plots:
            links = ', '.join(f'[{kind}]({scenario_label(name)}_{kind}.png)'
                              for kind in ('tracking', 'errors', 'commands', 'estimates'))
            lines += [f'Plots (the nominal plant): {links}', '']
    return '\n'.join(lines)


def plot_scenario(name: str, results: list[dict], folder: Path) -> list[Path]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    runs = [r for r in sorted(results, key=lambda r: r['law'])
            if r['scenario'] == name and 'curves' in r and r.get('plant', NOMINAL) == NOMINAL]
    label = scenario_label(name)
    paths = []

    def save(fig, kind):
        path = folder / f'{label}_{kind}.png'
        fig.tight_layout()
        fig.savefig(path, dpi=90)
        plt.close(fig)
        paths.append(path)

    fig, ax = plt.subplots(figsize=(10, 4))
    if runs:
        c = runs[0]['curves']
        ax.plot(c['time_s'], np.array(c['ref_speed_mps']) * 3.6, 'k--', lw=1, label='reference')
    for r in runs:
        c = r['curves']
        ax.plot(c['time_s'], np.array(c['speed_mps']) * 3.6, lw=1, label=r['law'])
    ax.set(xlabel='time (s)', ylabel='speed (km/h)', title=f'{label}: speed tracking')
    ax.legend(fontsize=8)
    save(fig, 'tracking')

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for r in runs:
        c = r['curves']
        top.plot(c['time_s'], (np.array(c['ref_speed_mps']) - c['speed_mps']) * 3.6, lw=1,
                 label=r['law'])
        bottom.plot(c['time_s'], np.array(c['ref_position_m']) - c['position_m'], lw=1,
                    label=r['law'])
    top.set(ylabel='speed error (km/h)', title=f'{label}: errors (reference - truth)')
    bottom.set(xlabel='time (s)', ylabel='position error (m)')
    top.legend(fontsize=8)
    save(fig, 'errors')

    fig, ax = plt.subplots(figsize=(10, 4))
    for r in runs:
        c = r['curves']
        ax.plot(c['time_s'], np.array(c['force_n']) / 1e3, lw=1, label=r['law'])
    ax.set(xlabel='time (s)', ylabel='applied force (kN)', title=f'{label}: commands (applied)')
    ax.legend(fontsize=8)
    save(fig, 'commands')

    with_estimates = [r for r in runs if r['curves']['estimates']]
    fig, axes = plt.subplots(max(1, len(with_estimates)), 1,
                             figsize=(10, 2.6 * max(1, len(with_estimates))), squeeze=False)
    for ax, r in zip(axes[:, 0], with_estimates):
        c = r['curves']
        for key, values in c['estimates'].items():
            values = np.array(values, dtype=float)
            first = values[np.isfinite(values)][:1]
            scale = first[0] if first.size and first[0] != 0.0 else 1.0
            ax.plot(c['time_s'], values / scale, lw=1, label=key)
        ax.set(ylabel='estimate / initial', title=f'{r["law"]}')
        ax.legend(fontsize=7, ncol=4)
    if not with_estimates:
        axes[0, 0].text(0.5, 0.5, 'no law with estimates ran on this scenario', ha='center')
    axes[-1, 0].set_xlabel('time (s)')
    save(fig, 'estimates')
    return paths


def _timeout(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 0.0):
        raise argparse.ArgumentTypeError(f'must be a finite number of seconds >= 0 (0: no '
                                         f'limit), got {text!r}')
    return value


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--out', type=Path, default=DEFAULT_OUT)
    parser.add_argument('--jobs', type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument('--scenario', action='append', type=scenario_argument,
                        help='only this built-in scenario or scenario file (repeatable; '
                        'default: every built-in scenario)')
    parser.add_argument('--law', action='append', choices=sorted(LAWS),
                        help='only this law (repeatable; default: all)')
    parser.add_argument('--gains', choices=GAINS, default='published',
                        help="every law's configuration of its gains (default published; "
                        'tuned: the tuned artefact for the scenario\'s train)')
    parser.add_argument('--timeout-s', type=_timeout, default=DEFAULT_TIMEOUT_S,
                        help='wall-time limit of one run, s: a run that exceeds it is stopped '
                        'and listed with status timeout, the others go on (default '
                        f'{DEFAULT_TIMEOUT_S:g}; 0: no limit, and with --jobs 1 the runs then '
                        'take turns in this process)')
    parser.add_argument('--results-page', type=Path, default=None,
                        help='also write the tables, with date, machine and commit, to this '
                        'results page of the docs (make compare: docs/results/comparison.md)')
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    scenarios = args.scenario or builtin_scenarios()
    measured = (results_page_provenance(args.results_page)
                if args.results_page is not None else None)
    jobs, skipped = plan_jobs(scenarios, args.law, PLANTS, args.gains)
    margins = law_margins(jobs)
    print(f'{len(jobs)} runs ({len(skipped)} law/scenario pairs not applicable) on '
          f'{args.jobs} processes', file=sys.stderr)
    results = run_all(jobs, args.jobs, args.timeout_s or None)
    args.out.mkdir(parents=True, exist_ok=True)
    stamp = datetime.now(timezone.utc).strftime('%Y-%m-%d %H:%M UTC')
    default_page = ['--results-page', str(DEFAULT_RESULTS_PAGE)]
    command = ('make compare' if argv in ([], default_page)
               else ' '.join(['python -m ato_campaigns.compare', *argv]))
    (args.out / 'compare.md').write_text(markdown(results, skipped, scenarios, stamp, command,
                                                  margins=margins, gains=args.gains))
    if args.results_page is not None:
        body = markdown(results, skipped, scenarios, stamp, command, plots=False,
                        margins=margins, gains=args.gains)
        body = body.split('\n', 2)[2]  # the page has its own title and provenance line
        write_results_page(args.results_page, 'Comparison of the control laws', command,
                           f'{body}\n\nThe plots of each scenario are written beside '
                           f'`{args.out}/compare.md` when the command runs.', measured)
    best, with_actuator = ({scenario_label(name): best_law(
        [r for r in results if r['scenario'] == name], plant) for name in scenarios}
        for plant in PLANTS)
    summary = [{k: v for k, v in r.items() if k not in ('curves', 'detail')} for r in results]
    (args.out / 'compare.json').write_text(json.dumps(
        {'generated': stamp, 'best': best, 'best_with_actuator': with_actuator,
         'actuator': {name: ACTUATOR_DRAW[name] for name in ACTUATOR_PARAMETERS},
         'gains': args.gains, 'margins': margins,
         'results': summary, 'not_applicable': skipped}, indent=1))
    for name in scenarios:
        plot_scenario(name, results, args.out)
    failed = [r for r in results if r['status'] != 'ok']
    print(f'wrote {args.out / "compare.md"} ({len(results)} runs, {len(failed)} not ok); '
          f'best: ' + ', '.join(f'{n}: {b or "none"}' for n, b in best.items()))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
