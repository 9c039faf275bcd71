"""The reference pages of the documentation, generated from the code.

``mkdocs build`` runs ``docs/gen_reference.py`` (the mkdocs-gen-files plugin), which writes
:data:`PAGES` into the site: the topics and QoS (``ato_common.conventions.TOPICS``), every
node's parameters (each node's parameter table), the registry of laws with their settings and
papers, the built-in scenarios and the train presets with their sources. Nothing on these pages
is typed by hand, so they cannot go stale; ``python -m ato_tools.reference_pages DIR`` writes
them to a folder to read without the site.
"""

from __future__ import annotations

import argparse
import inspect
import sys
from pathlib import Path
from typing import Callable

from ato_campaigns.provenance import REPOSITORY
from ato_common import units
from ato_common.conventions import TOPICS
from ato_common.scenario import builtin_scenarios, load_scenario
from ato_common.trains import TRAIN_PRESETS, train_preset
from ato_controller_node.laws import LAWS
from ato_controller_node.laws.base import setting_fields
from ato_controller_node.node import NODE_PARAMS, gain_params
from ato_ros.params import Param
from profile_node.node import PARAMS as PROFILE_PARAMS
from train_plant_node.node import PARAMS as PLANT_PARAMS

GENERATED = ('*Generated from the code by `ato_tools.reference_pages` when the site is built; '
             'edit the code, not this page.*')


def _cell(text) -> str:
    """A table cell: pipes and square brackets escaped (``[FIX] [-]`` is no reference link)."""
    return str(text).replace('|', '\\|').replace('[', '\\[').replace('\n', ' ')


def law_names() -> list[str]:
    """Every registered law, sorted: what every list of laws in the docs must name."""
    return sorted(LAWS)


def topics_page() -> str:
    lines = ['# Topics', '', GENERATED, '',
             'All quantities are SI. The suite\'s own topic names are relative, so a stack '
             'pushed into a namespace (`-r __ns:=/train1`) keeps them under it; `/clock` and '
             '`/diagnostics` are global. Every type is a standard `common_interfaces` message.',
             '', '| topic | type | QoS | rate | units | publisher | subscribers | content |',
             '|---|---|---|---|---|---|---|---|']
    for t in TOPICS.values():
        lines.append(f'| `{t.name}` | `{t.type_name}` | {t.qos.describe()} | {_cell(t.rate)} '
                     f'| {_cell(t.units)} '
                     f'| {_cell(t.publisher)} | {_cell(t.subscribers)} | '
                     f'{_cell(t.description)} |')
    lines += ['', 'QoS: the per-step streams are reliable and keep-all, so a subscriber that '
              'lags (a monitor, a recorder) slows the publisher down instead of losing messages; '
              'the whole curve is latched (transient local) for late joiners; `/clock` is '
              'reliable.', '']
    return '\n'.join(lines)


def _parameter_rows(params) -> list[str]:
    rows = ['| parameter | default | range | set at run time | description |',
            '|---|---|---|---|---|']
    for p in params:
        if p.minimum is not None:
            valid = f'{p.minimum:g} .. {p.maximum:g}'
        else:
            valid = ', '.join(p.choices) if p.choices else ''
        default = str(p.default).lower() if isinstance(p.default, bool) else p.default
        rows.append(f'| `{p.name}` | `{default}` | {_cell(valid)} | '
                    f'{"no" if p.read_only else "yes"} | {_cell(p.description)} |')
    return rows


NODES: tuple[tuple[str, Callable[[], tuple[Param, ...]]], ...] = (
    ('train_plant_node', lambda: tuple(PLANT_PARAMS)),
    ('profile_node', lambda: tuple(PROFILE_PARAMS)),
    ('ato_controller_node', lambda: tuple(NODE_PARAMS)),
)


