from __future__ import annotations

import math

from hypothesis import example, given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_db.scene import Scene
from vbn_common.geometry.camera import PanoramicCamera, PinholeCamera
from vbn_common.geometry.frames import world_points_to_camera
from vbn_worlds.render.renderer import Renderer, cast_rays
from vbn_worlds.render.textures import build_wall_atlas

# A 4 m x 4 m room (counter-clockwise) with a 0.5 m pillar, walls 2.5 m, camera at 1.2 m.
SQUARE = Scene(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]),
               obstacles=(np.array([[3.0, 3.0], [3.5, 3.0], [3.5, 3.5], [3.0, 3.5]]),),
               wall_height=2.5, camera_height=1.2, texture_seed=1, name='square')


@pytest.fixture(scope='module')
def atlas():
    return build_wall_atlas(SQUARE, texels_per_metre=80)


@pytest.fixture(scope='module')
def pano(atlas):
    return Renderer(SQUARE, PanoramicCamera(512, 128), atlas)


@pytest.fixture(scope='module')
def pinhole(atlas):
    return Renderer(SQUARE, PinholeCamera.from_fov(320, 240, 90.0), atlas)


def test_cast_rays_hand_checked_distances():
    starts, ends, _ = SQUARE.wall_segments()
    angles = np.array([0.0, math.pi / 2, math.pi, -math.pi / 2, math.pi / 4, -3 * math.pi / 4])
    rho, seg, s = cast_rays(np.array([1.0, 2.0]), angles, starts, ends)
    assert rho == pytest.approx([3.0, 2.0, 1.0, 2.0, 2 * math.sqrt(2), math.sqrt(2)])
    # east wall is segment 1 (from (4,0) to (4,4)); hit at y = 2, halfway
    assert seg[0] == 1 and s[0] == pytest.approx(0.5)
    # the pillar blocks the diagonal from (2, 2): nearest face is at x = 3 (or y = 3)
    rho, seg, _ = cast_rays(np.array([2.0, 2.0]), np.array([math.pi / 4]), starts, ends)
    assert rho[0] == pytest.approx(math.sqrt(2)) and seg[0] >= 4


def test_panorama_wall_extent_matches_geometry(pano):
    pose = np.array([1.0, 2.0, 0.0])  # facing the east wall, 3 m away
    out = pano.render(pose, with_points=True)
    cam = pano.camera
    col = int(cam.cx)
    assert out.rho[col] == pytest.approx(3.0)
    # rows showing the wall: heights 0..2.5 m at 3 m range
    top = cam.horizon_row - cam.f_vertical * (2.5 - 1.2) / 3.0
    bottom = cam.horizon_row + cam.f_vertical * 1.2 / 3.0
    wall_rows = np.flatnonzero(~np.isnan(out.wall_points[:, col, 0]))
    assert wall_rows.min() == math.ceil(top)
    assert wall_rows.max() == math.floor(bottom)
    assert np.allclose(out.wall_points[wall_rows, col, 0], 4.0, atol=1e-5)
    assert np.allclose(out.wall_points[wall_rows, col, 1], 2.0, atol=1e-5)
    # above and below: ceiling and floor have no wall point
    assert np.isnan(out.wall_points[0, col]).all() and np.isnan(out.wall_points[-1, col]).all()


def test_pinhole_forward_wall_is_a_rectangle_at_constant_depth(pinhole):
    pose = np.array([2.0, 1.0, math.pi / 2])  # facing the north wall (y = 4), 3 m away
    out = pinhole.render(pose, with_points=True)
    cam = pinhole.camera
    # every column looking at the north wall sees the same rows (straight edges)
    centre_cols = np.arange(100, 220)
    points = out.wall_points[:, centre_cols]
    assert np.allclose(points[..., 1][~np.isnan(points[..., 1])], 4.0, atol=1e-5)
    rows = [np.flatnonzero(~np.isnan(points[:, k, 0])) for k in range(len(centre_cols))]
    assert len({(r.min(), r.max()) for r in rows}) == 1
    top = cam.cy - cam.fy * (2.5 - 1.2) / 3.0
    assert rows[0].min() == math.ceil(top)


def test_texture_reads_left_to_right_from_the_free_side(pano):
    # Facing the east wall from inside: arc length along the wall grows to the right.
    rho, seg, s = pano.cast(np.array([1.0, 2.0, 0.0]))
    cols = np.arange(int(pano.camera.cx) - 20, int(pano.camera.cx) + 20)
    atlas = pano.atlas
    arc = np.where(atlas.flip[seg[cols]], 1 - s[cols], s[cols]) * atlas.lengths[seg[cols]]
    assert np.all(seg[cols] == 1)
    assert np.all(np.diff(arc) > 0)
    # The same for a pillar face seen from outside (pillar's west face from (2, 3.25))
    rho, seg, s = pano.cast(np.array([2.0, 3.25, 0.0]))
    cols = cols[10:-10]
    arc = np.where(atlas.flip[seg[cols]], 1 - s[cols], s[cols]) * atlas.lengths[seg[cols]]
    assert np.all(seg[cols] >= 4)
    assert np.all(np.diff(arc) > 0)


