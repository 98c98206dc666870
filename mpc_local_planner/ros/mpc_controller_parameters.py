# SPDX-License-Identifier: Apache-2.0
"""The mpc_controller node's parameters: their table, and what their values mean.

`PARAMETERS` declares them (and `mpc_controller --help` lists them; config/mpc_controller.yaml
mirrors the defaults, which come from the core's dataclasses); `build_settings` turns their
values into the MPC's, the model's and the controller's settings, with Nav2's precedence for
the robot's shape (`robot_footprint`); `check_obstacles` and `check_sensing` refuse values
the node could not use, with the reason, before they are set.

The base's rate limits ``max_accel`` and ``max_decel`` (Nav2 velocity_smoother's names, here
[v, omega] in m/s^2 and rad/s^2) are double arrays, and a ROS double array cannot be None:
[0.0, 0.0] (`RATE_LIMIT_OFF`) means none (MpcConfig.max_accel None; ControllerSettings.max_decel
inf, a stop commands zero at once). Anything else must be two finite numbers > 0, given as
magnitudes (Nav2's velocity_smoother writes max_decel negative; a negative value is refused
here rather than guessed at).
"""

from __future__ import annotations

import math
from typing import Any

from mpc_local_planner.core.config import (
    INPUT_HOLDS,
    MpcConfig,
    OBSTACLE_SOURCES,
    SOLVERS,
    SolverSettings,
)
from mpc_local_planner.core.controller_settings import ControllerSettings
from mpc_local_planner.core.footprint import Footprint, FROM_WORLD, radius_in_force, resolve
from mpc_local_planner.core.models import Unicycle
from mpc_local_planner.core.obstacles import ConvexPolygon
from mpc_local_planner.core.recoveries import Recoveries, RecoverySettings
from mpc_local_planner.ros.lockstep import LOCKSTEP_PARAMETER
from mpc_local_planner.ros.parameters import ParameterSpec
from mpc_local_planner.ros.robot_pose import pose_parameters
from mpc_local_planner.worlds.data_files import resolve_data_file
from mpc_local_planner.worlds.world import load_world

__all__ = ['BASE_FRAME', 'DEFAULTS', 'PARAMETERS', 'RATE_LIMIT_OFF', 'RECOVERY_PARAMETERS',
           'build_recoveries', 'build_settings', 'check_obstacles', 'check_sensing',
           'load_robot', 'rate_limit', 'robot_footprint']

# The frame of a TwistStamped cmd_vel.
BASE_FRAME = 'base_link'
# Parameter -> field of MpcConfig, its SolverSettings, Unicycle and ControllerSettings (the
# parameters are flat: one namespace, whichever dataclass a field lives in).
_MPC_FIELDS = {
    'horizon': 'horizon', 'step': 'step', 'weights.position': 'weight_position',
    'weights.heading': 'weight_heading', 'weights.v': 'weight_v', 'weights.omega': 'weight_omega',
    'offset_weight': 'offset_weight', 'robot_radius': 'robot_radius',
    'input_hold': 'input_hold',
}
_SOLVER_FIELDS = ('solver', 'max_iterations', 'obstacle_slots', 'budget')
_MODEL_FIELDS = ('v_max', 'omega_max')
_SETTINGS_FIELDS = ('xy_goal_tolerance', 'yaw_goal_tolerance', 'odom_timeout',
                    'scan_timeout', 'control_frequency', 'actuation_delay')
# collision_margin None (v_max step / 2) is -1 as a parameter: a double cannot be None.
_AUTO_MARGIN = -1.0
# max_accel / max_decel of [0.0, 0.0]: no limit (a double array cannot be None).
RATE_LIMIT_OFF = (0.0, 0.0)
# Each limit of max_accel / max_decel (m/s^2, rad/s^2), or 0 (both: no limit).
_RATE_LIMIT = (0.01, 1000.0)
# The defaults come from the dataclasses (the paper's values), the single source.
_CONFIG, _MODEL, _SETTINGS = MpcConfig(), Unicycle(), ControllerSettings()
_RECOVERY = RecoverySettings()
_SHAPE = 'changes the NLP shape: rebuilt before the next solve'
_WEIGHT = (0.0, 1e6)