def parameters_page() -> str:
    lines = ['# Parameters', '', GENERATED, '',
             'Every parameter is declared with a descriptor (type, range, description). A '
             'rejected `ros2 param set` returns the reason and the node keeps its previous '
             'configuration; a bad value at start-up (an unknown law, a malformed scenario file) '
             'stops the node with exit code 2 and a message naming the file and the field, '
             'before it publishes anything.', '']
    for node, params in NODES:
        lines += [f'## {node}', '', *_parameter_rows(params()), '']
    lines += ['### Gains of the laws', '',
              'The controller declares one parameter `<law>.<setting>` per setting of every '
              'law (see [Control laws](laws.md)); all may be set at run time.', '',
              *_parameter_rows(gain_params()), '']
    return '\n'.join(lines)


def _first_paragraph(text: str | None) -> str:
    return ' '.join(inspect.cleandoc(text or '').split('\n\n')[0].split())


def _paper_title(stem: str) -> str:
    """The title of the paper note ``docs/papers/<stem>.md`` (its first heading)."""
    note = REPOSITORY / 'docs' / 'papers' / f'{stem}.md'
    for line in note.read_text().splitlines():
        if line.startswith('# '):
            return line[2:].strip()
    raise ValueError(f'{note} has no title')


def laws_page() -> str:
    lines = ['# Control laws', '', GENERATED, '',
             'The `controller` parameter of `ato_controller_node` (and `--controller` of '
             '`run_scenario`, `controller:=` of the launch file) names one of these laws: '
             + ', '.join(f'`{name}`' for name in law_names()) + '. Each is one module of '
             '`ato_controller_node/laws/` behind the interface of `laws/base.py` '
             '(`ControlLaw`); the paper notes are under [Papers](../papers/index.md).', '',
             '| law | paper | drives | measurements used | summary |', '|---|---|---|---|---|']
    for name in law_names():
        law = LAWS[name]
        paper = getattr(law, 'paper', None)
        paper_link = (f'[{_paper_title(paper)}](../papers/{paper}.md)' if paper
                      else 'none (industrial baseline)')
        drives = ('one total force, shared by the host' if law.actuators is None
                  else f'{law.actuators} actuators')
        used = ', '.join(law.requires) + (f' ({law.cars} cars)' if law.cars else '')
        lines.append(f'| [`{name}`](#{name}) | {paper_link} | {drives} | {used} | '
                     f'{_cell(law.summary)} |')
    for name in law_names():
        law = LAWS[name]
        module = inspect.getmodule(law)
        lines += ['', f'## {name}', '', f'`{law.__module__}.{law.__qualname__}`: '
                  f'{_first_paragraph(law.__doc__) or law.summary}', '',
                  '| setting | default | range | tuned over | units | description |',
                  '|---|---|---|---|---|---|']
        for f in setting_fields(law.Settings):
            meta = f.metadata
            valid = '' if isinstance(f.default, bool) else \
                f'{meta["minimum"]:g} .. {meta["maximum"]:g}'
            default = str(f.default).lower() if isinstance(f.default, bool) else f'{f.default:g}'
            admissible = meta.get('admissible')
            tuned = (f'{admissible[0]:g} .. {admissible[1]:g}'
                     + (' (log)' if meta.get('scale') == 'log' else '')) if admissible else '-'
            lines.append(f'| `{f.name}` | `{default}` | {valid} | {tuned} | '
                         f'{_cell(meta["units"])} | {_cell(meta["description"])} |')
        if module is not None and module.__doc__:
            lines += ['', f'From the module `{module.__name__}`:', '', '```text',
                      inspect.cleandoc(module.__doc__), '```']
    return '\n'.join(lines) + '\n'


