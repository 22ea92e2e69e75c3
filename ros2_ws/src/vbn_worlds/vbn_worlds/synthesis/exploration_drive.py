"""An exploration driven as a robot drives it: stop and go between the grid positions.

The plain exploration bag places the camera at every grid position
(:func:`~.grid.exploration_poses`) with its pose from the ground truth. A real robot
drives there: it turns on the spot towards the next position, drives straight to it,
stops, turns through the image headings (pinhole and fisheye explorations; a panorama
is taken at whatever heading the robot arrived with) and takes one image at each, still
standing. Its wheels measure all of it, so the wheel odometry
(:func:`~.odometry.simulate_odometry`) drifts with the whole path, turns included.

The positions are visited nearest first (:func:`visiting_order`), as a robot explores
room by room. Motions are a turn on the spot or a straight drive, each with a trapezoidal speed
profile (``max_turn_rate`` and :data:`TURN_ACCEL`; ``max_speed`` and ``max_accel`` of
:class:`~.trajectory.RunParameters`), stretched to a whole number of time steps so that
each sample's velocity is exactly the motion to the next sample (noise-free odometry
then reproduces the ground truth). A straight leg that would pass closer than the
exploration's clearance to a wall (the next position lies behind an obstacle, or round
a corner of an L-shaped hall) follows the shortest path on a free-space lattice
instead, cut into the fewest straight legs that stay clear.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy.sparse.csgraph import dijkstra

from landmark_db.scene import Scene
from vbn_common.geometry.frames import wrap_angle
from vbn_worlds.errors import WorldsError
from vbn_worlds.synthesis.trajectory import RunParameters, Trajectory, lattice_graph

__all__ = ['DWELL_S', 'TURN_ACCEL', 'DrivenExploration', 'driven_exploration',
           'visiting_order']

#: Angular acceleration of a turn on the spot, rad/s^2.
TURN_ACCEL = 1.5
#: How long the robot stands still for each image, seconds (the image in the middle).
DWELL_S = 0.4
#: Samples of a straight leg checked for clearance, per metre.
_CHECKS_PER_M = 50


@dataclass(frozen=True)
class DrivenExploration:
    """The driven path and its images.

    Attributes:
        trajectory: the ground truth, sampled every ``dt`` (velocities exact).
        image_times: ``(m,)`` seconds from the start, one per image, increasing.
        image_poses: ``(m, 3)`` ground-truth ``(x, y, yaw)`` of each image (standing).
        image_positions: ``(m,)`` index of the grid position each image was taken at.
    """

    trajectory: Trajectory
    image_times: np.ndarray
    image_poses: np.ndarray
    image_positions: np.ndarray


class _Path:
    """Accumulates samples ``(x, y, yaw, v, omega)``, each lasting ``dt``."""

    def __init__(self, start: np.ndarray, dt: float) -> None:
        self.dt = dt
        self.pose = np.asarray(start, float).copy()
        self.rows: list[np.ndarray] = []
        self.time = 0.0

    def _profile(self, distance: float, top: float, accel: float) -> np.ndarray:
        """Distance covered at each sample of a trapezoidal move, ending on a sample."""
        ramp = top / accel
        if distance < top * ramp:   # triangular: never reaches the top speed
            ramp = math.sqrt(distance / accel)
            duration = 2.0 * ramp
        else:
            duration = 2.0 * ramp + (distance - top * ramp) / top
        steps = max(1, math.ceil(duration / self.dt - 1e-9))
        t = np.arange(steps + 1) * (duration / steps)   # stretched onto whole steps
        peak = accel * ramp
        s = np.where(t < ramp, 0.5 * accel * t ** 2,
                     np.where(t <= duration - ramp, 0.5 * accel * ramp ** 2 + peak * (t - ramp),
                              distance - 0.5 * accel * (duration - t) ** 2))
        s[-1] = distance
        return s

    def turn(self, yaw: float, rate: float) -> None:
        change = float(wrap_angle(yaw - self.pose[2]))
        if abs(change) < 1e-9:
            return
        s = self._profile(abs(change), rate, TURN_ACCEL) * math.copysign(1.0, change)
        n = len(s) - 1
        rows = np.zeros((n, 5))
        rows[:, 0:2] = self.pose[:2]
        rows[:, 2] = self.pose[2] + s[:-1]
        rows[:, 4] = np.diff(s) / self.dt
        self.rows.append(rows)
        self.pose[2] += change
        self.time += n * self.dt

    def drive(self, target: np.ndarray, speed: float, accel: float) -> None:
        delta = np.asarray(target, float) - self.pose[:2]
        distance = float(np.linalg.norm(delta))
        if distance < 1e-9:
            return
        s = self._profile(distance, speed, accel)
        n = len(s) - 1
        unit = delta / distance
        rows = np.zeros((n, 5))
        rows[:, 0:2] = self.pose[:2] + s[:-1, None] * unit
        rows[:, 2] = self.pose[2]
        rows[:, 3] = np.diff(s) / self.dt
        self.rows.append(rows)
        self.pose[:2] = target
        self.time += n * self.dt

    def dwell(self, seconds: float) -> float:
        """Stand still; return the time of the middle of the stop."""
        n = max(1, math.ceil(seconds / self.dt - 1e-9))
        rows = np.zeros((n, 5))
        rows[:, :3] = self.pose
        self.rows.append(rows)
        middle = self.time + 0.5 * n * self.dt
        self.time += n * self.dt
        return middle

    def trajectory(self) -> Trajectory:
        last = np.concatenate([self.pose, [0.0, 0.0]])[None]
        rows = np.concatenate(self.rows + [last])
        times = np.arange(len(rows)) * self.dt
        return Trajectory(times, rows[:, :3].copy(), rows[:, 3:5].copy())


def _clear(scene: Scene, a: np.ndarray, b: np.ndarray, clearance: float) -> bool:
    """Whether the straight leg from ``a`` to ``b`` keeps ``clearance`` from every wall."""
    n = max(2, int(math.ceil(np.linalg.norm(b - a) * _CHECKS_PER_M)) + 1)
    points = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
    free = scene.free_space(points)
    if not free.all():
        return False
    return bool(np.all(scene.wall_distance(points) >= clearance - 1e-9))


class _Router:
    """Legs between positions: straight when clear, else along the free-space lattice."""

    def __init__(self, scene: Scene, clearance: float, params: RunParameters) -> None:
        self.scene, self.clearance, self.params = scene, clearance, params
        self._lattice: tuple[np.ndarray, object] | None = None

    def legs(self, a: np.ndarray, b: np.ndarray) -> list[np.ndarray]:
        if _clear(self.scene, a, b, self.clearance):
            return [b]
        if self._lattice is None:
            lattice = RunParameters(clearance=self.clearance, lattice=self.params.lattice)
            nodes, _, graph = lattice_graph(self.scene, lattice)
            self._lattice = (nodes, graph)
        nodes, graph = self._lattice
        start = int(np.argmin(np.linalg.norm(nodes - a, axis=1)))
        goal = int(np.argmin(np.linalg.norm(nodes - b, axis=1)))
        _, predecessors = dijkstra(graph, indices=start, return_predecessors=True)
        if goal != start and predecessors[goal] < 0:
            raise WorldsError(f'no free path from ({a[0]:.2f}, {a[1]:.2f}) to '
                                         f'({b[0]:.2f}, {b[1]:.2f}) for the exploration')
        chain = [goal]
        while chain[-1] != start:
            chain.append(int(predecessors[chain[-1]]))
        polyline = [a] + [nodes[k] for k in reversed(chain)] + [b]
        # The fewest straight legs that stay clear: from each corner, the furthest one.
        out, here = [], 0
        while here < len(polyline) - 1:
            nxt = len(polyline) - 1
            while nxt > here + 1 and not _clear(self.scene, polyline[here], polyline[nxt],
                                                0.5 * self.clearance):
                nxt -= 1
            out.append(np.asarray(polyline[nxt], float))
            here = nxt
        return out


def visiting_order(scene: Scene, positions: np.ndarray, clearance: float) -> np.ndarray:
    """Order the positions as an exploring robot would: the nearest one it can drive to.

    From the first position, each next one is the nearest unvisited position reachable
    by a clear straight leg, or, when none is, the nearest of all (the leg then goes round
    by the lattice). The grid's boustrophedon order crosses walls between rooms; on the
    floor scene at 0.75 m it made 2,385 s of driving and odometry 9 m off at the median.
    """
    positions = np.asarray(positions, float).reshape(-1, 2)
    left = np.ones(len(positions), bool)
    order = [0]
    left[0] = False
    while left.any():
        here = positions[order[-1]]
        candidates = np.flatnonzero(left)
        by_distance = candidates[np.argsort(np.linalg.norm(positions[candidates] - here,
                                                           axis=1), kind='stable')]
        chosen = by_distance[0]
        for k in by_distance[:8]:
            if _clear(scene, here, positions[k], clearance):
                chosen = k
                break
        order.append(int(chosen))
        left[chosen] = False
    return np.array(order, np.int64)


def driven_exploration(scene: Scene, positions: np.ndarray, headings: int,
                       params: RunParameters, clearance: float) -> DrivenExploration:
    """Drive through ``positions`` in order, taking ``headings`` images at each.

    Args:
        scene: the scene (for legs that must go round obstacles).
        positions: ``(n, 2)`` grid positions in visiting order.
        headings: images per position: 1 takes one at the arrival heading, N turns to
            the headings ``2 pi k / N`` (nearest first, then on in one direction).
        params: speeds and accelerations, and the time step ``dt``.
        clearance: the legs keep this far from walls where they can.

    Returns:
        The trajectory and the images' times and ground-truth poses.
    """
    positions = np.asarray(positions, float).reshape(-1, 2)
    if len(positions) == 0:
        raise WorldsError('no exploration position to drive to')
    path = _Path(np.array([positions[0, 0], positions[0, 1], 0.0]), params.dt)
    router = _Router(scene, clearance, params)
    times, poses, where = [], [], []
    step = 2.0 * math.pi / headings
    for i, target in enumerate(positions):
        if i > 0:
            for corner in router.legs(path.pose[:2].copy(), target):
                delta = corner - path.pose[:2]
                path.turn(math.atan2(delta[1], delta[0]), params.max_turn_rate)
                path.drive(corner, params.max_speed, params.max_accel)
        if headings == 1:
            order = [float(path.pose[2])]
        else:
            first = int(round(float(path.pose[2]) / step)) % headings
            order = [float(wrap_angle(step * ((first + k) % headings)))
                     for k in range(headings)]
        for yaw in order:
            path.turn(yaw, params.max_turn_rate)
            times.append(path.dwell(DWELL_S))
            poses.append(path.pose.copy())
            where.append(i)
    trajectory = path.trajectory()
    poses_arr = np.array(poses)
    poses_arr[:, 2] = wrap_angle(poses_arr[:, 2])
    return DrivenExploration(trajectory, np.array(times), poses_arr,
                             np.array(where, np.int64))