# The node's parameters: declared from this table, and listed by ``mpc_controller --help``
# (config/mpc_controller.yaml mirrors the defaults).
PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('horizon', int(_CONFIG.horizon), f'prediction steps N; {_SHAPE}',
                  int_range=(1, 200)),
    ParameterSpec('step', float(_CONFIG.step),
                  f'sampling time h (s of ROS time): the MPC solves once per step; {_SHAPE}',
                  float_range=(0.01, 5.0)),
    ParameterSpec('control_frequency', float(_SETTINGS.control_frequency),
                  "cmd_vel per second (Hz of ROS time; Nav2's controller_server name): the "
                  'control timer runs at this rate, independent of step; between solves '
                  "each tick applies the last verified plan's input after every safety "
                  'check (1 / step or less: every tick solves); restarts the timer',
                  float_range=(0.1, 1000.0)),
    ParameterSpec('max_accel', list(RATE_LIMIT_OFF),
                  "the base's acceleration limits [v, omega] (m/s^2, rad/s^2; Nav2 "
                  "velocity_smoother's name): the NLP bounds each input change by "
                  "max_accel step, so the plan is one the base can follow; [0.0, 0.0] = "
                  "none (inputs may jump, the paper's model; config/jackal.yaml turns "
                  f"it on for a Jackal); {_SHAPE}", float_range=_RATE_LIMIT, special=0.0),
    ParameterSpec('input_hold', str(_CONFIG.input_hold),
                  f"how an input acts over a step, one of {INPUT_HOLDS}: 'zero' holds it "
                  "(the paper's model: the velocity jumps at each sample); 'first_order' "
                  'ramps the velocity linearly from the input before (needs max_accel: then '
                  'an acceleration bound the base can follow at its own limits, and the '
                  'predictions match a lagging base; config/jackal.yaml turns it on); '
                  f'{_SHAPE}'),
    ParameterSpec('actuation_delay', float(_SETTINGS.actuation_delay),
                  "with input_hold 'first_order': how far ahead of now the plan's velocity "
                  "ramp is commanded (s): the base's command latency plus its lag's time "
                  'constant, so that the velocity it reaches is the predicted one; ignored '
                  'with a zero hold; next control tick', float_range=(0.0, 5.0)),
    ParameterSpec('max_decel', list(RATE_LIMIT_OFF),
                  "the base's deceleration limits [v, omega] (m/s^2, rad/s^2, magnitudes; "
                  "Nav2 velocity_smoother's name): a stop of a moving robot (stale or "
                  'invalid input, a failure) brakes along the last verified plan within '
                  'them instead of commanding zero at once, which a real base cannot '
                  'follow; [0.0, 0.0] = none (zero at once); next control tick',
                  float_range=_RATE_LIMIT, special=0.0),
    ParameterSpec('v_max', float(_MODEL.v_max),
                  'speed bound |v| (m/s); rebuilds the NLP before the next solve',
                  float_range=(0.001, 10.0)),
    ParameterSpec('omega_max', float(_MODEL.omega_max),
                  'turn-rate bound |omega| (rad/s); rebuilds the NLP', float_range=(0.001, 50.0)),
    ParameterSpec('allow_reversing', _MODEL.v_min is None or _MODEL.v_min < 0.0,
                  "may drive backwards (v down to -v_max; false: v >= 0, as DWB's "
                  'min_vel_x = 0). Set false when the laser does not see behind the robot (a '
                  "Jackal's sees 270 degrees): backwards it would drive where it never looked; "
                  'next solve'),
    ParameterSpec('weights.position', float(_CONFIG.weight_position),
                  'stage weight of dx^4 and dy^4; next solve', float_range=_WEIGHT),
    ParameterSpec('weights.heading', float(_CONFIG.weight_heading),
                  'stage weight of dtheta^4; next solve', float_range=_WEIGHT),
    ParameterSpec('weights.v', float(_CONFIG.weight_v), 'stage weight of v^4; next solve',
                  float_range=_WEIGHT),
    ParameterSpec('weights.omega', float(_CONFIG.weight_omega),
                  'stage weight of omega^4; next solve', float_range=_WEIGHT),
    ParameterSpec('offset_weight', float(_CONFIG.offset_weight),
                  'offset cost weight of (1 - s)^2; next solve', float_range=(1e-6, 1e9)),
    ParameterSpec('robot_radius', FROM_WORLD,
                  "the round robot's radius (m), obstacles are inflated by it and scan "
                  "returns within it are the robot itself (ignored); -1 = the world file's "
                  "robot_radius (0 without one); a radius >= 0 is the robot's, smaller than "
                  "the world's too; ignored when a polygon footprint applies",
                  float_range=(0.0, 10.0), special=FROM_WORLD),
    ParameterSpec('footprint', '',
                  "the robot's convex polygon in base_link (x forward), Nav2's form "
                  "\"[[x, y], [x, y], ...]\"; the MPC separates it from each obstacle exactly; "
                  "'' = the world file's footprint if it has a polygon, else a circle of "
                  f'robot_radius; {_SHAPE}'),
    ParameterSpec('collision_margin',
                  _AUTO_MARGIN if _CONFIG.collision_margin is None
                  else float(_CONFIG.collision_margin),
                  'extra inflation (m) against corner cutting between samples; '
                  '-1 = v_max step / 2', float_range=(-1.0, 10.0)),
    ParameterSpec('max_solve_time', _AUTO_MARGIN,
                  "wall-time budget (s) of one control step's solving; past it the verified "
                  'shifted candidate is applied (counted in timeouts_total); -1 = step / 2',
                  float_range=(-1.0, 60.0)),
    ParameterSpec('budget', str(_CONFIG.solving.budget),
                  "what bounds a control step's solving: 'wall' (max_solve_time, a robot's) or "
                  "'iterations' (the iterations max_solve_time is worth at 1 ms each: the same "
                  'commands under any load, for lockstep simulation and evaluation)'),
    ParameterSpec('world_file', '',
                  "world YAML/JSON with the obstacles (a path, or a name in the package's "
                  "config/ or config/worlds/); '' = none; read again at each configure"),
    ParameterSpec('analytic_path', '',
                  "follow this analytic path (e.g. 'paper_sinusoid') instead of the plan "
                  "topic; '' = use plan"),
    ParameterSpec('solver', str(_CONFIG.solving.solver), f'NLP solver, one of {SOLVERS}'),
    ParameterSpec('max_iterations', int(_CONFIG.solving.max_iterations),
                  f'solver iterations per solve; {_SHAPE}', int_range=(1, 100000)),
    ParameterSpec('obstacle_slots', int(_CONFIG.solving.obstacle_slots),
                  'the most obstacles one solve holds, the nearest (its solution is checked '
                  'against all in reach): the NLPs for 0..this many are built with each plan, '
                  'so that no control step builds one; a change rebuilds them as steps need '
                  'them', int_range=(0, 64)),
    ParameterSpec('xy_goal_tolerance', float(_SETTINGS.xy_goal_tolerance),
                  "distance to the end of the plan that counts as arrived (m; Nav2's name): "
                  'there the robot turns in place to the goal heading, and arrived cmd_vel is '
                  'zero', float_range=(1e-4, 10.0)),
    ParameterSpec('yaw_goal_tolerance', float(_SETTINGS.yaw_goal_tolerance),
                  "heading error that counts as arrived (rad; Nav2's name)",
                  float_range=(1e-4, math.pi)),
    ParameterSpec('stateful', bool(_SETTINGS.stateful),
                  "as Nav2's SimpleGoalChecker: the position met stays met, and arrived "
                  'cmd_vel stays zero until a new plan, even if the odometry drifts out; '
                  'false: a pose drifting out is driven back'),
    ParameterSpec('odom_timeout', float(_SETTINGS.odom_timeout),
                  'odometry older than this (s) is stale: cmd_vel is zero',
                  float_range=(0.001, 3600.0)),
    ParameterSpec('max_plan_poses', int(_SETTINGS.max_plan_poses),
                  'a plan with more poses is refused (cmd_vel is zero until a valid plan '
                  'comes)', int_range=(2, 10_000_000)),
    ParameterSpec('global_frame', 'map',
                  'frame of local_plan, mpc/obstacles and mpc/footprint, and the frame a plan '
                  'must be in'),
    ParameterSpec('obstacle_sources', ['world'],
                  "what the controller avoids, any of 'world' (world_file's obstacles), "
                  "'scan' (the laser, remembered for obstacle_memory s) and 'map' (the map's "
                  'occupied cells near the robot); read at configure'),
    ParameterSpec('laser_pose', [0.0, 0.0, 0.0],
                  "the laser's [x, y, yaw] in the robot frame (m, m, rad); next scan"),
    ParameterSpec('obstacle_memory', 5.0,
                  'seconds an obstacle seen by the laser is remembered (unless a later beam '
                  'passes through it); next scan', float_range=(0.01, 3600.0)),
    ParameterSpec('track_moving', False,
                  "with 'scan' a source, follow the scan's small clusters over time (a "
                  'Kalman filter per track); a moving one reaches the MPC as a disc with '
                  'its velocity, predicted over the horizon, instead of the pieces it built, '
                  'so that a walker leaves no trail; mpc/tracks shows the tracks '
                  '(perception/tracking.py, docs/real_robot.md); false: the world is taken '
                  'as static; read at configure'),
    ParameterSpec('scan_timeout', float(_SETTINGS.scan_timeout),
                  "with 'scan' a source, a scan older than this (s) is stale: cmd_vel is zero "
                  '(and before the first scan)', float_range=(0.001, 3600.0)),
    ParameterSpec('robot_base_frame', BASE_FRAME,
                  'the robot frame: scans must be in it (laser_pose says where the laser '
                  'sits), and a TwistStamped cmd_vel is in it'),
    ParameterSpec('recoveries', True,
                  'a robot that makes no progress for recovery_stuck_timeout backs out along '
                  'its own trail (forward-only robots: allow_reversing false), spins to clear '
                  'the view and waits for a re-plan (core/recoveries.py; Nav2 BackUp, Spin, '
                  "Wait); false: cmd_vel is always the MPC's; next step"),
    ParameterSpec('recovery_stuck_timeout', float(_RECOVERY.stuck_timeout),
                  's without progress (recovery_progress_radius moved or 0.5 rad turned) '
                  "before a recovery; longer than the planner's progress_timeout, so its "
                  'no-progress re-plan comes first; next step', float_range=(0.1, 3600.0)),
    ParameterSpec('recovery_progress_radius', float(_RECOVERY.progress_radius),
                  'metres that count as progress; next step', float_range=(0.01, 10.0)),
    ParameterSpec('recovery_back_out_distance', float(_RECOVERY.back_out_max),
                  'metres a back-out along the trail may go at most (it stops sooner where '
                  'a turn in place is possible); next step', float_range=(0.01, 10.0)),
    ParameterSpec('recovery_back_out_speed', float(_RECOVERY.back_out_speed),
                  'reverse speed of a back-out, m/s (capped by v_max); next step',
                  float_range=(0.01, 10.0)),
    ParameterSpec('recovery_max_tries', int(_RECOVERY.max_tries),
                  'recoveries per goal at most; next step', int_range=(0, 1000)),
    ParameterSpec('enable_stamped_cmd_vel', False,
                  'publish cmd_vel as geometry_msgs/TwistStamped (frame base_link) instead of '
                  "Twist (Nav2's name); read at configure"),
    *pose_parameters('the controller stops (no_localization)'),
    LOCKSTEP_PARAMETER,
    ParameterSpec('autostart', True,
                  'configure and activate at start; false = wait for a lifecycle manager '
                  '(or ros2 lifecycle set)', read_only=True),
)