def scenarios_page() -> str:
    lines = ['# Built-in scenarios', '', GENERATED, '',
             'Each is a YAML file of `ato_common/ato_common/scenarios/` that states its source '
             'and what was built; `scenario:=<name>` (or a path to your own file, see '
             '[Scenarios and lines](../guide/scenarios.md)) selects one.', '',
             '| scenario | train | line | stops | top limit | control rate | plant model |',
             '|---|---|---|---|---|---|---|']
    scenarios = [load_scenario(name) for name in builtin_scenarios()]
    for s in scenarios:
        top = f'{units.mps_to_kmh(max(s.line.speed_limit_mps.values)):.0f} km/h'
        model = 'multi_car' if s.train.cars else 'point_mass'
        lines.append(f'| `{s.name}` | [`{s.train.name}`](trains.md#{s.train.name}) | '
                     f'{s.line.length_m / 1000:.2f} km | {len(s.line.stations)} | {top} | '
                     f'{s.run.controller_rate_hz:g} Hz | {model} |')
    for s in scenarios:
        lines += ['', f'## {s.name}', '', _cell(s.description), '', f'Source: {_cell(s.source)}',
                  '', 'Stations: ' + ', '.join(
                      f'{st.name} at {st.position_m:g} m' + (f' (dwell {st.dwell_s:g} s)'
                                                             if st.dwell_s else '')
                      for st in s.line.stations) + '.']
        if s.plant.failures:
            lines += ['', 'Actuator failures of the plant: ' + '; '.join(
                f'{f.actuator} {f.kind} from {f.start_s:g} s' for f in s.plant.failures) + '.']
    return '\n'.join(lines) + '\n'


def _davis(d) -> str:
    return (f'a = {d.a_n:.6g} N, b = {d.b_n_s_per_m:.6g} N s/m, '
            f'c = {d.c_n_s2_per_m2:.6g} N s^2/m^2')


def trains_page() -> str:
    lines = ['# Train presets', '', GENERATED, '',
             'A scenario names its train with `train: {preset: <name>}` (or a TTOBench train '
             'file). Values in SI; the Davis resistance is `a + b v + c v^2` (N, v in m/s).', '',
             '| preset | mass | max traction | max power | service / emergency brake | '
             'cars | actuators |', '|---|---|---|---|---|---|---|']
    trains = [train_preset(name) for name in TRAIN_PRESETS]
    for t in trains:
        tr = t.traction
        lines.append(
            f'| [`{t.name}`](#{t.name}) | {t.mass_kg / 1000:.1f} t | '
            f'{tr.max_traction_force_n / 1000:.0f} kN | {tr.max_traction_power_w / 1e6:.2f} MW '
            f'| {tr.max_service_brake_force_n / 1000:.0f} / '
            f'{tr.max_emergency_brake_force_n / 1000:.0f} kN | {max(1, len(t.cars))} | '
            f'{", ".join(t.actuator_names)} |')
    for t in trains:
        lines += ['', f'## {t.name}', '', _cell(t.description), '',
                  f'- simulated Davis resistance: {_davis(t.davis)}',
                  f'- nominal (what the controller knows): {_davis(t.davis_nominal)}',
                  f'- length {t.length_m:g} m' + (f', {len(t.cars)} cars' if t.cars else '')]
        if t.sources:
            lines += ['', '| value | source |', '|---|---|']
            lines += [f'| {_cell(k)} | {_cell(v)} |' for k, v in t.sources.items()]
    return '\n'.join(lines) + '\n'


def _rclcpp_qos(qos) -> str:
    """A QoS of ``conventions`` as rclcpp writes it."""
    history = f'rclcpp::KeepLast({qos.depth})' if qos.depth else 'rclcpp::KeepAll()'
    return (f'rclcpp::QoS({history}).{"reliable" if qos.reliable else "best_effort"}()'
            f'.{"transient_local" if qos.transient_local else "durability_volatile"}()')


def _contract_values() -> dict[str, object]:
    """The figures the contract's clauses quote: the nodes' parameter defaults and the
    harness's stop limit."""
    from ato_bringup.conformance_cases import STOP_LIMIT_S
    defaults = {p.name: p.default for p in (*PLANT_PARAMS, *NODE_PARAMS)}
    names = ('resend_period_s', 'command_stamp_tolerance_s', 'stale_after_s',
             'command_wait_limit_s', 'watchdog_periods', 'emergency_periods')
    return {**{name: f'{defaults[name]:g}' for name in names}, 'stop_limit_s': f'{STOP_LIMIT_S:g}'}


