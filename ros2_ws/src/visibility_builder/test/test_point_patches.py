"""The exploration patches of scene points: views, axes, patches, by hand."""
from __future__ import annotations

import numpy as np
import pytest

from vbn_common.geometry.camera import make_camera
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.point_patches import (
    MIN_FACING_COS,
    choose_patch_views,
    patch_axes,
    point_patches,
)
from visibility_builder.scene_points import PointsConfig


def _pixel(camera, point: np.ndarray, pose: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    d = point - [pose[0], pose[1], 0.0]
    base = np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])
    uv, ok = camera.project((base @ BASE_TO_CAMERA_ROTATION)[None])
    assert ok.all()
    return uv[0]


def test_pinhole_axes_by_hand() -> None:
    # A 90 deg, 640 px pinhole looking along +x: focal 320 px. A point 2 m ahead on the
    # axis: one pixel right is 2/320 m to the camera's right (-y), one down 2/320 m down.
    camera = make_camera('pinhole', 640, 480, hfov_deg=90)
    point = np.array([[2.0, 0.0, 0.0]])
    uv = np.array([[319.5, 239.5]])
    np.testing.assert_allclose(_pixel(camera, point[0], np.zeros(3)), uv[0], atol=1e-9)
    axes = patch_axes(point, np.zeros((1, 3)), uv, camera)
    np.testing.assert_allclose(axes[0], [[0.0, -2 / 320, 0.0], [0.0, 0.0, -2 / 320]],
                               atol=1e-6)
    # Turned by 90 deg and 4 m away: twice the step, along the turned axes.
    axes = patch_axes(np.array([[0.0, 4.0, 0.0]]), np.array([[0.0, 0.0, np.pi / 2]]), uv,
                      camera)
    np.testing.assert_allclose(axes[0], [[4 / 320, 0.0, 0.0], [0.0, 0.0, -4 / 320]],
                               atol=1e-6)


def test_the_axes_move_the_projection_one_pixel() -> None:
    camera = make_camera('panoramic')
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.uniform(-3, 3, 20), rng.uniform(2, 4, 20),
                              rng.uniform(-0.5, 0.8, 20)])
    poses = np.column_stack([rng.uniform(-0.5, 0.5, (20, 2)), rng.uniform(-np.pi, np.pi, 20)])
    uv = np.array([_pixel(camera, p, q) for p, q in zip(points, poses, strict=True)])
    axes = patch_axes(points, poses, uv, camera).astype(float)
    for i in range(20):
        right = _pixel(camera, points[i] + axes[i, 0], poses[i])
        down = _pixel(camera, points[i] + axes[i, 1], poses[i])
        np.testing.assert_allclose(right - uv[i], [1.0, 0.0], atol=2e-3)
        np.testing.assert_allclose(down - uv[i], [0.0, 1.0], atol=2e-3)


def test_axes_on_a_given_surface_by_hand() -> None:
    # The pinhole of test_pinhole_axes_by_hand, 2 m from a wall turned 45 degrees about
    # the vertical (normal (1, 1, 0) / sqrt 2): one pixel right (-y on the facing plane,
    # 2/320 m) meets the wall 2/320 m further along x as well; one down stays vertical.
    camera = make_camera('pinhole', 640, 480, hfov_deg=90)
    point, uv = np.array([[2.0, 0.0, 0.0]]), np.array([[319.5, 239.5]])
    normal = np.array([[1.0, 1.0, 0.0]]) / np.sqrt(2)
    axes = patch_axes(point, np.zeros((1, 3)), uv, camera, normal).astype(float)
    step = 2 / 320
    np.testing.assert_allclose(axes[0, 1], [0.0, 0.0, -step], atol=1e-6)
    right = axes[0, 0]
    assert abs(right @ normal[0]) < 1e-6                 # on the wall
    np.testing.assert_allclose(right[1] / right[0], -1.0, rtol=1e-3)
    np.testing.assert_allclose(_pixel(camera, point[0] + right, np.zeros(3)) - uv[0],
                               [1.0, 0.0], atol=1e-3)
    # Either sign of the normal is the same plane; a NaN normal, or a wall seen nearer
    # grazing than MIN_FACING_COS, keeps the plane facing the camera.
    np.testing.assert_allclose(patch_axes(point, np.zeros((1, 3)), uv, camera, -normal),
                               axes, atol=1e-9)
    facing = patch_axes(point, np.zeros((1, 3)), uv, camera)
    grazing = np.array([[np.cos(np.radians(80)), np.sin(np.radians(80)), 0.0]])
    for unusable in (np.full((1, 3), np.nan), grazing):
        np.testing.assert_array_equal(patch_axes(point, np.zeros((1, 3)), uv, camera,
                                                 unusable), facing)
    assert np.cos(np.radians(80)) < MIN_FACING_COS < np.cos(np.radians(45))