# The recovery behaviours' parameters (a change rebuilds them; the trail starts again).
RECOVERY_PARAMETERS = frozenset(spec.name for spec in PARAMETERS
                                if spec.name.startswith('recover'))
# Parameter defaults by name.
DEFAULTS: dict[str, Any] = {spec.name: spec.default for spec in PARAMETERS}


def rate_limit(name: str, value: Any) -> tuple[float, float] | None:
    """Return a max_accel / max_decel parameter as limits, or None for RATE_LIMIT_OFF.

    Raises:
        ValueError: unless it is [0.0, 0.0] or two finite numbers > 0, with the reason.

    """
    try:
        limits = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        limits = ()
    if limits == RATE_LIMIT_OFF:
        return None
    if len(limits) != 2 or not all(math.isfinite(v) and v > 0 for v in limits):
        msg = (f'{name} must be [v, omega], two finite numbers > 0 (m/s^2, rad/s^2, '
               f'magnitudes), or [0.0, 0.0] for none; got {list(value)}')
        raise ValueError(msg)
    return limits  # type: ignore[return-value]  # two floats, checked above


def load_robot(world_file: str) -> tuple[list[ConvexPolygon], Footprint]:
    """Return the obstacles and the robot's footprint of a world file.

    '' means no world: no obstacles and a circle of radius 0 (the parameters decide).
    """
    if not world_file:
        return [], Footprint.circle(0.0)
    world = load_world(resolve_data_file(world_file))
    return list(world.obstacles), world.footprint


