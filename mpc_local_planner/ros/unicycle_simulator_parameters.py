# SPDX-License-Identifier: Apache-2.0
"""The unicycle simulator's parameters: their table, their checks, the Reality they describe.

The node (ros/unicycle_simulator_node.py) declares PARAMETERS, refuses values that
validate_simulator_parameters refuses, and builds its robot's imperfections with
reality_from_parameters (closed_loop reports the same Reality).
"""

from __future__ import annotations

from dataclasses import replace
import math
from typing import Any

from mpc_local_planner.core.footprint import FROM_WORLD, parse_footprint
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.ros.parameters import ParameterSpec, range_problem
from mpc_local_planner.sim.localizer import LOCALIZER_NOISE
from mpc_local_planner.sim.physics import mujoco_missing, ODOMETRY_SOURCES, PHYSICS_ROBOTS, PLANTS
from mpc_local_planner.sim.reality import Reality, reality_preset, REALITY_PRESETS

__all__ = ['ACTIVE_CONTACTS_TOPIC', 'CONTACTS_TOPIC', 'MOVING_OBSTACLES_TOPIC',
           'PASSIVE_CONTACTS_TOPIC', 'FROM_PRESET', 'GROUND_TRUTH_TOPIC', 'LOCALIZER_TOPIC',
           'LOCKSTEP_STALLS_TOPIC', 'MAX_SCAN_BEAMS', 'PARAMETERS',
           'REALITY_PARAMETERS', 'SCAN_RANGE_MIN', 'SCAN_TOPIC', 'reality_from_parameters',
           'validate_simulator_parameters']

_MODEL = Unicycle()  # the single source of the saturation defaults
# The topics the simulator publishes besides odom and clock (here, not in the node, so that
# closed_loop can name them without loading the node): the laser, the contact count, and the
# localizer stand-in's, as AMCL's.
SCAN_TOPIC = 'scan'
CONTACTS_TOPIC = 'simulator/contacts'
# Of those, the ones that began with the robot moving and with it standing still (an obstacle
# ran into it), latched like the total.
ACTIVE_CONTACTS_TOPIC = 'simulator/active_contacts'
PASSIVE_CONTACTS_TOPIC = 'simulator/passive_contacts'
# Where the world's moving obstacles are (visualization_msgs/MarkerArray at the scan rate).
MOVING_OBSTACLES_TOPIC = 'simulator/moving_obstacles'
# The TRUE pose and velocity (a referee's view, as Gazebo's p3d plugin gives it), in the
# localizer's global frame: no node of the robot's may read it.
GROUND_TRUTH_TOPIC = 'simulator/ground_truth'
# Where the lockstep clock counts the times it gave up waiting (latched, as the contacts).
LOCKSTEP_STALLS_TOPIC = 'simulator/lockstep_stalls'
LOCALIZER_TOPIC = 'amcl_pose'
# The simulated laser's closest valid reading (m), as a LaserScan's range_min.
SCAN_RANGE_MIN = 0.05
# At most this many beams (a bigger scan is a typo, and would stall every tick).
MAX_SCAN_BEAMS = 10_000
# The one marker of every reality override: -1 = the preset's value (in a pair: per
# component). It is outside every override's range, so 0 always means zero (no noise, no
# lag, exact odometry), and the drift, which may be negative, can say it too.
FROM_PRESET = -1.0
# Overrides of the preset's fields, each: parameter -> Reality field.
_PAIR_OVERRIDES = {'actuator_lag': 'lag', 'acceleration_limits': 'acceleration',
                   'odom_noise_std': 'odom_noise'}
_SCALAR_OVERRIDES = {'command_latency': 'latency', 'scan.noise_std': 'scan_noise',
                     'scan.nan_fraction': 'scan_nan', 'scan.neg_inf_fraction': 'scan_neg_inf',
                     'scan.loss_fraction': 'scan_loss'}
_DRIFT = ('odom_drift.position', 'odom_drift.heading')
# Every parameter that shapes the Reality (a change rebuilds it: see post_parameters_callback).
REALITY_PARAMETERS = frozenset({'reality', 'seed', *_PAIR_OVERRIDES, *_SCALAR_OVERRIDES,
                                *_DRIFT})
# A fraction of beams or scans, < 1 (Reality's rule) with a range's inclusive end.
_FRACTION = (0.0, 0.99)
_PRESET = "-1 = the reality preset's"


PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('initial_pose', [0.0, 0.0, 0.0],
                  'start pose [x, y, theta] (m, m, rad); read once at start'),
    ParameterSpec('rate', 50.0,
                  'integration rate in Hz of simulated time (one step of 1/rate per tick: RK4 '
                  "with ideal reality, else the exact arc of the wheels' velocity)",
                  float_range=(1.0, 1000.0)),
    ParameterSpec('cmd_timeout', 0.5,
                  'a cmd_vel older than this (s of simulated time) is replaced by zero; '
                  '0 = never', float_range=(0.0, 60.0)),
    ParameterSpec('enable_stamped_cmd_vel', False,
                  "subscribe cmd_vel as geometry_msgs/TwistStamped (Nav2's name); false = "
                  'Twist; read once at start', read_only=True),
    ParameterSpec('publish_clock', False,
                  'drive /clock from the simulation (other nodes then use_sim_time)',
                  read_only=True),
    ParameterSpec('real_time_factor', 1.0,
                  'simulated seconds per wall second when publish_clock is true (not with '
                  'lockstep)', float_range=(0.01, 100.0)),
    ParameterSpec('lockstep', False,
                  'with publish_clock: move the clock only when every node of '
                  'lockstep.participants has done its due steps and taken every message (as '
                  'fast as they compute, the same run under any load); read once at start',
                  read_only=True),
    ParameterSpec('lockstep.participants', ['global_planner', 'mpc_controller'],
                  'names of the nodes the lockstep clock waits for (each with its own '
                  'lockstep parameter true)', read_only=True),
    ParameterSpec('lockstep.timeout', 30.0,
                  'wall seconds the lockstep clock waits for one move before it goes on '
                  'without (a participant that died or hangs); each time is logged and '
                  'counted on simulator/lockstep_stalls', float_range=(0.01, 3600.0)),
    ParameterSpec('v_max', _MODEL.v_max, 'saturation of |linear.x| (m/s)',
                  float_range=(0.001, 10.0)),
    ParameterSpec('omega_max', _MODEL.omega_max, 'saturation of |angular.z| (rad/s)',
                  float_range=(0.001, 50.0)),
    ParameterSpec('odom_frame', 'odom', 'frame of odom (its header.frame_id)'),
    ParameterSpec('robot_base_frame', 'base_link',
                  "robot frame: odom's child_frame_id and the frame of scan (Nav2's name)"),
    ParameterSpec('world_file', '',
                  'the TRUE world (known and unknown obstacles) the laser sees and the robot '
                  "can touch: a path, or a name in the package's config/ or config/worlds/; "
                  "'' = an empty world; read once at start", read_only=True),
    ParameterSpec('robot_radius', FROM_WORLD,
                  "radius of the robot's disk for contacts (m) when no polygon footprint "
                  "applies; -1 = the world file's robot_radius (0 without one); a radius >= 0 "
                  "is the robot's, smaller than the world's too",
                  float_range=(0.0, 10.0), special=FROM_WORLD),
    ParameterSpec('footprint', '',
                  'the robot\'s convex polygon for contacts, Nav2\'s form "[[x, y], ...]" in '
                  "the robot frame (x forward); '' or '[]' = the world file's footprint if it "
                  'has one, else the circle of robot_radius. Precedence: this parameter, then '
                  "the world's footprint, then robot_radius"),
    ParameterSpec('scan.rate', 10.0,
                  'laser scans per second of simulated time (at most one per tick, so at '
                  'most rate)', float_range=(0.01, 1000.0)),
    ParameterSpec('scan.fov', 4.71,
                  'field of view (rad), at most 2 pi: angle_min = -fov / 2, '
                  'angle_increment = fov / (beams - 1)', float_range=(0.001, 2.0 * math.pi)),
    ParameterSpec('scan.beams', 720, 'beams per scan', int_range=(2, MAX_SCAN_BEAMS)),
    ParameterSpec('scan.range_max', 10.0,
                  f'farthest reading (m; range_min is {SCAN_RANGE_MIN}); beyond it a beam '
                  'reads inf', float_range=(0.1, 1000.0)),
    ParameterSpec('scan.noise_std', FROM_PRESET,
                  f'standard deviation of the Gaussian range noise (m); {_PRESET} (ideal: '
                  'none)', float_range=(0.0, 10.0), special=FROM_PRESET),
    ParameterSpec('odom_drift.position', FROM_PRESET,
                  "odometry's distance error as a fraction of the distance travelled (0.05 = "
                  f'5 %: the odometry says 1.05 m per true metre; 0 = exact); {_PRESET} '
                  '(ideal: exact)', float_range=(-0.5, 0.5), special=FROM_PRESET),
    ParameterSpec('odom_drift.heading', FROM_PRESET,
                  "odometry's heading error per metre travelled (rad/m; 0 = exact); "
                  f'{_PRESET} (ideal: exact)', float_range=(-0.5, 0.5), special=FROM_PRESET),
    ParameterSpec('reality', 'ideal',
                  'how real the robot and its laser are, a preset of sim/reality.py: '
                  f'{"|".join(REALITY_PRESETS)} (ideal: commands act at once and exactly, '
                  'odometry is the pose, the laser is exact); the parameters below and '
                  "scan.noise_std, odom_drift.* and scan.*_fraction override single fields, "
                  "each -1 (its default) for the preset's, 0 for none"),
    ParameterSpec('seed', 0,
                  "seed of the simulated reality's random draws, the base's (odometry noise) "
                  "and, on a stream of their own, the laser's (range noise, NaN and -inf "
                  'beams, lost scans): runs are reproducible; the base reads it once at start, '
                  "the laser at each change (the localizer has localizer.seed)",
                  int_range=(0, 2**31 - 1)),
    ParameterSpec('actuator_lag', [FROM_PRESET, FROM_PRESET],
                  'first-order time constants [v, omega] (s) of the wheels following the '
                  f'command (0 = at once); {_PRESET}', float_range=(0.0, 10.0),
                  special=FROM_PRESET),
    ParameterSpec('acceleration_limits', [FROM_PRESET, FROM_PRESET],
                  'limits of |dv/dt| (m/s^2) and |domega/dt| (rad/s^2) (.inf = none); '
                  f'{_PRESET}', float_range=(0.01, math.inf), special=FROM_PRESET),
    ParameterSpec('command_latency', FROM_PRESET,
                  'seconds from a cmd_vel to its reaching the motors (simulated time); '
                  f'{_PRESET}', float_range=(0.0, 10.0), special=FROM_PRESET),
    ParameterSpec('odom_noise_std', [FROM_PRESET, FROM_PRESET],
                  'standard deviations [m, rad] of the white noise on each published odometry '
                  f'pose; {_PRESET}', float_range=(0.0, 10.0), special=FROM_PRESET),
    ParameterSpec('scan.nan_fraction', FROM_PRESET,
                  f'fraction of beams that read NaN; {_PRESET}', float_range=_FRACTION,
                  special=FROM_PRESET),
    ParameterSpec('scan.neg_inf_fraction', FROM_PRESET,
                  f'fraction of beams that read -inf (too close); {_PRESET}',
                  float_range=_FRACTION, special=FROM_PRESET),
    ParameterSpec('scan.loss_fraction', FROM_PRESET,
                  f'fraction of scans that are never published; {_PRESET}',
                  float_range=_FRACTION, special=FROM_PRESET),
    ParameterSpec('localizer.rate', 0.0,
                  f'publish the true pose with noise on {LOCALIZER_TOPIC} this often (Hz of '
                  'simulated time, at most one per tick), a stand-in for AMCL; 0 = off',
                  float_range=(0.0, 1000.0)),
    ParameterSpec('localizer.noise_std', LOCALIZER_NOISE,
                  "standard deviation of the localizer's Gaussian noise (m, and rad for the "
                  'heading)', float_range=(0.0, 10.0)),
    ParameterSpec('localizer.global_frame', 'map',
                  "frame of the localizer's poses (Nav2's name for the map frame)"),
    ParameterSpec('localizer.seed', 0, "seed of the localizer's noise",
                  int_range=(0, 2**31 - 1)),
    ParameterSpec('plant', 'kinematic',
                  f'the robot\'s plant: {"|".join(PLANTS)}; kinematic = the unicycle as '
                  'real as reality says; mujoco = a rigid body with wheels (sim/physics/: '
                  "torque-limited servos, slip, diff_drive_controller's limits, timeout and "
                  'wheel odometry, the laser cast by the engine; of reality only the command '
                  "latency, odometry noise and the laser's faults apply; needs the [physics] "
                  'extra); its bumper is the footprint at start; read once at start',
                  read_only=True),
    ParameterSpec('physics.robot', 'jackal',
                  f'the robot the mujoco plant simulates: {"|".join(PHYSICS_ROBOTS)} '
                  "(the Jackal's four wheels skid-steer; small: the paper's two-wheeled robot); "
                  'read once at start', read_only=True),
    ParameterSpec('physics.odometry', 'fused',
                  f'what the mujoco plant\'s odometry integrates: {"|".join(ODOMETRY_SOURCES)}; '
                  "fused = the wheels' distance and a gyro's heading, as the robots' stacks "
                  "fuse their IMU (the Jackal's robot_localization EKF); wheels = "
                  "diff_drive_controller's wheel odometry alone (a skid-steer's drifts in "
                  'heading); read once at start', read_only=True),
)


