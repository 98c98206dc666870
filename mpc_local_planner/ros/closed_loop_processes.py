# SPDX-License-Identifier: Apache-2.0
"""closed_loop's node processes (``--separate-processes``): start, restart and stop them.

Each node runs as ``python -m <module> --ros-args -p key:=value ...`` (no ros2cli needed),
its output in a log file; with ``--respawn`` a node that exits is started again, at most
MAX_RESPAWNS times per run, and never one that refused its parameters.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
import signal
import subprocess
import sys
import time
from typing import Any, NamedTuple

import yaml

from mpc_local_planner.process_ties import tied_environment
from mpc_local_planner.ros.closed_loop_parameters import LoopOptions, MODULES
from mpc_local_planner.ros.node_main import EXIT_INVALID_PARAMETERS

__all__ = ['CHILD_EXIT_TIMEOUT', 'MAX_RESPAWNS', 'node_command', 'node_usage', 'ProcessSample',
           'process_sample', 'respawn', 'spawn_all', 'spawn_node', 'stop_children']

# Wall seconds a child process gets to exit after SIGINT before it is killed.
CHILD_EXIT_TIMEOUT = 5.0
# Restarts of node processes per run with --respawn (a crash loop ends the run instead).
MAX_RESPAWNS = 10


def _ros_arg(name: str, value: Any) -> str:
    if isinstance(value, bool):
        text = 'true' if value else 'false'
    elif isinstance(value, (list, tuple)):
        text = '[' + ','.join(repr(float(v)) if isinstance(v, float) else str(v)
                              for v in value) + ']'
    elif isinstance(value, float):
        text = repr(value)
    elif isinstance(value, str):
        # ROS reads a -p value as YAML: quote a string that would read as something else
        # ('' as nothing, a footprint "[[x, y], ...]" as a nested list)
        try:
            plain = yaml.safe_load(value) == value
        except yaml.YAMLError:
            plain = False
        text = value if plain else "'" + value.replace("'", "''") + "'"
    else:
        text = str(value)
    return f'{name}:={text}'


def node_command(name: str, parameters: dict[str, Any]) -> list[str]:
    """Return the command that runs node name (a key of MODULES) with parameters.

    ``python -m <module> --ros-args -p key:=value ...``: no ros2cli or colcon install needed.
    """
    command = [sys.executable, '-m', MODULES[name], '--ros-args']
    for key, value in parameters.items():
        command += ['-p', _ros_arg(key, value)]
    return command


def spawn_node(name: str, parameters: dict[str, Any], log: Path, *,
               append: bool = False) -> subprocess.Popen:
    """Start node name as a process; stdout and stderr go to log."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, 'a' if append else 'w', encoding='utf-8') as stream:
        if append:
            stream.write(f'--- {name} started again ---\n')
            stream.flush()
        # the child holds its own descriptor once started
        return subprocess.Popen(node_command(name, parameters), stdout=stream,
                                stderr=subprocess.STDOUT, env=tied_environment())


def spawn_all(params: dict[str, dict[str, Any]], logs: Path) -> dict[str, subprocess.Popen]:
    """Start every node of params that runs as a process (MODULES order); logs in logs/."""
    return {name: spawn_node(name, params[name], logs / f'{name}.log')
            for name in MODULES if name in params}


def respawn(options: LoopOptions, dead: list[str], children: dict[str, subprocess.Popen],
             params: dict[str, dict[str, Any]], logs: Path, respawns: list[dict[str, Any]],
             sim_time: float) -> bool:
    """Start the dead node processes again if --respawn allows; return False to end the run."""
    if not options.respawn:
        return False
    for name in dead:
        code = children[name].returncode
        if code == EXIT_INVALID_PARAMETERS or len(respawns) >= MAX_RESPAWNS:
            return False
        respawns.append({'node': name, 'exit_code': code, 'sim_time': sim_time})
        print(f'closed_loop: {name} exited (code {code}) at {sim_time:.1f} s simulated; '
              'starting it again', file=sys.stderr, flush=True)
        children[name] = spawn_node(name, params[name], logs / f'{name}.log', append=True)
    return True


def stop_children(children: list[subprocess.Popen]) -> None:
    """SIGINT the running children; kill those still running after CHILD_EXIT_TIMEOUT."""
    for child in children:
        if child.poll() is None:
            child.send_signal(signal.SIGINT)
    deadline = time.monotonic() + CHILD_EXIT_TIMEOUT
    for child in children:
        try:
            child.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()


class ProcessSample(NamedTuple):
    """What a node process had used at one moment (Linux's /proc)."""

    pid: int
    cpu_seconds: float  # user + system time of the process so far
    rss_mb: float  # resident memory now
    peak_rss_mb: float  # the most resident memory it has had


def process_sample(pid: int) -> ProcessSample | None:
    """Return the process's CPU time and memory from /proc, or None (gone, or not Linux)."""
    try:
        with open(f'/proc/{pid}/stat', encoding='ascii') as f:
            # the fields after the command's parenthesis: utime and stime are 14th and 15th
            fields = f.read().rsplit(')', 1)[1].split()
        with open(f'/proc/{pid}/status', encoding='ascii') as f:
            status = dict(line.split(':', 1) for line in f if ':' in line)
    except (OSError, IndexError, ValueError):
        return None
    ticks = os.sysconf('SC_CLK_TCK')

    def megabytes(key: str) -> float:
        value = status.get(key, '').split()
        return float(value[0]) / 1024.0 if value else math.nan  # kB

    return ProcessSample(pid=pid, cpu_seconds=(int(fields[11]) + int(fields[12])) / ticks,
                         rss_mb=megabytes('VmRSS'), peak_rss_mb=megabytes('VmHWM'))


def node_usage(first: dict[str, tuple[float, float, ProcessSample]],
               last: dict[str, tuple[float, float, ProcessSample]]
               ) -> dict[str, dict[str, float]]:
    """Return per node its share of a core while the robot drove, and its memory.

    first and last map a node to (simulated time, wall time, sample) at the start and the
    end of the measured span. cpu_share is CPU seconds per simulated second: in lockstep the
    simulator waits for the nodes, so this is the part of a core the node's work per second
    of robot time takes (what waits on the wall clock, DDS and polling, is counted per
    simulated second too: more than in real time when the run is slower than real time).
    cpu_per_wall_second is the same CPU per wall second. A node started again in between
    (another pid) is left out.
    """
    usage = {}
    for name, (t0, wall0, a) in first.items():
        if name not in last:
            continue
        t1, wall1, b = last[name]
        if a.pid != b.pid or not t1 > t0 or not wall1 > wall0:
            continue
        cpu = b.cpu_seconds - a.cpu_seconds
        usage[name] = {'cpu_share': cpu / (t1 - t0), 'cpu_per_wall_second': cpu / (wall1 - wall0),
                       'rss_mb': b.rss_mb, 'peak_rss_mb': b.peak_rss_mb,
                       'sim_seconds': t1 - t0, 'wall_seconds': wall1 - wall0}
    return usage