def robot_footprint(parameter: str, world_footprint: Footprint | None = None
                    ) -> tuple[tuple[float, float], ...]:
    """Return the polygon the footprint parameter and the world give (() for a circle).

    Nav2's precedence, as the simulator and the planner apply it: the parameter's polygon,
    else the world's polygon, else a round robot (robot_radius).

    Raises:
        ValueError: the parameter is not Nav2's "[[x, y], ...]" form of a convex polygon,
            with the reason (too few vertices, not convex, ...).

    """
    shape = resolve(str(parameter), world_footprint=world_footprint)
    if shape.is_circle:
        return ()
    return tuple((float(x), float(y)) for x, y in shape.vertices)


def build_settings(values: dict[str, Any], *, world_radius: float = 0.0,
                   world_footprint: Footprint | None = None
                   ) -> tuple[MpcConfig, Unicycle, ControllerSettings]:
    """Turn parameter values into the controller's settings.

    The robot radius in force is the parameter's, or the world's for -1 (radius_in_force);
    the footprint is the parameter's polygon, else the world's polygon, else that circle
    (see robot_footprint).

    Raises:
        ValueError: with every reason the values are invalid (validate_solver_settings' and
            validate_mpc_config's rules, the footprint's, the model's and the controller's).

    """
    mpc_kwargs = {field: values[name] for name, field in _MPC_FIELDS.items()}
    mpc_kwargs['horizon'] = int(mpc_kwargs['horizon'])
    solver_kwargs = {name: values[name] for name in _SOLVER_FIELDS}
    solver_kwargs['max_iterations'] = int(solver_kwargs['max_iterations'])
    solver_kwargs['obstacle_slots'] = int(solver_kwargs['obstacle_slots'])
    for key in ('step', 'weight_position', 'weight_heading', 'weight_v', 'weight_omega',
                'offset_weight'):
        mpc_kwargs[key] = float(mpc_kwargs[key])
    margin = float(values['collision_margin'])
    mpc_kwargs['collision_margin'] = None if margin < 0 else margin
    budget = float(values['max_solve_time'])
    solver_kwargs['max_solve_time'] = None if budget <= 0 else budget
    mpc_kwargs['robot_radius'] = radius_in_force(float(values['robot_radius']), world_radius)
    mpc_kwargs['footprint'] = robot_footprint(values['footprint'], world_footprint)
    mpc_kwargs['max_accel'] = rate_limit('max_accel', values['max_accel'])
    decel = rate_limit('max_decel', values['max_decel'])
    # each raises ValueError with its validator's reasons; both are collected
    problems: list[str] = []
    try:
        solving = SolverSettings(**solver_kwargs)
    except ValueError as err:
        problems.append(str(err))
        solving = SolverSettings()
    try:
        config = MpcConfig(**mpc_kwargs, solving=solving)
    except ValueError as err:
        problems.append(str(err))
    if problems:
        raise ValueError('; '.join(problems))
    model = Unicycle(**{name: float(values[name]) for name in _MODEL_FIELDS},
                     v_min=None if values['allow_reversing'] else 0.0)
    settings = ControllerSettings(**{k: float(values[k]) for k in _SETTINGS_FIELDS},
                                  stateful=bool(values['stateful']),
                                  max_plan_poses=int(values['max_plan_poses']),
                                  max_decel=(math.inf, math.inf) if decel is None else decel)
    return config, model, settings


