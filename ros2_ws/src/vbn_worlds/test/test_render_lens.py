"""Rendering through a lens: distorted pinholes and fisheyes (render/lens_view.py)."""
from __future__ import annotations

import numpy as np
import pytest

from landmark_db.scene import Scene
from vbn_common.geometry.camera import PinholeCamera, make_camera
from vbn_common.geometry.frames import world_points_to_camera
from vbn_common.geometry.mount import TiltedCamera, tilt_matrix
from vbn_worlds.render.lens_view import LensRenderer, make_renderer
from vbn_worlds.render.renderer import Renderer
from vbn_worlds.render.textures import build_wall_atlas
from vbn_worlds.synthesis.bags import BagSpec

SQUARE = Scene(np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]),
               obstacles=(np.array([[3.0, 3.0], [3.5, 3.0], [3.5, 3.5], [3.0, 3.5]]),),
               wall_height=2.5, camera_height=1.2, texture_seed=1, name='square')
BARREL = ('plumb_bob', (-0.3, 0.08, 0.0005, -0.0005, 0.0))
FISHEYE = ('equidistant', (0.02, -0.005, 0.001, 0.0))


@pytest.fixture(scope='module')
def atlas():
    return build_wall_atlas(SQUARE, texels_per_metre=80)


def _cameras():
    return [make_camera('pinhole', 160, 120, distortion=BARREL),
            make_camera('fisheye', 160, 120, 200.0, distortion=FISHEYE),
            TiltedCamera(make_camera('pinhole', 160, 120), tilt_matrix(-12.0, 4.0)),
            TiltedCamera(make_camera('panoramic', 256, 64), tilt_matrix(3.0, -2.0))]


@pytest.mark.parametrize('camera', _cameras(),
                         ids=['plumb_bob', 'fisheye', 'pitched_pinhole', 'tilted_panorama'])
def test_ground_truth_projects_back_through_the_lens(atlas, camera) -> None:
    renderer = make_renderer(SQUARE, camera, atlas)
    assert isinstance(renderer, LensRenderer)
    pose = np.array([1.5, 1.8, 0.4])
    u, v = np.meshgrid(np.linspace(0, camera.width - 1, 11).round(),
                       np.linspace(0, camera.height - 1, 9).round())
    points = renderer.pixel_to_wall_point(pose, u.ravel(), v.ravel())
    ok = ~np.isnan(points[:, 0])
    assert ok.sum() > 40
    back, inside = camera.project(world_points_to_camera(pose, SQUARE.camera_height,
                                                         points[ok]))
    assert inside.all()
    expected = np.column_stack([u.ravel(), v.ravel()])[ok]
    if camera.kind == 'panoramic':  # the last column wraps around to the first
        back[:, 0] = np.where(back[:, 0] < expected[:, 0] - camera.width / 2,
                              back[:, 0] + camera.width, back[:, 0])
    assert back == pytest.approx(expected, abs=1e-6)
    assert np.all((points[ok, 2] >= 0) & (points[ok, 2] <= 2.5))
    # The rendering's per-pixel points agree with the per-pixel query (the nearest source
    # pixel: within a few centimetres at these ranges)
    rendering = renderer.render(pose, with_points=True)
    assert rendering.image.shape == (camera.height, camera.width, 3)
    grid = rendering.wall_points[v.ravel().astype(int), u.ravel().astype(int)]
    both = ok & ~np.isnan(grid[:, 0])
    assert both.sum() > 0.9 * ok.sum()
    # (a pixel on an occluding edge may take the nearer wall: nine in ten agree)
    error = np.abs(grid[both] - points[both]).max(axis=1)
    assert np.mean(error < 0.08) >= 0.9


def test_no_distortion_keeps_the_column_renderer_and_a_lens_bends_the_image(atlas) -> None:
    plain = make_camera('pinhole', 160, 120)
    assert type(make_renderer(SQUARE, plain, atlas)) is Renderer
    barrel = make_camera('pinhole', 160, 120, distortion=BARREL)
    renderer = make_renderer(SQUARE, barrel, atlas)
    # Barrel distortion pulls a wider view into the image: the source is larger.
    assert isinstance(renderer.source, PinholeCamera)
    assert renderer.source.width > 160 and renderer.source.fx == pytest.approx(barrel.fx)
    pose = np.array([1.5, 1.8, 0.4])
    lens_image = renderer.render(pose, encoding='mono8').image
    plain_image = make_renderer(SQUARE, plain, atlas).render(pose, encoding='mono8').image
    # The centre is the same view; the edges are not.
    centre = np.s_[50:70, 70:90]
    assert np.abs(lens_image[centre].astype(int) - plain_image[centre]).mean() < 12
    assert np.abs(lens_image[:, :10].astype(int) - plain_image[:, :10]).mean() > 5


def test_bag_spec_takes_the_lens_and_names_bad_ones() -> None:
    spec = BagSpec(camera='fisheye', distortion=FISHEYE, hfov_deg=190.0)
    info = spec.camera_model().camera_info()
    assert info.distortion_model == 'equidistant' and info.d == FISHEYE[1]
    from vbn_common.errors import VbnCommonError
    with pytest.raises(VbnCommonError, match='a pinhole camera takes plumb_bob'):
        BagSpec(camera='pinhole', distortion=FISHEYE).check()
