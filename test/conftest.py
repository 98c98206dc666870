# SPDX-License-Identifier: Apache-2.0
"""Session-wide test setup: isolate ROS 2 discovery before anything imports rclpy.

The environment is set at import time because DDS reads it when the first context is
initialised; pytest imports conftest.py before any test module, hence before rclpy.
Keeping discovery on localhost and using a domain id derived from the pid keeps parallel
test sessions (and other machines) from seeing each other's nodes.

Fixtures: ``ros`` (a fresh context and executor per test; ``ros.probe()`` adds a `Probe` that
publishes inputs and records outputs, diagnostics and /rosout) and ``ros_module`` (the same,
per module). `SimClock` is the one simulated-clock harness: a test's world subclasses it.
"""

from __future__ import annotations

import os

# Domain ids 1..100: 0 is the default everyone else uses, and ids above ~101 collide with
# the ephemeral port range on Linux for some RMW implementations.
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ['ROS_DOMAIN_ID'] = str(1 + os.getpid() % 100)


# ----------------------------------------------------------------------------- rclpy fixtures
# Imported after the environment is set (above): DDS reads it at the first rclpy.init.
import time
from typing import Any, Callable, Iterator, NamedTuple, Sequence

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Twist
from nav_msgs.msg import Odometry, Path
import numpy as np
import pytest
from rcl_interfaces.msg import Log
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock

from mpc_local_planner.core.diagnostics import (
    CONTROLLER_DIAGNOSTICS_TOPIC,
    ControllerDiagnostics,
    PLANNER_DIAGNOSTICS_TOPIC,
    PlannerDiagnostics,
)
from mpc_local_planner.ros.conversions import (
    seconds_to_stamp,
    stamp_to_seconds,
    state_to_odometry,
)
from mpc_local_planner.ros.qos import (
    CMD_VEL_QOS,
    DIAGNOSTICS_QOS,
    GOAL_QOS,
    LOCAL_PLAN_QOS,
    ODOM_QOS,
    PLAN_QOS,
    PLANNER_DIAGNOSTICS_QOS,
)

# /rosout as rclpy publishes it (Jazzy): reliable, transient_local, depth 1000.
ROSOUT_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)


class RosHarness:
    """One rclpy context, a SingleThreadedExecutor on it, and the nodes a test adds."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor

        self.context = Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list = []

    def add(self, node):
        """Spin node with the others; it is destroyed at teardown."""
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def spin_until(self, condition: Callable[[], bool], timeout: float = 10.0) -> bool:
        """Spin until condition() holds or timeout wall seconds pass; return condition()."""
        deadline = time.monotonic() + timeout
        while not condition() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        return condition()

    def settle(self) -> None:
        """Let every node react to what was just published: six short spins (2 ms each)."""
        for _ in range(6):
            self.executor.spin_once(timeout_sec=0.002)

    @staticmethod
    def tick_until(tick: Callable[[], None], condition: Callable[[], bool],
                   timeout: float) -> bool:
        """Tick a test's simulated world until condition() holds or timeout wall seconds pass.

        Returns condition(): the run_until of the tests' simulated worlds.
        """
        deadline = time.monotonic() + timeout
        while not condition() and time.monotonic() < deadline:
            tick()
        return condition()

    def probe(self, *, use_sim_time: bool = False) -> Probe:
        """Create a Probe in this context and spin it with the others."""
        return self.add(Probe(self.context, use_sim_time=use_sim_time))

    def close(self) -> None:
        """Tear down in rclpy's order: executor, nodes, context."""
        import rclpy

        self.executor.shutdown()
        for node in reversed(self.nodes):
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def ros() -> Iterator[RosHarness]:
    """Yield a fresh rclpy context with an executor; tear everything down afterwards."""
    harness = RosHarness()
    try:
        yield harness
    finally:
        harness.close()


@pytest.fixture(scope='module')
def ros_module() -> Iterator[RosHarness]:
    """Like ros, shared by a module's tests (hypothesis runs many examples on one node)."""
    harness = RosHarness()
    try:
        yield harness
    finally:
        harness.close()