def build_recoveries(values: dict[str, Any], config: MpcConfig,
                     model: Unicycle) -> Recoveries:
    """Return the recovery behaviours the values set up for this robot's shape and limits.

    A robot that may reverse (allow_reversing) does not back out: its MPC plans backwards.
    """
    settings = RecoverySettings(
        enabled=bool(values['recoveries']),
        stuck_timeout=float(values['recovery_stuck_timeout']),
        progress_radius=float(values['recovery_progress_radius']),
        back_out=not bool(values['allow_reversing']),
        back_out_max=float(values['recovery_back_out_distance']),
        back_out_speed=float(values['recovery_back_out_speed']),
        max_tries=int(values['recovery_max_tries']))
    return Recoveries(config.robot_footprint, v_max=model.v_max, omega_max=model.omega_max,
                      settings=settings)


def check_obstacles(obstacles: list[ConvexPolygon], config: MpcConfig) -> None:
    """Raise ValueError if an obstacle has more faces than the NLP's slots hold.

    The MPC would raise the same from set_obstacles, but in the post-set callback, where
    the change can no longer be refused.
    """
    for index, obstacle in enumerate(obstacles):
        if obstacle.num_faces > config.solving.faces_per_obstacle:
            msg = (f'obstacle {index} has {obstacle.num_faces} faces, more than '
                   f'faces_per_obstacle ({config.solving.faces_per_obstacle})')
            raise ValueError(msg)


def check_sensing(values: dict[str, Any]) -> None:
    """Raise ValueError if obstacle_sources or laser_pose is not usable.

    obstacle_sources must list only OBSTACLE_SOURCES (each at most once); laser_pose must be
    three finite numbers; track_moving needs 'scan' among the sources (else it would track
    nothing, silently).
    """
    sources = list(values['obstacle_sources'])
    unknown = [s for s in sources if s not in OBSTACLE_SOURCES]
    if unknown:
        msg = f'obstacle_sources: unknown {unknown}, expected any of {list(OBSTACLE_SOURCES)}'
        raise ValueError(msg)
    if len(set(sources)) != len(sources):
        msg = f'obstacle_sources lists a source twice: {sources}'
        raise ValueError(msg)
    pose = list(values['laser_pose'])
    if len(pose) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v)
                                 for v in pose):
        msg = f'laser_pose must be three finite numbers [x, y, yaw], got {pose}'
        raise ValueError(msg)
    if values.get('track_moving') and 'scan' not in sources:
        msg = f"track_moving needs 'scan' in obstacle_sources, got {sources}"
        raise ValueError(msg)
