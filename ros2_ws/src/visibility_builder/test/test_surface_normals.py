"""Surface normals of scene points from their neighbours (visibility_builder.surface_normals)."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np

from visibility_builder.surface_normals import MIN_SPAN_M, surface_normals


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.abs(np.sum(a * b, axis=1)) / np.linalg.norm(a, axis=1) / np.linalg.norm(b, axis=1)
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


def _corner(rng: np.random.Generator, n: int, noise: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points on two walls meeting at a right angle along the z axis (x = 0 and y = 0):
    the points, their walls' normals and their distances from the corner."""
    along = rng.uniform(0.0, 1.5, n)
    height = rng.uniform(-1.0, 1.0, n)
    on_x = rng.random(n) < 0.5   # the wall x = 0 (normal x) or y = 0 (normal y)
    points = np.column_stack([np.where(on_x, 0.0, along), np.where(on_x, along, 0.0), height])
    points[:, :2] += rng.normal(0.0, noise, (n, 2)) * np.column_stack([on_x, ~on_x])
    normals = np.column_stack([on_x, ~on_x, np.zeros(n)]).astype(float)
    return points, normals, along


def test_two_walls_by_their_points() -> None:
    """Points a few millimetres off two walls: each one's wall within a degree or two, away
    from the corner; a point is never given the other wall's normal (it is not on it)."""
    rng = np.random.default_rng(0)
    points, truth, along = _corner(rng, 3000, 0.003)
    normals = surface_normals(points)
    ok = np.all(np.isfinite(normals), axis=1)
    away = along > 0.1
    assert ok[away].mean() > 0.95
    errors = _angle_deg(normals[ok], truth[ok])
    assert np.median(errors) < 0.5 and np.percentile(errors[away[ok]], 99) < 1.5
    assert errors.max() < 10.0
    np.testing.assert_allclose(np.linalg.norm(normals[ok], axis=1), 1.0, atol=1e-9)


def test_no_plane_without_one() -> None:
    """Too few neighbours, a line of points, points far apart or NaN: no normal."""
    rng = np.random.default_rng(1)
    few = rng.normal(0.0, 0.05, (5, 3))
    assert np.isnan(surface_normals(few)).all()
    line = np.column_stack([np.zeros(40), np.zeros(40), np.linspace(0, 1, 40)])
    line[:, :2] += rng.normal(0, 0.002, (40, 2))
    assert np.isnan(surface_normals(line)).all()
    sparse = rng.uniform(0, 20, (100, 3))        # neighbours beyond the radius
    assert np.isnan(surface_normals(sparse, radius=0.3)).all()
    wall = _corner(rng, 500, 0.002)[0]
    wall[7] = np.nan
    normals = surface_normals(wall)
    assert np.isnan(normals[7]).all() and np.isfinite(normals).all(axis=1).mean() > 0.8
    assert surface_normals(np.zeros((0, 3))).shape == (0, 3)
    # A ball of points: no neighbourhood is planar within the tolerance.
    ball = rng.normal(0, 0.1, (800, 3))
    assert np.isfinite(surface_normals(ball)).all(axis=1).mean() < 0.05


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.floats(-np.pi, np.pi), st.floats(-1.2, 1.2), st.integers(0, 2 ** 16))
def test_a_turned_plane_is_found_whatever_its_orientation(yaw: float, tilt: float,
                                                           seed: int) -> None:
    rng = np.random.default_rng(seed)
    normal = np.array([np.cos(yaw) * np.cos(tilt), np.sin(yaw) * np.cos(tilt), np.sin(tilt)])
    a = np.cross(normal, [0.0, 0.0, 1.0] if abs(normal[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    uv = rng.uniform(-0.5, 0.5, (400, 2))
    points = np.array([3.0, -1.0, 0.5]) + uv[:, :1] * a + uv[:, 1:] * b + \
        rng.normal(0, 0.002, (400, 1)) * normal
    found = surface_normals(points)
    ok = np.all(np.isfinite(found), axis=1)
    assert ok.mean() > 0.9
    assert np.percentile(_angle_deg(found[ok], np.tile(normal, (ok.sum(), 1))), 95) < 2.0
    assert MIN_SPAN_M < 0.5 / np.sqrt(12)   # the patch of points spans enough
