# SPDX-License-Identifier: Apache-2.0
"""Recoveries for a robot that makes no progress: back out along its own trail, spin, wait.

The paper's guarantee holds for a path the robot can follow; it does not cover a
forward-only robot that the laser let into a pocket it cannot turn in (through the nodes on
the MuJoCo Jackal, BARN 227 and 283 ended so: standing, no verified forward plan from there,
every no-progress re-plan the same). Nav2 answers this with recovery behaviours that its
behaviour tree runs for every controller (BackUp, Spin, Wait); so does this module, for
every `LocalController`, in core, so that the controller node and the suites run one rule.

**When.** The robot is stuck when, while its controller answers with a plan to follow
(TRACKING, CANDIDATE, or STOP: not a missing input, not the goal), it has neither moved
``progress_radius`` nor turned ``progress_angle`` for ``stuck_timeout`` seconds, farther than
``progress_radius`` from the plan's end (the re-planner's progress rule, Nav2's
PoseProgressChecker; ``stuck_timeout`` is longer than the re-planner's ``progress_timeout``,
so a no-progress re-plan gets its chance first).

**What**, in this order (`RecoveryKind`):

1. *Back out along the trail* (forward-only robots: `RecoverySettings.back_out`). The robot's
   own recent trail, the poses it occupied, is known free of static obstacles, including
   behind it where its laser does not see. It reverses along the trail (a reverse pure
   pursuit on it, at ``back_out_speed``) until a turn in place is possible (its circumscribed
   disc ``turn_clearance`` clear of every obstacle held), or it has backed ``back_out_max``
   metres, or the trail ends. Before every command the footprint is checked, at the trail's
   poses ahead and along the commanded arc, against every obstacle the controller holds:
   a trail crossed by an obstacle seen since is not taken. Where the robot turned in place,
   the back-out turns back first (the trail keeps the turns): reversing at another heading
   than the body had there would sweep where it never was.
2. *Spin* to clear the view: where a turn in place is possible, by ``spin_angle`` towards the
   plan's end, so that the laser sees what the pocket hid and the re-plan knows it. "Possible"
   is judged against the obstacles held, as the MPC's own turns are: behind the robot the
   laser sees nothing, and what it saw there is forgotten after the memory's time-to-live;
   after a back-out the trail covers the disc behind the robot but for slivers at the rear
   corners, so a spin is as safe as the MPC's turns in place, not more.
3. *Wait* standing for a new plan (the re-planner's no-progress rule re-plans from where the
   robot now stands), at most ``wait_timeout`` seconds; then the controller drives again.

**Bounds.** At most ``max_tries`` recoveries per goal (a plan whose end moves by more than
``progress_radius`` is a new goal); then the controller's own answer stands, with the
reason said once in the log (`Recoveries.exhausted`).

A robot that may reverse (``allow_reversing``) needs no back-out: its MPC plans backwards
itself; it still spins and waits. During a recovery the controller is not asked (its
commands would fight the recovery); its answer resumes after the wait.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
import math
from typing import Callable, NamedTuple, Sequence

import numpy as np

from mpc_local_planner.core.control_output import ControlOutput, Reason
from mpc_local_planner.core.footprint import Footprint
from mpc_local_planner.core.margin_relief import footprint_clearance_at, standing
from mpc_local_planner.core.obstacles import ConvexPolygon, min_clearance
from mpc_local_planner.core.replanning import PROGRESS_ANGLE, PROGRESS_RADIUS, PROGRESS_TIMEOUT

__all__ = [
    'Recoveries',
    'RecoveryKind',
    'RecoveryRecord',
    'RecoverySettings',
    'Trail',
]

# Reasons whose robot has a plan and is driven by it: only these count towards being stuck
# (a robot stopped for stale odometry, a missing scan or at its goal is not stuck).
_DRIVEN = (Reason.TRACKING, Reason.CANDIDATE, Reason.STOP)
# Seconds of the commanded arc checked ahead during a back-out, in steps of _ARC_STEP.
_ARC_TIME = 0.5
_ARC_STEP = 0.1
# Metres: trail points nearer than this to the robot are passed (popped) during a back-out.
_PASSED = 0.08
# Metres of trail ahead (behind the robot) that the reverse pursuit aims at.
_LOOKAHEAD = 0.3
# Radians of turn in place between two recorded trail poses, and within which the robot's
# heading is aligned with a trail pose (else a back-out first turns back to it: reversing at
# another heading than the body had there would sweep where the body never was).
_TURN_SPACING = 0.05
_ALIGNED = 0.1
# Trail poses kept per spacing of path at most (a robot turning in place for long adds poses
# without path).
_TURNS_PER_SPACING = 4
# 1/s: a turn back to a trail pose slows as it comes near its heading (rad/s per rad).
_RETRACE_GAIN = 2.0
# Metres deeper into an obstacle that a back-out from contact still counts as no deeper
# (rounding of the separation, not a tolerance of the check).
_DEEPER = 1e-6


class RecoveryKind(str, Enum):
    """A recovery behaviour (the value is the diagnostics' and the rows' word)."""

    BACK_OUT = 'back_out'
    SPIN = 'spin'
    WAIT = 'wait'

    def __str__(self) -> str:
        """Return the word itself."""
        return self.value


@dataclass(frozen=True)
class RecoverySettings:
    """When a robot counts as stuck, and how far each recovery may go.

    Attributes:
        enabled: Recoveries run at all (off: the controller's answer always stands).
        stuck_timeout: Seconds without progress before a recovery (longer than the
            re-planner's progress_timeout, so a no-progress re-plan comes first).
        progress_radius: Metres that count as progress (and the plan's end within which
            standing is arriving).
        progress_angle: Radians of turn that count as progress.
        back_out: Back out along the trail (False for a robot that may reverse).
        back_out_speed: Reverse speed, m/s (capped by the robot's v_max).
        back_out_max: Metres a back-out may go at most.
        trail_length: Metres of trail kept.
        trail_spacing: Metres between two recorded trail poses.
        turn_clearance: A back-out ends where the footprint's circumscribed disc is this
            clear of every obstacle held (a turn in place is then possible), metres.
        spin_angle: Radians of the spin (0: no spin).
        spin_speed: Yaw rate of the spin, rad/s (capped by the robot's omega_max).
        wait_timeout: Seconds to wait standing for a new plan after the motions.
        max_tries: Recoveries per goal at most.

    """

    enabled: bool = True
    stuck_timeout: float = 1.5 * PROGRESS_TIMEOUT
    progress_radius: float = PROGRESS_RADIUS
    progress_angle: float = PROGRESS_ANGLE
    back_out: bool = True
    back_out_speed: float = 0.25
    back_out_max: float = 1.5
    trail_length: float = 3.0
    trail_spacing: float = 0.02
    turn_clearance: float = 0.05
    spin_angle: float = 0.5 * math.pi
    spin_speed: float = 1.0
    wait_timeout: float = 2.0 * PROGRESS_TIMEOUT
    max_tries: int = 3

    def __post_init__(self) -> None:
        """Refuse values that would make a recovery unbounded or meaningless."""
        for name in ('stuck_timeout', 'progress_radius', 'back_out_speed', 'back_out_max',
                     'trail_length', 'trail_spacing', 'spin_speed'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                problem = f'recoveries: {name} must be finite and > 0, got {value}'
                raise ValueError(problem)
        for name in ('progress_angle', 'turn_clearance', 'spin_angle', 'wait_timeout'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                problem = f'recoveries: {name} must be finite and >= 0, got {value}'
                raise ValueError(problem)
        if self.max_tries < 0:
            problem = f'recoveries: max_tries must be >= 0, got {self.max_tries}'
            raise ValueError(problem)


class RecoveryRecord(NamedTuple):
    """One recovery behaviour that ran: what, from when to when, how far, how it ended."""

    kind: RecoveryKind
    start: float
    end: float
    distance: float
    ended: str


class Trail:
    """The poses the robot occupied, newest last, at most `length` metres of path.

    Args:
        spacing: Metres between two recorded poses.
        length: Metres of path kept (the oldest poses are dropped).

    """

    def __init__(self, spacing: float, length: float) -> None:
        self.spacing = float(spacing)
        self.length = float(length)
        self._poses: list[np.ndarray] = []

    @property
    def poses(self) -> np.ndarray:
        """(K, 3) poses, oldest first."""
        return np.array(self._poses, dtype=float).reshape(-1, 3)

    def __len__(self) -> int:
        return len(self._poses)

    def clear(self) -> None:
        """Forget the trail (a new run, a jump of the pose)."""
        self._poses.clear()

    def record(self, pose: np.ndarray) -> None:
        """Add pose when it is `spacing` from the newest one or turned _TURN_SPACING from it.

        Turns in place are kept too: the body swept them, so turning back is retracing them.
        At most `length` metres of path, and _TURNS_PER_SPACING poses per spacing of it.
        """
        pose = np.asarray(pose, dtype=float)[:3].copy()
        if self._poses:
            newest = self._poses[-1]
            moved = math.hypot(*(pose[:2] - newest[:2])) >= self.spacing
            turned = abs(math.remainder(float(pose[2] - newest[2]), math.tau)) >= _TURN_SPACING
            if not (moved or turned):
                return
        self._poses.append(pose)
        xy = self.poses[:, :2]
        steps = np.hypot(*np.diff(xy, axis=0).T)
        beyond = np.cumsum(steps[::-1])[::-1] > self.length  # path from pose i to the newest
        drop = max(int(np.count_nonzero(beyond)),
                   len(self._poses) - int(_TURNS_PER_SPACING * self.length / self.spacing))
        del self._poses[:drop]

    def pop_passed(self, pose: np.ndarray) -> None:
        """Drop the newest poses a back-out has reached (within _PASSED and _ALIGNED of pose)."""
        while self._poses and self._reached(self._poses[-1], pose):
            self._poses.pop()

    @staticmethod
    def _reached(trail_pose: np.ndarray, pose: np.ndarray) -> bool:
        near = math.hypot(*(trail_pose[:2] - pose[:2])) < _PASSED
        return near and abs(math.remainder(float(trail_pose[2] - pose[2]), math.tau)) < _ALIGNED

    def behind(self, position: np.ndarray, distance: float) -> np.ndarray:
        """Return the newest poses back along the trail for `distance` metres, newest first."""
        poses = self.poses[::-1]
        if len(poses) == 0:
            return poses
        xy = np.vstack([position[None, :2], poses[:, :2]])
        along = np.cumsum(np.hypot(*np.diff(xy, axis=0).T))
        return poses[: int(np.searchsorted(along, distance, side='right')) + 1]


class Recoveries:
    """The recovery behaviours around any local controller (see the module's docstring).

    Args:
        footprint: The robot's footprint (the back-out's checks, the turn's disc).
        v_max: The robot's speed limit, m/s (caps the back-out's speed).
        omega_max: The robot's yaw-rate limit, rad/s (caps the turns).
        settings: When and how far.

    """

    def __init__(self, footprint: Footprint, *, v_max: float, omega_max: float,
                 settings: RecoverySettings | None = None) -> None:
        self.footprint = footprint
        self.v_max = float(v_max)
        self.omega_max = float(omega_max)
        self.settings = settings or RecoverySettings()
        self.trail = Trail(self.settings.trail_spacing, self.settings.trail_length)
        self.log: list[RecoveryRecord] = []
        self.started = 0  # recoveries started, in all (the log keeps each behaviour)
        self.exhausted = False
        self._obstacles: list[ConvexPolygon] = []
        self._goal: np.ndarray | None = None
        self._tries = 0
        self._anchor: np.ndarray | None = None
        self._anchor_time = -math.inf
        self._phase: RecoveryKind | None = None
        self._phase_start = 0.0
        self._phase_pose = np.zeros(3)
        self._backed = 0.0
        self._last_position: np.ndarray | None = None
        self._spin_sign = 1.0
        self._new_plan = False

    @property
    def phase(self) -> RecoveryKind | None:
        """The recovery running now, or None."""
        return self._phase

    @property
    def tries(self) -> int:
        """Recoveries started for the goal in force."""
        return self._tries

    def set_obstacles(self, obstacles: Sequence[ConvexPolygon]) -> None:
        """Check the back-out against these obstacles (as sensed, not grown)."""
        self._obstacles = list(obstacles)

    def plan_changed(self, poses: np.ndarray) -> None:
        """A new plan is in force: it ends a wait; a plan to a new goal resets the tries."""
        end = np.asarray(poses, dtype=float).reshape(-1, np.shape(poses)[-1])[-1, :2]
        if self._goal is None or math.hypot(*(end - self._goal)) > self.settings.progress_radius:
            self._tries = 0
            self.exhausted = False
        self._goal = end.copy()
        self._new_plan = True

    def reset(self) -> None:
        """Forget the run: trail, goal, tries, a recovery under way (the log and count stay)."""
        self.trail.clear()
        self._goal = None
        self._tries = 0
        self.exhausted = False
        self._anchor = None
        self._phase = None

    def step(self, pose: np.ndarray | None, twist: np.ndarray | None, now: float,
             compute: Callable[[], ControlOutput]) -> ControlOutput:
        """Return the recovery's command while one runs, else the controller's (compute()).

        Args:
            pose: The robot's pose [x, y, theta] (None: no pose; the controller answers).
            twist: Its measured [v, omega] (None: unknown, taken as standing: a wait ends
                when a new plan comes, as on a base that reports no twist).
            now: The caller's time, seconds.
            compute: The controller's answer for this step.

        """
        if not self.settings.enabled or pose is None:
            return compute()
        pose = np.asarray(pose, dtype=float).reshape(-1)[:3]
        if self._phase is not None:
            return self._recover(pose, twist, now)
        answer = compute()
        self.trail.record(pose)
        if self._stuck(pose, now, answer.reason):
            if self._tries >= self.settings.max_tries:
                self.exhausted = True
                return answer
            self._tries += 1
            self.started += 1
            first = RecoveryKind.BACK_OUT if self.settings.back_out else RecoveryKind.SPIN
            self._enter(first, pose, now)
            return self._recover(pose, twist, now)
        return answer

    # -- being stuck ------------------------------------------------------------------------

    def _stuck(self, pose: np.ndarray, now: float, reason: Reason) -> bool:
        settings = self.settings
        if (reason not in _DRIVEN or self._anchor is None or self._progressed(pose)
                or (self._goal is not None
                    and math.hypot(*(pose[:2] - self._goal)) <= settings.progress_radius)):
            self._anchor, self._anchor_time = pose.copy(), now
            return False
        return now - self._anchor_time >= settings.stuck_timeout - 1e-9

    def _progressed(self, pose: np.ndarray) -> bool:
        assert self._anchor is not None
        if math.hypot(*(pose[:2] - self._anchor[:2])) >= self.settings.progress_radius:
            return True
        turned = abs(math.remainder(float(pose[2] - self._anchor[2]), math.tau))
        return self.settings.progress_angle > 0.0 and turned >= self.settings.progress_angle

    # -- the behaviours ---------------------------------------------------------------------

    def _enter(self, kind: RecoveryKind, pose: np.ndarray, now: float) -> None:
        self._phase, self._phase_start, self._phase_pose = kind, now, pose.copy()
        self._backed = 0.0
        self._last_position = pose[:2].copy()
        self._new_plan = False
        if kind is RecoveryKind.SPIN and self._goal is not None:
            bearing = math.atan2(*(self._goal - pose[:2])[::-1])
            self._spin_sign = 1.0 if math.remainder(bearing - pose[2], math.tau) >= 0 else -1.0

    def _finish(self, pose: np.ndarray, now: float, ended: str) -> None:
        assert self._phase is not None
        distance = self._backed if self._phase is RecoveryKind.BACK_OUT else 0.0
        self.log.append(RecoveryRecord(self._phase, self._phase_start, now, distance, ended))
        following = {RecoveryKind.BACK_OUT: RecoveryKind.SPIN,
                     RecoveryKind.SPIN: RecoveryKind.WAIT}.get(self._phase)
        if following is None:
            self._phase = None
            self._anchor, self._anchor_time = pose.copy(), now
            return
        self._enter(following, pose, now)

    def _recover(self, pose: np.ndarray, twist: np.ndarray | None,
                 now: float) -> ControlOutput:
        for _ in range(len(RecoveryKind)):  # a behaviour that ends at once hands on
            kind = self._phase
            if kind is None:
                break
            if kind is RecoveryKind.BACK_OUT:
                answer = self._back_out(pose, now)
            elif kind is RecoveryKind.SPIN:
                answer = self._spin(pose, now)
            else:
                answer = self._wait(pose, twist, now)
            if answer is not None:
                return answer
        return ControlOutput(np.zeros(2), None, Reason.RECOVERY, 'recovery done: standing')

    def _turn_possible(self, pose: np.ndarray) -> bool:
        clearance = min_clearance(self._obstacles, pose[None, :2])
        return clearance >= self.footprint.radius + self.settings.turn_clearance

    def _back_out(self, pose: np.ndarray, now: float) -> ControlOutput | None:
        settings = self.settings
        assert self._last_position is not None
        self._backed += math.hypot(*(pose[:2] - self._last_position))
        self._last_position = pose[:2].copy()
        self.trail.pop_passed(pose)
        ended = None
        if self._turn_possible(pose):
            ended = 'a turn in place is possible'
        elif self._backed >= settings.back_out_max:
            ended = f'backed out {settings.back_out_max:g} m'
        elif len(self.trail) == 0:
            ended = 'the trail ends'
        if ended is None:
            speed = min(settings.back_out_speed, self.v_max)
            u = self._retrace_turn(pose)
            if u is None:
                u = self._reverse_pursuit(pose, speed)
            blocked = self._blocked(pose, u, speed)
            if blocked is None:
                # one wording per behaviour: the node logs a reason's message when it changes
                detail = f'backing out along the trail (at most {settings.back_out_max:g} m)'
                return ControlOutput(u, None, Reason.RECOVERY, detail)
            ended = blocked
        self._finish(pose, now, ended)
        return None

    def _retrace_turn(self, pose: np.ndarray) -> np.ndarray | None:
        """Return (0, omega) back to the newest trail pose's heading where the robot stands.

        None unless the robot stands at that pose's position at another heading (it turned in
        place there).
        """
        newest = self.trail.poses[-1]
        if math.hypot(*(newest[:2] - pose[:2])) >= _PASSED:
            return None
        error = math.remainder(float(newest[2] - pose[2]), math.tau)
        # trail poses are _TURN_SPACING apart: the short way back is the way the body came
        omega = math.copysign(min(self.settings.spin_speed, self.omega_max,
                                  _RETRACE_GAIN * abs(error)), error)
        return np.array([0.0, omega])

    def _reverse_pursuit(self, pose: np.ndarray, speed: float) -> np.ndarray:
        """Return (v < 0, omega) along the arc through the trail point _LOOKAHEAD behind."""
        ahead = self.trail.behind(pose, _LOOKAHEAD)
        target = ahead[-1, :2]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        dx, dy = target - pose[:2]
        x_body, y_body = c * dx + s * dy, -s * dx + c * dy
        chord = x_body * x_body + y_body * y_body
        curvature = 2.0 * y_body / chord if chord > 1e-12 else 0.0
        v = -speed
        omega = v * curvature
        if abs(omega) > self.omega_max:  # keep the arc: slow down rather than cut the turn
            v *= self.omega_max / abs(omega)
            omega = math.copysign(self.omega_max, omega)
        return np.array([v, omega])

    def _blocked(self, pose: np.ndarray, u: np.ndarray, speed: float) -> str | None:
        """Say what an obstacle held blocks: the trail ahead or the commanded arc; else None."""
        if not self._obstacles:
            return None
        ahead = self.trail.behind(pose, _LOOKAHEAD + speed * _ARC_TIME)
        times = np.arange(1, int(round(_ARC_TIME / _ARC_STEP)) + 1) * _ARC_STEP
        arc = _arc(pose, u, times)
        # a robot touching an obstacle already (a base that coasted on, a sensed piece a
        # millimetre into where it stands) may back out as long as it gets no deeper
        now = self._clearance(pose[None, :])
        for name, poses in (('the trail', ahead), ('the arc', arc)):
            if not len(poses):
                continue
            clearance = self._clearance(poses)
            if (clearance <= 0.0) if now > 0.0 else (clearance < now - _DEEPER):
                return f'{name} behind is blocked by an obstacle seen since'
        return None

    def _clearance(self, poses: np.ndarray) -> float:
        return footprint_clearance_at(self.footprint, poses, self._obstacles)

    def _spin(self, pose: np.ndarray, now: float) -> ControlOutput | None:
        settings = self.settings
        turned = abs(math.remainder(float(pose[2] - self._phase_pose[2]), math.tau))
        speed = min(settings.spin_speed, self.omega_max)
        ended = None
        if settings.spin_angle <= 0.0:
            ended = 'no spin'
        elif not self._turn_possible(pose):
            ended = 'no room to turn in place'
        elif turned >= settings.spin_angle:
            ended = f'turned {turned:.2f} rad'
        elif now - self._phase_start > 3.0 * settings.spin_angle / speed:
            ended = 'the spin timed out'
        if ended is not None:
            self._finish(pose, now, ended)
            return None
        u = np.array([0.0, self._spin_sign * speed])
        return ControlOutput(u, None, Reason.RECOVERY,
                             f'spinning to clear the view ({settings.spin_angle:.2f} rad)')

    def _wait(self, pose: np.ndarray, twist: np.ndarray | None,
              now: float) -> ControlOutput | None:
        still = twist is None or standing(twist)
        waited = now - self._phase_start
        if waited >= self.settings.wait_timeout:
            self._finish(pose, now, 'waited for a plan in vain')
            return None
        if self._new_plan and still:
            self._finish(pose, now, 'a new plan came')
            return None
        return ControlOutput(np.zeros(2), None, Reason.RECOVERY,
                             f'waiting for a new plan (at most {self.settings.wait_timeout:g} s)')


def _arc(pose: np.ndarray, u: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Return the unicycle's poses at times (s) under constant u from pose, (len(times), 3)."""
    v, omega = float(u[0]), float(u[1])
    heading = pose[2] + omega * times
    if abs(omega) < 1e-9:
        x = pose[0] + v * times * math.cos(pose[2])
        y = pose[1] + v * times * math.sin(pose[2])
    else:
        radius = v / omega
        x = pose[0] + radius * (np.sin(heading) - math.sin(pose[2]))
        y = pose[1] - radius * (np.cos(heading) - math.cos(pose[2]))
    return np.column_stack([x, y, heading])
