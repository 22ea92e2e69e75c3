"""Smooth run trajectories through a scene, and the kidnapped-robot variant.

A run drives a differential-drive robot forward along a smooth path that contains
turns, a loop close to the walls and a pass through the middle of the free space.
The path is planned on a fine free-space lattice (8-connected, edges
weighted to stay away from walls), through waypoints chosen from the scene: a
ring of poses at ``near_wall`` metres from the nearest wall, ordered by angle
around the free space's centroid, then the two most open poses that are furthest
apart (the pass through the middle). The polyline is smoothed with a Gaussian
kernel (weaker where smoothing would bring it closer than ``clearance`` to a
wall) and timed with speed limited by ``max_speed``, by ``max_turn_rate`` over
the curvature and by ``max_accel``; the heading follows the path's tangent.

Another path seed gives another day's run through the same scene (the loop at
another distance from the walls, through more or fewer waypoints, from another start,
either way round, and another pass through the middle); seed 0 is the scene's own.

The kidnapped variant drives the first half of a run and is then carried (no
wheel motion) to the pose of the run's first half that is furthest away, from
which it drives on along the run for the remaining time.
"""
from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from landmark_db.scene import Scene
from vbn_common.geometry.frames import wrap_angle
from vbn_worlds.errors import WorldsError

__all__ = ['RunParameters', 'Trajectory', 'kidnapped_trajectory', 'lattice_graph',
           'run_trajectory']


@dataclass(frozen=True)
class RunParameters:
    """How a run is planned and timed.

    Attributes:
        max_speed: top speed, m/s.
        max_turn_rate: top yaw rate, rad/s.
        max_accel: acceleration limit, m/s^2.
        near_wall: distance of the wall-following loop from the walls, metres.
        clearance: the path never comes closer to a wall, metres.
        smoothing: Gaussian smoothing of the planned polyline, metres.
        lattice: planning lattice step, metres.
        waypoints: number of waypoints on the wall-following loop.
        dt: time step of the sampled trajectory, seconds.
    """

    max_speed: float = 0.4
    max_turn_rate: float = 0.6
    max_accel: float = 0.4
    near_wall: float = 0.5
    clearance: float = 0.3
    smoothing: float = 0.35
    lattice: float = 0.1
    waypoints: int = 8
    dt: float = 0.01


@dataclass(frozen=True)
class Trajectory:
    """A sampled planar trajectory of ``base_link`` in ``map``.

    Attributes:
        times: ``(n,)`` seconds from the start, uniform step.
        poses: ``(n, 3)`` ground-truth ``(x, y, yaw)``; yaw unwrapped (continuous).
        velocity: ``(n, 2)`` true body velocity ``(v, omega)`` (m/s, rad/s), what the
            wheels do; zero-length teleports do not appear in it.
        teleport_time: time of the kidnapping, seconds, or ``None``.
    """

    times: np.ndarray
    poses: np.ndarray
    velocity: np.ndarray
    teleport_time: float | None = None

    @property
    def duration(self) -> float:
        """Return the last sample time, seconds."""
        return float(self.times[-1])

    def pose_at(self, t: np.ndarray | float) -> np.ndarray:
        """Return ground-truth poses at times ``t`` (linear interpolation, yaw wrapped).

        Args:
            t: time(s) in seconds within ``[0, duration]``.

        Returns:
            ``(m, 3)`` poses; yaw in ``[-pi, pi)``.
        """
        t = np.atleast_1d(np.asarray(t, dtype=float))
        index = np.clip(np.searchsorted(self.times, t, side='right') - 1, 0,
                        len(self.times) - 1)
        nxt = np.minimum(index + 1, len(self.times) - 1)
        span = np.maximum(self.times[nxt] - self.times[index], 1e-12)
        w = np.clip((t - self.times[index]) / span, 0.0, 1.0)[:, None]
        jump = np.linalg.norm(self.poses[nxt, :2] - self.poses[index, :2], axis=1) > 0.2
        w[jump] = 0.0  # never interpolate across a teleport
        out = self.poses[index] * (1 - w) + self.poses[nxt] * w
        out[:, 2] = wrap_angle(out[:, 2])
        return out


