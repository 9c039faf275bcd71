"""What an ATP node of its own would cost the composed stack: ``python bench/atp_node_cost.py``.

The ATP (``train_plant_node.atp``) runs inside the plant process, called by the simulation
each control period. As a node of its own it would need, per lockstep step, the plant to
publish the odometry's report to it, the ATP to take it and publish its demand (emergency
brake, holding brake), and the plant to take the demand and wait for it before it advances.
This script measures exactly that traffic in the composed stack (``ato_bringup.composed``:
the plant, the profile and the controller in one process on one executor), in paired runs
of ``short_line`` in lockstep: each pair runs the stack as it is (``baseline``) and the stack
with a stand-in ATP node (``atp node``: the plant publishes a ``std_msgs/Float64MultiArray``
odometry report per step on ``atp/odometry``, the stand-in answers each with a
``std_msgs/Header`` stamped for the step on ``atp/demand``, the plant advances once both the
command and the demand of the step have come). The supervision's own computation is the same
in either design and is left out: the difference is the cost of the node.

Each run is a fresh process; its CPU time and wall time per step are taken between 10 s of
simulated time and the end. ``--write`` puts the result, with the date, the machine and the
commit, on the page that shows it (docs/guide/plant.md, between its markers).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARKERS = ('<!-- atp-node-cost: begin -->', '<!-- atp-node-cost: end -->')
START_S = 10.0   # the steady window starts here (start-up, discovery and the first plan done)


def child(variant: str, seconds: float) -> dict:
    """One composed run in this process; the CPU and wall time per step of its steady part."""
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from std_msgs.msg import Float64MultiArray, Header

    from ato_controller_node.node import AtoControllerNode
    from ato_ros.lifecycle import RunNodeHooks, run_nodes
    from ato_ros.messages import to_time
    from profile_node.node import ProfileNode
    from train_plant_node.node import TrainPlantNode

    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    marks: dict = {}

    class Plant(TrainPlantNode):
        def advance(self) -> None:
            super().advance()
            if self.sim.stamp_ns == int(START_S * 1e9):
                marks['start'] = (time.process_time(), time.perf_counter(), self.sim.stamp_ns)
            if self.finished:
                marks['end'] = (time.process_time(), time.perf_counter(), self.sim.stamp_ns)

    class PlantWithAtpNode(Plant):
        def __init__(self):
            super().__init__()
            self.odometry_pub = self.create_publisher(Float64MultiArray, 'atp/odometry', qos)
            self.create_subscription(Header, 'atp/demand', self.on_demand, qos)
            self.demand_ns = -1
            self.waiting_command: bytes | None = None
            marks['demands'] = marks['waits'] = 0

        def publish_step(self) -> None:
            new_step = self.step_messages is None or self.step_messages[0] != self.stamp_ns()
            super().publish_step()
            if new_step and self.started:
                o = self.sim.odometry
                self.odometry_pub.publish(Float64MultiArray(data=[
                    float(self.sim.stamp_ns), o.position_m, o.min_safe_front_m,
                    o.max_safe_front_m, o.speed_mps, o.max_speed_mps]))

        def on_demand(self, msg: Header) -> None:
            self.demand_ns = msg.stamp.sec * 1_000_000_000 + msg.stamp.nanosec
            marks['demands'] += 1
            if self.waiting_command is not None and self.demand_ns == self.stamp_ns():
                data, self.waiting_command = self.waiting_command, None
                super().on_command(data)

        def on_command(self, data: bytes) -> None:
            if self.started and not self.finished and self.demand_ns != self.stamp_ns():
                self.waiting_command = data  # the step's demand has not come: wait for it
                marks['waits'] += 1
                return
            super().on_command(data)

    class AtpStandIn(RunNodeHooks, Node):
        def __init__(self):
            super().__init__('atp_node')
            self.demand_pub = self.create_publisher(Header, 'atp/demand', qos)
            self.create_subscription(Float64MultiArray, 'atp/odometry', self.on_odometry, qos)

        def on_odometry(self, msg: Float64MultiArray) -> None:
            self.demand_pub.publish(Header(stamp=to_time(int(msg.data[0])), frame_id=''))

    makers = ((Plant, ProfileNode, AtoControllerNode) if variant == 'baseline' else
              (PlantWithAtpNode, ProfileNode, AtoControllerNode, AtpStandIn))
    code = run_nodes(makers, ['--ros-args', '-p', 'scenario:=short_line',
                              '-p', f'end_time_s:={seconds}',
                              '-p', 'diagnostics_period_s:=10.0', '--log-level', 'warn'])
    (cpu0, wall0, stamp0), (cpu1, wall1, stamp1) = marks['start'], marks['end']
    steps = (stamp1 - stamp0) // 100_000_000
    return {'variant': variant, 'code': code, 'steps': steps,
            'cpu_ms_per_step': 1e3 * (cpu1 - cpu0) / steps,
            'wall_ms_per_step': 1e3 * (wall1 - wall0) / steps,
            'demands': marks.get('demands', 0), 'waits': marks.get('waits', 0)}


def run_pair(seconds: float, env: dict) -> list[dict]:
    out = []
    for variant in ('baseline', 'atp node'):
        done = subprocess.run([sys.executable, __file__, '--child', variant, '--seconds',
                               str(seconds)], env=env, capture_output=True, text=True,
                              timeout=600, check=False)
        lines = [line for line in done.stdout.splitlines() if line.startswith('{')]
        if done.returncode or not lines:
            raise RuntimeError(f'{variant} run failed ({done.returncode}):\n{done.stderr[-2000:]}')
        out.append(json.loads(lines[-1]))
    return out


def report(pairs: list[list[dict]], seconds: float, command: str, measured) -> str:
    """The measured figures as the plant page shows them (``measured``: the provenance taken
    when the measurement started)."""
    def cell(values: list[float]) -> str:
        return f'{statistics.median(values):.3f} (range {min(values):.3f}-{max(values):.3f})'
    base = [p[0] for p in pairs]
    atp = [p[1] for p in pairs]
    cpu_extra = [a['cpu_ms_per_step'] - b['cpu_ms_per_step']
                 for b, a in pairs]
    share = [100.0 * (a['wall_ms_per_step'] / b['wall_ms_per_step'] - 1.0) for b, a in pairs]
    return '\n'.join([
        f'{measured.markdown(command)} {len(pairs)} pairs of composed lockstep runs of '
        f'short_line, {seconds:g} s of simulated time each, the steady part from {START_S:g} s; '
        'medians and ranges:', '',
        '| composed stack | CPU ms per step | wall ms per step |', '|---|---|---|',
        f'| as it is (the ATP inside the plant) | {cell([r["cpu_ms_per_step"] for r in base])} '
        f'| {cell([r["wall_ms_per_step"] for r in base])} |',
        f'| with an ATP node of its own | {cell([r["cpu_ms_per_step"] for r in atp])} | '
        f'{cell([r["wall_ms_per_step"] for r in atp])} |', '',
        f'Paired difference: {cell(cpu_extra)} ms of CPU per step more with the node, the run '
        f'{statistics.median(share):.0f} % slower in wall time (median of the pairs; range '
        f'{min(share):.0f} to {max(share):.0f} %). The node cost more CPU per step in '
        f'{sum(d > 0 for d in cpu_extra)} of {len(pairs)} pairs and more wall time in '
        f'{sum(d > 0 for d in share)} of {len(pairs)}.'])


def write(page: Path, text: str) -> None:
    content = page.read_text()
    begin, end = content.index(MARKERS[0]), content.index(MARKERS[1])
    page.write_text(content[:begin + len(MARKERS[0])] + '\n' + text + '\n' + content[end:])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--pairs', type=int, default=5)
    parser.add_argument('--seconds', type=float, default=300.0,
                        help='simulated time of each run, s')
    parser.add_argument('--write', type=Path, help='the page to put the figures on')
    parser.add_argument('--child', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.seconds)))
        return 0
    from ato_campaigns.provenance import results_page_provenance
    from ato_common.domains import free_domain
    from ato_ros.middleware import with_middleware_defaults
    measured = results_page_provenance(args.write or ROOT / 'docs/guide/plant.md')
    with free_domain() as domain:
        env = with_middleware_defaults(dict(os.environ, ROS_DOMAIN_ID=str(domain),
                                            ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST'))
        pairs = [run_pair(args.seconds, env) for _ in range(args.pairs)]
    command = 'python bench/atp_node_cost.py' + (f' --pairs {args.pairs}' if args.pairs != 5
                                                   else '') + (
        f' --seconds {args.seconds:g}' if args.seconds != 300.0 else '') + (
        f' --write {args.write}' if args.write else '')
    text = report(pairs, args.seconds, command, measured)
    print(text)
    if args.write:
        write(args.write, text)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
