# SPDX-License-Identifier: Apache-2.0
"""mpc_bench_dds: the controller node's latency over DDS and its resident memory.

The one benchmark that needs rclpy, so it lives in ros/ with its own entry point (mpc_bench,
in evaluation/, imports nothing from ros/): a probe node plays the simulator and the clock for
a controller started as its own process. Run it with
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST mpc_bench_dds [--quick] [--out FILE]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rosgraph_msgs.msg import Clock

from mpc_local_planner.core.config import SolverSettings
from mpc_local_planner.core.diagnostics import (
    CONTROLLER_DIAGNOSTICS_TOPIC,
    ControllerDiagnostics,
)
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.paths import paper_sinusoid
from mpc_local_planner.evaluation.bench_runs import stats, STEP
from mpc_local_planner.ros.conversions import seconds_to_stamp, state_to_odometry
from mpc_local_planner.ros.executors import spin_until
from mpc_local_planner.ros.qos import CLOCK_QOS, CMD_VEL_QOS, DIAGNOSTICS_QOS, ODOM_QOS

__all__ = ['measure_controller_latency']


def _rss_mb(pid: int) -> float:
    with open(f'/proc/{pid}/status', encoding='ascii') as f:
        for line in f:
            if line.startswith('VmRSS:'):
                return float(line.split()[1]) / 1024.0
    return math.nan


def measure_controller_latency(steps: int = 100) -> dict[str, Any]:
    """Time the controller node, a separate process, over DDS with simulated time.

    A probe node plays simulator and clock: it publishes ``odom`` (the state, stamped at
    the current simulated time), then advances ``/clock`` by one step h, which fires the
    controller's timer; it times from that clock message to the ``cmd_vel`` it causes, and
    reads the solve time the controller reports on ``mpc/diagnostics``. Latency beyond the
    solve = that interval minus the reported solve time (DDS both ways, executor wake-up,
    the controller's Python around the solve).
    """
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    env.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))  # this session's own
    os.environ.update({k: env[k] for k in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID')})
    cmd = [sys.executable, '-m', 'mpc_local_planner.ros.mpc_controller_node', '--ros-args',
           '-p', 'use_sim_time:=true', '-p', 'analytic_path:=paper_sinusoid',
           '-p', 'world_file:=worlds/paper_obstacle.yaml',
           '-p', f'solver:={SolverSettings().solver}',
           '-p', f'step:={STEP}', '-p', 'odom_timeout:=1000.0']
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            text=True)
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('mpc_bench_probe', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    got: dict[str, Any] = {'cmd': None, 'diag': None}

    def cmd_callback(msg: Twist) -> None:
        got['cmd'] = (time.perf_counter(), np.array([msg.linear.x, msg.angular.z]))

    def diag_callback(msg: DiagnosticArray) -> None:
        got['diag'] = ControllerDiagnostics.from_values(
            (kv.key, kv.value) for st in msg.status for kv in st.values)

    clock_pub = node.create_publisher(Clock, '/clock', CLOCK_QOS)
    odom_pub = node.create_publisher(Odometry, 'odom', ODOM_QOS)
    node.create_subscription(Twist, 'cmd_vel', cmd_callback, CMD_VEL_QOS)
    node.create_subscription(DiagnosticArray, CONTROLLER_DIAGNOSTICS_TOPIC, diag_callback,
                             DIAGNOSTICS_QOS)
    model, path = Unicycle(), paper_sinusoid()
    x, t_sim = path.start.copy(), 1.0
    latency, beyond, solve, rss = [], [], [], math.nan
    try:
        deadline = time.monotonic() + 120.0
        while time.monotonic() < deadline and (odom_pub.get_subscription_count() == 0
                                               or clock_pub.get_subscription_count() == 0):
            executor.spin_once(timeout_sec=0.1)
            if proc.poll() is not None:
                msg = f'controller exited: {proc.stderr.read()[-2000:]}'
                raise RuntimeError(msg)
        clock_pub.publish(Clock(clock=seconds_to_stamp(t_sim)))
        executor.spin_once(timeout_sec=1.0)  # let the controller see the clock, then odom
        for k in range(steps + 5):
            odom_pub.publish(state_to_odometry(x, np.zeros(2), stamp=seconds_to_stamp(t_sim)))
            end = time.perf_counter() + 0.02  # odom first: let it arrive before the clock
            while time.perf_counter() < end:
                executor.spin_once(timeout_sec=0.005)
            got['cmd'], got['diag'] = None, None
            t_sim += STEP
            sent = time.perf_counter()
            clock_pub.publish(Clock(clock=seconds_to_stamp(t_sim)))
            if not spin_until(executor, lambda: got['cmd'] is not None and got['diag'] is not None,
                              timeout_sec=5.0, period_sec=0.01):
                continue
            received, u = got['cmd']
            solve_ms = got['diag'].solve_ms
            if k >= 5 and math.isfinite(solve_ms):  # first steps build; at the goal, no solve
                latency.append(1e3 * (received - sent))
                solve.append(solve_ms)
                beyond.append(1e3 * (received - sent) - solve_ms)
            x = model.step(x, u, STEP)
        rss = _rss_mb(proc.pid)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
        proc.terminate()
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
    result = {'steps': len(latency), 'latency_ms': stats(latency), 'solve_ms': stats(solve),
              'beyond_solve_ms': stats(beyond), 'controller_rss_mb': rss}
    result['summary'] = (
        f"DDS (controller as its own process, sim time, {len(latency)} steps): clock->cmd_vel "
        f"median {result['latency_ms']['median']:.2f} ms, p95 {result['latency_ms']['p95']:.2f}"
        f" ms; reported solve median {result['solve_ms']['median']:.2f} ms; beyond the solve "
        f"median {result['beyond_solve_ms']['median']:.2f} ms, p95 "
        f"{result['beyond_solve_ms']['p95']:.2f} ms; controller RSS {rss:.0f} MB")
    return result


def main(argv: Sequence[str] | None = None) -> int:
    """Measure the controller node over DDS, print the summary and write JSON."""
    parser = argparse.ArgumentParser(prog='mpc_bench_dds', description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='30 control steps instead of 100')
    parser.add_argument('--out', default='bench_dds.json', help='JSON output file')
    args = parser.parse_args(argv)
    result = measure_controller_latency(steps=30 if args.quick else 100)
    print(result['summary'], flush=True)
    with open(args.out, 'w', encoding='utf-8') as f:
        json.dump(result, f, indent=2)
    print(f'wrote {args.out}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