@settings(max_examples=50, deadline=None)
@given(x=st.floats(0.01, 3.99), y=st.floats(0.01, 3.99), angle=st.floats(-math.pi, math.pi))
def test_cast_rays_in_an_empty_box_matches_the_slab_formula(x, y, angle):
    box = Scene(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]))
    starts, ends, _ = box.wall_segments()
    rho, seg, s = cast_rays(np.array([x, y]), np.array([angle]), starts, ends)
    d = np.array([math.cos(angle), math.sin(angle)])
    with np.errstate(divide='ignore'):
        exits = [(4.0 - c) / dc if dc > 0 else -c / dc for c, dc in zip((x, y), d)
                 if abs(dc) > 1e-12]
    assert rho[0] == pytest.approx(min(exits), rel=1e-9, abs=1e-9)
    hit = starts[seg[0]] + s[0] * (ends[seg[0]] - starts[seg[0]])
    assert hit == pytest.approx(np.array([x, y]) + rho[0] * d, abs=1e-9)


free = st.tuples(st.floats(0.2, 3.8), st.floats(0.2, 3.8), st.floats(-math.pi, math.pi))


@settings(max_examples=25, deadline=None)
@given(pose=free, uv=st.lists(st.tuples(st.floats(0, 511), st.floats(0, 127)), min_size=1,
                              max_size=20))
# Found by Hypothesis on a loaded machine: the ray of column 0 projected back to u = 512.0
# (the mod of a tiny negative column), outside the image.
@example(pose=(3.53125, 3.5, 1.0), uv=[(0.0, 0.0)])
def test_pixel_to_wall_point_projects_back_to_the_pixel(pano, pose, uv):
    pose = np.array(pose)
    if not SQUARE.free_space(pose[None, :2])[0]:
        return
    uv = np.array(uv)
    points = pano.pixel_to_wall_point(pose, uv[:, 0], uv[:, 1])
    ok = ~np.isnan(points[:, 0])
    cam_points = world_points_to_camera(pose, SQUARE.camera_height, points[ok])
    back, inside = pano.camera.project(cam_points)
    assert inside.all()
    du = np.abs(back[:, 0] - uv[ok, 0])
    du = np.minimum(du, 512 - du)  # the panorama wraps around
    assert du.max(initial=0) < 1e-6
    assert np.abs(back[:, 1] - uv[ok, 1]).max(initial=0) < 1e-6
    # the point lies on a wall: inside the walls' height, on the room's boundary
    assert np.all((points[ok, 2] >= 0) & (points[ok, 2] <= 2.5))


@settings(max_examples=10, deadline=None)
@given(pose=free)
def test_pinhole_ground_truth_round_trip(pinhole, pose):
    pose = np.array(pose)
    if not SQUARE.free_space(pose[None, :2])[0]:
        return
    u, v = np.meshgrid(np.linspace(0, 319, 9), np.linspace(0, 239, 7))
    points = pinhole.pixel_to_wall_point(pose, u.ravel(), v.ravel())
    ok = ~np.isnan(points[:, 0])
    back, inside = pinhole.camera.project(world_points_to_camera(pose, 1.2, points[ok]))
    assert inside.all()
    assert back == pytest.approx(np.stack([u.ravel(), v.ravel()], 1)[ok], abs=1e-6)


def test_per_pixel_ground_truth_agrees_with_pixel_query(pano):
    pose = np.array([1.3, 0.7, 0.4])
    out = pano.render(pose, with_points=True)
    v, u = np.mgrid[0:128:7, 0:512:13]
    direct = pano.pixel_to_wall_point(pose, u.ravel(), v.ravel())
    stored = out.wall_points[v.ravel(), u.ravel()]
    assert np.array_equal(np.isnan(direct[:, 0]), np.isnan(stored[:, 0]))
    ok = ~np.isnan(direct[:, 0])
    assert stored[ok] == pytest.approx(direct[ok], abs=1e-4)
    assert out.image.shape == (128, 512, 3)


def test_images_are_deterministic_and_depend_on_the_texture_seed(atlas):
    pose = np.array([1.0, 1.0, 0.3])
    a = Renderer(SQUARE, PanoramicCamera(512, 128), atlas).render(pose).image
    b = Renderer(SQUARE, PanoramicCamera(512, 128),
                 build_wall_atlas(SQUARE, texels_per_metre=80)).render(pose).image
    assert np.array_equal(a, b)
    other = Scene(SQUARE.perimeter, SQUARE.obstacles, wall_height=2.5, camera_height=1.2,
                  texture_seed=2)
    c = Renderer(other, PanoramicCamera(512, 128),
                 build_wall_atlas(other, texels_per_metre=80)).render(pose).image
    assert np.mean(np.abs(a.astype(int) - c.astype(int))) > 5