def contract_page() -> str:
    from ato_common import contract
    lines = [f'# The ATO node contract, version {contract.CONTRACT_VERSION}', '', GENERATED, '',
             'What an ATO node of your own honours to drive the suite\'s plant in place of '
             '`ato_controller_node`, in any language that speaks ROS 2: standard '
             '`common_interfaces` messages only. `ato conformance --controller-command CMD` '
             'checks a node against it case by case ([Your own ATO node]'
             '(../guide/external-ato.md)). A change a conforming node could fail is a new major '
             'version.', '', '## Topics', '',
             '| | topic | type | QoS | rclcpp QoS | rate | what for |',
             '|---|---|---|---|---|---|---|']
    for role, topics in (('reads', contract.INPUTS), ('publishes', contract.OUTPUTS),
                         ('may read', contract.OPTIONAL_INPUTS)):
        for key, why in topics.items():
            t = TOPICS[key]
            lines.append(f'| {role} | `{t.name}` | `{t.type_name}` | {t.qos.describe()} | '
                         f'`{_rclcpp_qos(t.qos)}` | {_cell(t.rate)} | {_cell(why)} |')
    lines += ['', 'Names without a leading `/` are relative: in a namespace they are under it. '
              'Subscribe to the per-step streams reliable and keep-all (or deep enough): a '
              'lockstep step lost is a step the plant waits for.', '']
    values = _contract_values()
    for clause in contract.CLAUSES:
        lines += [f'## {clause.title}', '', clause.text.format(**values), '']
    lines += ['## The conformance cases', '',
              '| case | clauses | what the harness does, and what passes |', '|---|---|---|']
    titles = {c.key: c.title for c in contract.CLAUSES}
    for name, case in contract.CASES.items():
        clauses = ', '.join(f'[{titles[k]}](#{titles[k].lower().replace(" ", "-")})'
                            for k in case.clauses)
        lines.append(f'| `{name}`: {case.title} | {clauses} | {_cell(case.how)} |')
    lines += ['', '## In C++ (rclcpp)', '',
              'The same topics and QoS; the types from `common_interfaces`:', '', '```cpp',
              '#include <sensor_msgs/msg/joint_state.hpp>          // ato/command',
              '#include <std_msgs/msg/string.hpp>                  // train/identity',
              '#include <trajectory_msgs/msg/joint_trajectory.hpp> // state, reference', '']
    for key in (*contract.INPUTS, *contract.OUTPUTS):
        t = TOPICS[key]
        lines.append(f'const auto qos_{key} = {_rclcpp_qos(t.qos)};  // {t.name}')
    lines += ['```', '',
              'Declare a `std::string` parameter `scenario`; keep the states and the references '
              'in maps keyed by `rclcpp::Time(msg.header.stamp).nanoseconds()`, step when a '
              'stamp is in both, and set the command\'s `header.stamp` to the state\'s. A '
              'minimal node in Python, written from this page alone: '
              '`examples/external_ato/p_ato_node.py`.', '']
    return '\n'.join(lines)


#: page path in the site -> generator
PAGES: dict[str, Callable[[], str]] = {
    'reference/ato-contract.md': contract_page,
    'reference/topics.md': topics_page,
    'reference/parameters.md': parameters_page,
    'reference/laws.md': laws_page,
    'reference/scenarios.md': scenarios_page,
    'reference/trains.md': trains_page,
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description='write the generated reference pages')
    parser.add_argument('folder', type=Path)
    args = parser.parse_args(argv)
    for path, page in PAGES.items():
        target = args.folder / path
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(page())
        print(target, file=sys.stderr)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