_SPECS = {spec.name: spec for spec in PARAMETERS}


def validate_simulator_parameters(values: dict[str, Any]) -> str | None:
    """Return why the simulator's parameter values are invalid, or None.

    Each value is held to its range (the table's, as the node enforces it on every set),
    so that values given without a node (closed_loop's) are judged alike.
    """
    pose = values.get('initial_pose')
    if pose is not None:
        pose = list(pose)
        if len(pose) != 3 or not all(math.isfinite(float(v)) for v in pose):
            return f'initial_pose must be [x, y, theta] (3 finite numbers), got {pose}'
    for name in ('scan.fov', 'scan.range_max'):
        value = values.get(name)
        if value is not None and not _is_number(value):
            return f'{name} must be a number, got {value!r}'
    for name in ('scan.beams', 'seed'):
        value = values.get(name)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int)):
            return f'{name} must be an integer, got {value!r}'
    for name in ('robot_radius', 'scan.fov', 'scan.beams', 'scan.range_max', 'seed'):
        reason = range_problem(_SPECS[name], values[name]) if name in values else None
        if reason is not None:
            return reason
    plant = values.get('plant')
    if plant is not None:
        if plant not in PLANTS:
            return f'plant must be one of {"|".join(PLANTS)}, got {plant!r}'
        if plant == 'mujoco' and mujoco_missing() is not None:
            return f'plant mujoco: {mujoco_missing()}'
    robot = values.get('physics.robot')
    if robot is not None and robot not in PHYSICS_ROBOTS:
        return f'physics.robot must be one of {"|".join(PHYSICS_ROBOTS)}, got {robot!r}'
    odometry = values.get('physics.odometry')
    if odometry is not None and odometry not in ODOMETRY_SOURCES:
        return (f'physics.odometry must be one of {"|".join(ODOMETRY_SOURCES)}, '
                f'got {odometry!r}')
    footprint = values.get('footprint')
    if footprint is not None:
        if not isinstance(footprint, str):
            return f'footprint must be a string "[[x, y], ...]", got {footprint!r}'
        try:
            parse_footprint(footprint)
        except ValueError as err:
            return f'footprint: {err}'
    return _validate_reality_parameters(values)