def lattice_graph(scene: Scene, params: RunParameters) -> tuple[np.ndarray, np.ndarray, object]:
    """Return the free lattice nodes, their clearances and their 8-connected graph.

    Nodes keep ``params.clearance`` from walls; edges are weighted to stay away from them
    (the runs' and the driven explorations' shortest paths).
    """
    xmin, ymin, xmax, ymax = scene.bounds()
    step = params.lattice
    xs = np.arange(xmin + step / 2, xmax, step)
    ys = np.arange(ymin + step / 2, ymax, step)
    gx, gy = np.meshgrid(xs, ys, indexing='ij')
    points = np.stack([gx.ravel(), gy.ravel()], axis=1)
    free = scene.free_space(points)
    clearance = np.zeros(len(points))
    clearance[free] = scene.wall_distance(points[free])
    ok = free & (clearance >= params.clearance)
    if ok.sum() < 2:
        raise WorldsError(
            f'no room to drive: the scene has no free space {params.clearance} m from walls')
    index = -np.ones(len(points), dtype=np.int64)
    index[ok] = np.arange(ok.sum())
    grid = index.reshape(len(xs), len(ys))
    rows, cols, weights = [], [], []
    node_clearance = clearance[ok]
    nx, ny = len(xs), len(ys)
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
        j0, j1 = max(0, -dj), ny - max(0, dj)
        a = grid[0:nx - di, j0:j1]
        b = grid[di:nx, j0 + dj:j1 + dj]
        both = (a >= 0) & (b >= 0)
        a, b = a[both], b[both]
        length = step * math.hypot(di, dj)
        cost = length * (1.0 + 0.3 / np.minimum(node_clearance[a], node_clearance[b]))
        rows.append(a)
        cols.append(b)
        weights.append(cost)
    n = int(ok.sum())
    r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(weights)
    graph = coo_matrix((np.concatenate([w, w]), (np.concatenate([r, c]),
                                                 np.concatenate([c, r]))), shape=(n, n))
    return points[ok], node_clearance, graph.tocsr()


def _waypoints(scene: Scene, nodes: np.ndarray, clearance: np.ndarray,
               params: RunParameters, path_seed: int = 0) -> list[int]:
    centroid = nodes.mean(axis=0)
    outer = Scene(scene.perimeter).wall_distance(nodes)  # distance to the outer walls
    near_wall, count = params.near_wall, params.waypoints
    rng = np.random.default_rng([path_seed, 4]) if path_seed else None
    if rng is not None:   # another day's run: another loop, another way round
        near_wall *= float(rng.uniform(0.8, 1.6))
        count = max(3, count + int(rng.integers(-2, 3)))
    ring = np.flatnonzero(np.abs(outer - near_wall) <= params.lattice / 2 + 1e-9)
    if ring.size < count:
        ring = np.argsort(np.abs(outer - near_wall))[:max(count, 2)]
    angle = np.arctan2(nodes[ring, 1] - centroid[1], nodes[ring, 0] - centroid[0])
    order = ring[np.argsort(angle)]
    if rng is not None:
        order = np.roll(order, int(rng.integers(0, order.size)))
        order = order[::-1] if rng.uniform() < 0.5 else order
    picks = order[np.linspace(0, order.size, count, endpoint=False).astype(int)]
    loop = [int(p) for p in picks] + [int(picks[0])]
    open_nodes = np.flatnonzero(clearance >= 0.8 * clearance.max())
    pts = nodes[open_nodes]
    dist = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    i, j = np.unravel_index(np.argmax(dist), dist.shape)
    if rng is not None:   # a pass through the middle between two far open places
        far = np.argwhere(dist >= 0.6 * dist.max())
        i, j = far[int(rng.integers(0, len(far)))]
    # Enter the middle pass at the end nearer to where the loop closed.
    a, b = int(open_nodes[i]), int(open_nodes[j])
    if np.linalg.norm(nodes[b] - nodes[loop[-1]]) < np.linalg.norm(nodes[a] - nodes[loop[-1]]):
        a, b = b, a
    return loop + [a, b]


def _plan(nodes: np.ndarray, graph: object, waypoints: list[int]) -> np.ndarray:
    unique = sorted(set(waypoints))
    _, predecessors = dijkstra(graph, indices=unique, return_predecessors=True)
    row_of = {w: k for k, w in enumerate(unique)}
    path: list[int] = [waypoints[0]]
    for src, dst in zip(waypoints[:-1], waypoints[1:]):
        if src == dst:
            continue
        pred = predecessors[row_of[src]]
        leg = [dst]
        while leg[-1] != src:
            prev = int(pred[leg[-1]])
            if prev < 0:
                raise WorldsError('the free space is not connected: cannot plan a run')
            leg.append(prev)
        path.extend(leg[::-1][1:])
    return nodes[np.array(path)]


def _resample(polyline: np.ndarray, step: float) -> np.ndarray:
    seg = np.linalg.norm(np.diff(polyline, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])
    polyline = polyline[keep]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(polyline, axis=0), axis=1))])
    samples = np.arange(0.0, s[-1], step)
    return np.stack([np.interp(samples, s, polyline[:, 0]),
                     np.interp(samples, s, polyline[:, 1])], axis=1)


def _smooth(scene: Scene, path: np.ndarray, params: RunParameters, step: float) -> np.ndarray:
    sigma = params.smoothing / step
    while sigma >= 0.5:
        smooth = np.stack([gaussian_filter1d(path[:, k], sigma, mode='nearest')
                           for k in range(2)], axis=1)
        if (np.all(scene.wall_distance(smooth) >= params.clearance * 0.8)
                and np.all(scene.free_space(smooth))):
            return smooth
        sigma /= 2.0
    return path