def test_the_patch_view_is_nearest_where_the_point_was_seen_from() -> None:
    camera = make_camera('pinhole', 640, 480, hfov_deg=90)
    points = np.array([[3.0, 0.0, 0.0], [3.0, 0.1, 0.0]])
    poses = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, np.pi]])
    # Point 0 seen by images 0, 1, 2 (centre 0.4: image 1 nearest); point 1 by 0 and 3
    # (image 3 faces away); image 1 may not give patches for point 1's sake either.
    member_point = np.array([0, 0, 0, 1, 1])
    member_image = np.array([0, 1, 2, 0, 3])
    centres = np.array([[0.4, 0.0], [0.0, 0.0]])
    image, uv = choose_patch_views(points, member_point, member_image, poses, centres,
                                   camera, 15, np.ones(4, bool))
    assert image.tolist() == [1, 0]
    np.testing.assert_allclose(uv[0], _pixel(camera, points[0], poses[1]))
    # Image 1 unusable (tilted): the next nearest, image 0 (0.4 m) before image 2 (0.6).
    image, _ = choose_patch_views(points, member_point, member_image, poses, centres,
                                  camera, 15, np.array([True, False, True, True]))
    assert image.tolist() == [0, 0]
    # A point whose patch would leave every image keeps none.
    image, _ = choose_patch_views(np.array([[3.0, 2.999, 0.0]]), np.array([0]),
                                  np.array([0]), poses, centres[:1], camera, 15,
                                  np.ones(4, bool))
    assert image.tolist() == [-1]


def test_a_patch_is_centred_on_the_point_to_a_subpixel() -> None:
    camera = make_camera('pinhole', 640, 480, hfov_deg=90)
    pose = np.zeros((1, 3))
    point = np.array([[2.0, -0.3, 0.2]])
    uv = _pixel(camera, point[0], pose[0])[None]
    # A blob at the point's pixel: the patch's centre pixel is its peak, its moments
    # centred to a hundredth of a pixel.
    yy, xx = np.mgrid[0:480, 0:640]
    blob = 40 + 200 * np.exp(-((xx - uv[0, 0]) ** 2 + (yy - uv[0, 1]) ** 2) / 8.0)
    image = np.clip(np.rint(blob), 0, 255).astype(np.uint8)
    patches, axes = point_patches(point, np.array([0]), uv, pose, camera, 15,
                                  lambda i: image)
    patch = patches[0].astype(float) - 40
    assert np.unravel_index(np.argmax(patch), patch.shape) == (7, 7)
    grid = np.arange(15) - 7
    assert abs((patch.sum(axis=0) * grid).sum() / patch.sum()) < 0.02
    assert abs((patch.sum(axis=1) * grid).sum() / patch.sum()) < 0.02
    assert np.isfinite(axes).all()
    # No view, or an image that cannot be decoded: no patch, NaN axes.
    patches, axes = point_patches(np.vstack([point, point]), np.array([-1, 0]),
                                  np.vstack([uv, uv]), pose, camera, 15, lambda i: None)
    assert not patches.any() and np.isnan(axes).all()


@pytest.mark.parametrize('size', [-1, 6, 5, 16, True])
def test_patch_sizes_are_checked(size) -> None:
    with pytest.raises(VisibilityBuilderError, match='patch_px'):
        PointsConfig(patch_px=size)
    assert PointsConfig(patch_px=0).patch_px == 0


@pytest.mark.parametrize('views', [1, 2.5, True])
def test_patch_min_views_is_checked(views) -> None:
    with pytest.raises(VisibilityBuilderError, match='patch_min_views'):
        PointsConfig(patch_min_views=views)


def _textured(camera, point: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """A dark image with two blobs of different size at and beside the point's pixel."""
    u, v = _pixel(camera, point, pose)
    yy, xx = np.mgrid[0:camera.height, 0:camera.width]
    dx, dy = xx - u, yy - v
    image = 40 + 160 * np.exp(-(dx ** 2 + dy ** 2) / 6.0) + \
        60 * np.exp(-((dx - 3) ** 2 + (dy + 2) ** 2) / 3.0)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def test_a_point_off_along_its_patch_view_ray_is_triangulated_where_its_patch_is() -> None:
    from visibility_builder.point_patches import triangulate_on_patches

    camera = make_camera('pinhole', 640, 480, hfov_deg=90)
    truth = np.array([2.5, 0.2, 0.1])
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.4, 0.0], [0.0, -0.4, 0.05], [0.3, 0.0, 0.0]])
    images = [_textured(camera, truth, pose) for pose in poses]
    # Triangulated 4 cm too deep along image 0's ray: the patch cut there is still the
    # blob's, and images 1 to 3 see the blob where the true point projects.
    ray = truth / np.linalg.norm(truth)
    guess = (truth + 0.04 * ray)[None]
    uv = _pixel(camera, guess[0], poses[0])[None]
    patches, axes = point_patches(guess, np.array([0]), uv, poses, camera, 15,
                                  lambda i: images[i])
    moved, found = triangulate_on_patches(guess, patches, axes, np.zeros(4, np.int64),
                                          np.arange(4), poses, camera, lambda i: images[i],
                                          min_views=3)
    assert found.tolist() == [4]
    assert np.linalg.norm(moved[0] - truth) < 2e-3 < np.linalg.norm(guess[0] - truth) / 10
    # Found in fewer than min_views images: not moved.
    kept, found = triangulate_on_patches(guess, patches, axes, np.zeros(2, np.int64),
                                         np.arange(2), poses, camera, lambda i: images[i],
                                         min_views=3)
    assert found.tolist() == [2] and np.array_equal(kept, guess)


@pytest.mark.parametrize('radius', [-0.1, float('nan'), True, '0.3'])
def test_patch_normal_radius_is_checked(radius) -> None:
    with pytest.raises(VisibilityBuilderError, match='patch_normal_radius_m'):
        PointsConfig(patch_normal_radius_m=radius)
    assert PointsConfig(patch_normal_radius_m=0).patch_normal_radius_m == 0