def _is_number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and not math.isnan(
        float(value))


def _validate_reality_parameters(values: dict[str, Any]) -> str | None:
    """Return why a reality parameter is invalid on its own, or None (see PARAMETERS).

    Each override is a number (a pair: two), -1 for the preset's or within its range.
    Combinations (scan.nan_fraction + scan.neg_inf_fraction < 1 with the preset's values
    filled in) are Reality's to check: reality_from_parameters.
    """
    name = values.get('reality')
    if name is not None and (not isinstance(name, str) or name not in REALITY_PRESETS):
        return (f'reality must be one of {"|".join(REALITY_PRESETS)} (sim/reality.py), '
                f'got {name!r}')
    for key in _PAIR_OVERRIDES:
        value = values.get(key)
        if value is None:
            continue
        pair = list(value) if isinstance(value, (list, tuple)) else None
        if pair is None or len(pair) != 2 or not all(_is_number(v) for v in pair):
            return f'{key} must be two numbers, got {value!r}'
        reason = range_problem(_SPECS[key], pair)
        if reason is not None:
            return reason
    for key in (*_SCALAR_OVERRIDES, *_DRIFT):
        value = values.get(key)
        if value is None:
            continue
        if not _is_number(value):
            return f'{key} must be a number, got {value!r}'
        reason = range_problem(_SPECS[key], value)
        if reason is not None:
            return reason
    return None


def reality_from_parameters(values: dict[str, Any]) -> Reality:
    """Return the Reality the simulator's parameter values describe.

    The preset named by ``reality`` (default 'ideal'), with each override that is set taking
    the place of the preset's field; FROM_PRESET (-1, the overrides' default; in a pair, per
    component) means "the preset's", and 0 means zero. ``seed`` is the seed. Missing
    names are the preset's.

    Raises:
        ValueError: for an unknown preset, or values Reality refuses (the reason says which).

    """
    reason = _validate_reality_parameters(values)
    if reason is not None:
        raise ValueError(reason)
    preset = reality_preset(str(values.get('reality', 'ideal')))
    changes: dict[str, Any] = {}
    for key, attribute in _PAIR_OVERRIDES.items():
        value = values.get(key)
        if value is not None:
            changes[attribute] = tuple(
                old if float(v) == FROM_PRESET else float(v)
                for v, old in zip(value, getattr(preset, attribute), strict=True))
    for key, attribute in _SCALAR_OVERRIDES.items():
        value = values.get(key)
        if value is not None and float(value) != FROM_PRESET:
            changes[attribute] = float(value)
    drift = list(preset.odom_drift)
    for i, key in enumerate(_DRIFT):
        value = values.get(key)
        if value is not None and float(value) != FROM_PRESET:
            drift[i] = float(value)
    changes['odom_drift'] = tuple(drift)
    changes['seed'] = int(values.get('seed', 0))
    try:
        return replace(preset, **changes)  # Reality.__post_init__ checks the whole
    except ValueError as err:
        msg = (f"reality {values.get('reality', 'ideal')!r} with its overrides: {err} "
               '(scan_nan = scan.nan_fraction, scan_neg_inf = scan.neg_inf_fraction)')
        raise ValueError(msg) from None