class ThrottleClock:
    """The time the nodes' log throttles see, owned by a test: it moves only by `advance`."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t

    def advance(self, seconds: float) -> None:
        self.t += seconds


@pytest.fixture
def throttle_clock(monkeypatch: pytest.MonkeyPatch) -> ThrottleClock:
    """Put every node's ProblemThrottle on a clock the test advances, not on wall time.

    With the clock held, a problem that persists is logged exactly once however long the
    test takes on a loaded machine.
    """
    from mpc_local_planner.ros import throttle
    clock = ThrottleClock()
    monkeypatch.setattr(throttle, 'steady_clock', clock)
    return clock


def point_in_any(
    obstacles: Sequence[Any], points: np.ndarray, *, margin: float = 0.0
) -> np.ndarray:
    """Say, per point, whether it lies in any obstacle grown by margin (a test oracle)."""
    pts = np.atleast_2d(np.asarray(points, dtype=float))
    inside = np.zeros(len(pts), dtype=bool)
    for obstacle in obstacles:
        inside |= obstacle.contains(pts, margin=margin)
    return inside


def flat_parameters(values: dict, prefix: str = '') -> dict[str, Any]:
    """Return a ros__parameters mapping with groups flattened to dotted names (as rclpy)."""
    out: dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, dict):
            out.update(flat_parameters(value, f'{prefix}{key}.'))
        else:
            out[prefix + key] = value
    return out


class SimClock:
    """Simulated time owned by a test: the one harness of the tests' simulated worlds.

    Each `tick` advances ``t`` by ``dt``, calls `publish` (what the test's world publishes at
    the new instant: odometry, scans; a subclass says), publishes /clock and lets every node
    react (`spin`) before the next instant. `run_until` ticks until a condition holds (a
    wall-clock timeout only guards against a hang); `run_for` ticks through a span of
    simulated time.

    Args:
        ros: the harness whose executor is spun.
        probe: the Probe that publishes /clock (made with use_sim_time).
        dt: simulated seconds per tick.

    """

    def __init__(self, ros: RosHarness, probe: Probe, dt: float = 0.05) -> None:
        self.ros, self.probe, self.dt = ros, probe, dt
        self.t = 1.0  # 0 is "no time yet" for a node with use_sim_time

    def publish(self) -> None:
        """Publish what the world publishes at t, before /clock (nothing here)."""

    def spin(self) -> None:
        """Let every node react to the instant (`RosHarness.settle`)."""
        self.ros.settle()

    def tick(self) -> None:
        """Advance time by dt, publish, publish /clock, and let every node react."""
        self.t += self.dt
        self.publish()
        self.probe.publish_clock(self.t)
        self.spin()

    def run_until(self, condition: Callable[[], bool], timeout: float = 30.0) -> bool:
        """Tick until condition() holds or timeout wall seconds pass; return condition()."""
        return self.ros.tick_until(self.tick, condition, timeout)

    def run_for(self, seconds: float) -> None:
        """Tick until `seconds` of simulated time have passed."""
        end = self.t + seconds
        while self.t < end - 1e-9:
            self.tick()


class ReportedStep(NamedTuple):
    """One mpc/diagnostics message as a test reads it: the typed step and its status."""

    step: ControllerDiagnostics
    level: int  # DiagnosticStatus level (0 OK, 1 WARN, 2 ERROR)
    message: str
    stamp: float


class Probe(Node):
    """A test node: publishes what the nodes listen to and keeps what they say.

    What the controller says on mpc/diagnostics is in ``diagnostics`` (`ReportedStep`s), what
    the planner says on planner/diagnostics in ``planner_outcomes``.

    Plans are kept as CDR bytes and deserialised on access (``plans``): a test that sends
    100,000 poses should not spend seconds decoding its own message. Every node's log lines
    come from /rosout (``logs``), and ``publish_clock`` lets a test own simulated time.
    """

    def __init__(self, context, *, use_sim_time: bool = False) -> None:
        super().__init__('probe', context=context, parameter_overrides=[
            Parameter('use_sim_time', value=use_sim_time)])
        self.cmd_pub = self.create_publisher(Twist, 'cmd_vel', CMD_VEL_QOS)
        self.odom_pub = self.create_publisher(Odometry, 'odom', ODOM_QOS)
        self.plan_pub = self.create_publisher(Path, 'plan', PLAN_QOS)
        self.goal_pub = self.create_publisher(PoseStamped, 'goal_pose', GOAL_QOS)
        self.clock_pub = self.create_publisher(Clock, '/clock', 10)
        self.odoms: list[Odometry] = []
        self.cmds: list[Twist] = []
        self.cmd_times: list[float] = []  # the probe's ROS time at each cmd_vel's arrival
        self.raw_plans: list[bytes] = []
        self.local_plans: list[Path] = []
        self.diagnostics: list[ReportedStep] = []
        self.planner_outcomes: list[PlannerDiagnostics] = []
        self.logs: list[Log] = []
        self.create_subscription(Odometry, 'odom', self.odoms.append, ODOM_QOS)
        self.create_subscription(Twist, 'cmd_vel', self._cmd_vel, CMD_VEL_QOS)
        self.create_subscription(Path, 'plan', self.raw_plans.append, PLAN_QOS, raw=True)
        self.create_subscription(Path, 'local_plan', self.local_plans.append, LOCAL_PLAN_QOS)
        self.create_subscription(DiagnosticArray, CONTROLLER_DIAGNOSTICS_TOPIC,
                                 self._diagnostics, DIAGNOSTICS_QOS)
        self.create_subscription(DiagnosticArray, PLANNER_DIAGNOSTICS_TOPIC,
                                 self._planner_diagnostics, PLANNER_DIAGNOSTICS_QOS)
        self.create_subscription(Log, '/rosout', self.logs.append, ROSOUT_QOS)

    @property
    def plans(self) -> list[Path]:
        """The plans received, deserialised."""
        return [deserialize_message(raw, Path) for raw in self.raw_plans]

    def now(self) -> float:
        """The probe's ROS time in seconds (simulated with use_sim_time)."""
        return self.get_clock().now().nanoseconds * 1e-9

    def _cmd_vel(self, msg: Twist) -> None:
        self.cmds.append(msg)
        self.cmd_times.append(self.now())

    def _diagnostics(self, msg: DiagnosticArray) -> None:
        status = msg.status[0]
        self.diagnostics.append(ReportedStep(
            step=ControllerDiagnostics.from_values((kv.key, kv.value) for kv in status.values),
            level=int.from_bytes(status.level, 'little'), message=status.message,
            stamp=stamp_to_seconds(msg.header.stamp)))

    def _planner_diagnostics(self, msg: DiagnosticArray) -> None:
        self.planner_outcomes.append(PlannerDiagnostics.from_values(
            (kv.key, kv.value) for kv in msg.status[0].values))

    def publish_odom(self, state, stamp: float | None = None) -> None:
        """Publish odometry of state (x, y, yaw), stamped now or at stamp (seconds)."""
        when = self.get_clock().now().to_msg() if stamp is None else seconds_to_stamp(stamp)
        self.odom_pub.publish(state_to_odometry(np.asarray(state, dtype=float), np.zeros(2),
                                                stamp=when))

    def publish_clock(self, seconds: float) -> None:
        """Publish simulated time (seconds)."""
        self.clock_pub.publish(Clock(clock=seconds_to_stamp(seconds)))

    def log_lines(self, node: str, level: int | None = None) -> list[str]:
        """Return what node logged (at level, e.g. Log.ERROR, if given), in order."""
        return [entry.msg for entry in self.logs
                if entry.name == node and (level is None or entry.level == level)]


# Modules whose tests run whole closed loops without DDS (rollouts, suites, the benchmark's
# sections, recorded BARN states stepped until the MPC tracks): marked closed_loop. Every
# test not marked dds or closed_loop is marked unit, so `-m unit` is the quick run.
CLOSED_LOOP_MODULES = frozenset({
    'test_controller_real_base.py', 'test_mpc_barn_stalls.py', 'test_rollout.py',
    'test_sensing_suites.py', 'test_evaluate.py', 'test_sweep.py', 'test_experiments.py',
    'test_bench_footprint.py', 'test_bench_rate.py', 'test_bench_cold_start.py',
    'test_bench_peer.py', 'test_mpc_footprint.py', 'test_recovery_barn.py',
})


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark every test by its cost: dds (already marked), closed_loop, or unit."""
    for item in items:
        if item.get_closest_marker('dds') is not None:
            continue
        if item.path.name in CLOSED_LOOP_MODULES:
            item.add_marker(pytest.mark.closed_loop)
        else:
            item.add_marker(pytest.mark.unit)