def _time_path(path: np.ndarray, params: RunParameters) -> Trajectory:
    d = np.diff(path, axis=0)
    ds = np.linalg.norm(d, axis=1)
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    heading = np.concatenate([heading, heading[-1:]])
    # Speed limits at each path sample: top speed, turn rate over curvature, rest at ends.
    curvature = np.abs(np.gradient(heading)) / max(float(np.median(ds)), 1e-9)
    curvature = gaussian_filter1d(curvature, 3.0)
    v = np.minimum(params.max_speed, params.max_turn_rate / np.maximum(curvature, 1e-9))
    v[0] = v[-1] = 0.0
    for i in range(1, len(v)):  # acceleration limit, forward and backward
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * params.max_accel * ds[i - 1]))
    for i in range(len(v) - 2, -1, -1):
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * params.max_accel * ds[i]))
    v_mid = np.maximum(0.5 * (v[:-1] + v[1:]), 1e-3)
    # Slow enough that the heading change per step respects the turn rate.
    dt_turn = np.abs(np.diff(heading)) / params.max_turn_rate
    dt = np.maximum(ds / v_mid, dt_turn)
    t_path = np.concatenate([[0.0], np.cumsum(dt)])
    times = np.arange(0.0, t_path[-1], params.dt)
    s_path = np.concatenate([[0.0], np.cumsum(ds)])
    arc = np.interp(times, t_path, s_path)
    yaw = np.interp(times, t_path, heading)
    # Drive it as a unicycle (exact arcs): the body never slips sideways, so the
    # velocities below are exactly what the wheels do.
    v = np.diff(arc) / params.dt
    omega = np.diff(yaw) / params.dt
    poses = np.zeros((len(times), 3))
    poses[0] = (path[0, 0], path[0, 1], yaw[0])
    poses[1:] = _integrate(poses[0], v, omega, params.dt)
    velocity = np.concatenate([np.stack([v, omega], axis=1), [[0.0, 0.0]]])
    return Trajectory(times, poses, velocity)


def _integrate(start: np.ndarray, v: np.ndarray, omega: np.ndarray, dt: float) -> np.ndarray:
    """Integrate unicycle velocities with exact arcs; returns the poses after each step."""
    dtheta = omega * dt
    theta = start[2] + np.cumsum(dtheta)
    mid = theta - 0.5 * dtheta
    small = np.abs(dtheta) < 1e-9
    chord = np.where(small, 1.0, np.sin(dtheta / 2) / np.where(small, 1.0, dtheta / 2))
    x = start[0] + np.cumsum(v * dt * chord * np.cos(mid))
    y = start[1] + np.cumsum(v * dt * chord * np.sin(mid))
    return np.stack([x, y, theta], axis=1)


def run_trajectory(scene: Scene, params: RunParameters | None = None,
                   duration: float | None = None, path_seed: int = 0) -> Trajectory:
    """Plan and time a run through ``scene`` (see the module docstring).

    The run is deterministic: it depends only on the scene, ``params`` and
    ``path_seed``.

    Args:
        scene: the scene.
        params: planning and timing parameters.
        duration: cut the run after this many seconds (``None``: the whole run).
        path_seed: 0: the scene's own path; another: a loop at another distance from
            the walls (0.8 to 1.6 times), through more or fewer waypoints, from another
            start, either way round, and another pass through the middle.

    Returns:
        The ground-truth trajectory, starting at rest.

    Raises:
        WorldsError: the scene leaves no room to drive.
    """
    params = params or RunParameters()
    nodes, clearance, graph = lattice_graph(scene, params)
    waypoints = _waypoints(scene, nodes, clearance, params, path_seed)
    polyline = _plan(nodes, graph, waypoints)
    if np.sum(np.linalg.norm(np.diff(polyline, axis=0), axis=1)) < 2 * params.lattice:
        raise WorldsError('the scene is too small for a run')
    step = params.lattice / 2
    path = _smooth(scene, _resample(polyline, step), params, step)
    trajectory = _time_path(path, params)
    if duration is not None:
        if duration <= 0:
            raise WorldsError(f'run duration must be positive, got {duration}')
        keep = trajectory.times <= duration
        trajectory = Trajectory(trajectory.times[keep], trajectory.poses[keep],
                                trajectory.velocity[keep])
    return trajectory


def kidnapped_trajectory(run: Trajectory) -> Trajectory:
    """Turn a run into the kidnapped-robot variant (see the module docstring).

    The robot drives ``run`` up to its middle sample, is teleported (the wheels do
    not turn) to the sample of the first half furthest from there, and drives on
    along ``run`` from that sample for the remaining time. The result has the
    same length and time step as ``run``.
    """
    n = len(run.times)
    if n < 4:
        raise WorldsError('a run of fewer than 4 samples cannot be kidnapped')
    half = n // 2
    distance = np.linalg.norm(run.poses[:half, :2] - run.poses[half, :2], axis=1)
    target = int(np.argmax(distance))
    rest = n - half
    poses = np.concatenate([run.poses[:half], run.poses[target:target + rest]])
    velocity = np.concatenate([run.velocity[:half], run.velocity[target:target + rest]])
    velocity[half - 1] = 0.0  # the step across the teleport: carried, wheels still
    return Trajectory(run.times[:len(poses)], poses, velocity,
                      teleport_time=float(run.times[half]))
