"""Tests of vbn_common.images: every encoding, byte order, padding and bad input."""
from __future__ import annotations

from dataclasses import dataclass
import pickle

import cv2
import numpy as np
import pytest

from vbn_common.bags import TYPESTORE
from vbn_common.errors import VbnCommonError
from vbn_common.images import EncodedImage, ImageDecodeError, check_image, decode_image

T = TYPESTORE.types

# One 2 x 3 colour image: red, green, blue / white, black, grey 128 (as R, G, B).
RGB = np.array([[[255, 0, 0], [0, 255, 0], [0, 0, 255]],
                [[255, 255, 255], [0, 0, 0], [128, 128, 128]]], dtype=np.uint8)
BGR = RGB[:, :, ::-1]
# cvtColor's BT.601 fixed point: red 76, green 150, blue 29.
GRAY = np.array([[76, 150, 29], [255, 0, 128]], dtype=np.uint8)


@dataclass
class FakeImage:
    """A duck-typed sensor_msgs/Image, like rclpy's (data as array-like of ints)."""

    encoding: str
    height: int
    width: int
    step: int
    is_bigendian: int
    data: object


@dataclass
class FakeCompressed:
    format: str
    data: object


def raw(pixels: np.ndarray, encoding: str, pad: int = 0, bigendian: bool = False) -> FakeImage:
    """Pack (H, W[, C]) pixels into an Image with ``pad`` bytes of row padding."""
    height, width = pixels.shape[:2]
    rows = pixels.reshape(height, -1)
    if pixels.dtype == np.uint16:
        rows = pixels.astype('>u2' if bigendian else '<u2').view(np.uint8).reshape(height, -1)
    padded = np.concatenate([rows, np.full((height, pad), 0xAB, np.uint8)], axis=1)
    return FakeImage(encoding, height, width, padded.shape[1], int(bigendian),
                     padded.reshape(-1).tolist())


@pytest.mark.parametrize('pad', [0, 5])
@pytest.mark.parametrize('encoding, pixels', [
    ('bgr8', BGR), ('rgb8', RGB),
    ('bgra8', np.dstack([BGR, np.full((2, 3), 7, np.uint8)])),
    ('rgba8', np.dstack([RGB, np.full((2, 3), 7, np.uint8)])),
])
def test_colour_encodings_decode_to_the_same_bgr_and_gray(encoding: str, pixels: np.ndarray,
                                                          pad: int) -> None:
    msg = raw(pixels, encoding, pad)
    assert decode_image(msg).tolist() == GRAY.tolist()
    colour = decode_image(msg, gray=False)
    assert colour.shape == (2, 3, 3) and colour.dtype == np.uint8
    assert colour.tolist() == BGR.tolist()


@pytest.mark.parametrize('pad', [0, 3])
def test_mono8_with_and_without_padding(pad: int) -> None:
    pixels = np.array([[0, 1, 2], [253, 254, 255]], dtype=np.uint8)
    msg = raw(pixels, 'mono8', pad)
    assert msg.step == 3 + pad
    for gray in (True, False):
        out = decode_image(msg, gray=gray)
        assert out.shape == (2, 3) and out.tolist() == pixels.tolist()


@pytest.mark.parametrize('bigendian', [False, True])
@pytest.mark.parametrize('pad', [0, 1, 2])
def test_mono16_both_byte_orders_scale_linearly(bigendian: bool, pad: int) -> None:
    # round(v * 255 / 65535): 0 -> 0, 257 -> 1, 128 -> 0, 129 -> 1, 32896 -> 128, 65535 -> 255
    pixels = np.array([[0, 257, 128], [129, 32896, 65535]], dtype=np.uint16)
    msg = raw(pixels, 'mono16', pad, bigendian)
    assert decode_image(msg).tolist() == [[0, 1, 0], [1, 128, 255]]


def test_mono16_byte_order_matters() -> None:
    # The same two bytes are 65280 little endian and 255 big endian.
    msg = FakeImage('mono16', 1, 1, 2, 0, [0x00, 0xFF])  # little endian 0xFF00 = 65280
    assert decode_image(msg).tolist() == [[254]]
    msg.is_bigendian = 1  # big endian 0x00FF = 255
    assert decode_image(msg).tolist() == [[1]]


def test_rosbags_image_message_decodes() -> None:
    data = np.ascontiguousarray(BGR).reshape(-1)
    msg = T['sensor_msgs/msg/Image'](
        header=T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](sec=0, nanosec=0),
                                        frame_id='camera'),
        height=2, width=3, encoding='bgr8', is_bigendian=0, step=9, data=data)
    assert decode_image(msg).tolist() == GRAY.tolist()


@pytest.mark.parametrize('fmt', ['jpeg', 'png'])
def test_compressed_colour_and_gray(fmt: str) -> None:
    # Flat 16 x 16 blocks survive JPEG almost exactly.
    image = np.zeros((16, 32, 3), np.uint8)
    image[:, :16] = (255, 0, 0)  # blue (BGR)
    image[:, 16:] = (0, 0, 255)  # red
    ok, data = cv2.imencode('.jpg' if fmt == 'jpeg' else '.png', image)
    assert ok
    msg = FakeCompressed(f'bgr8; {fmt} compressed bgr8', np.asarray(data).reshape(-1))
    colour = decode_image(msg, gray=False)
    gray = decode_image(msg)
    tol = 0 if fmt == 'png' else 3
    assert colour.shape == (16, 32, 3)
    assert np.abs(colour[8, 8].astype(int) - [255, 0, 0]).max() <= tol
    assert np.abs(colour[8, 24].astype(int) - [0, 0, 255]).max() <= tol
    assert abs(int(gray[8, 8]) - 29) <= tol and abs(int(gray[8, 24]) - 76) <= tol


def test_compressed_mono_jpeg_and_png16() -> None:
    mono = np.full((8, 8), 200, np.uint8)
    ok, data = cv2.imencode('.jpg', mono)
    assert ok
    out = decode_image(FakeCompressed('mono8; jpeg compressed mono8', data.tobytes()),
                       gray=False)
    assert out.shape == (8, 8) and abs(int(out[4, 4]) - 200) <= 1
    deep = np.full((4, 4), 257 * 100, np.uint16)
    ok, data = cv2.imencode('.png', deep)
    assert ok
    assert decode_image(FakeCompressed('mono16; png compressed mono16', data.tobytes())).tolist() \
        == [[100] * 4] * 4


def test_compressed_format_sniffed_from_magic_bytes() -> None:
    ok, data = cv2.imencode('.png', np.full((2, 2), 9, np.uint8))
    assert ok
    assert decode_image(FakeCompressed('', data.tobytes())).tolist() == [[9, 9], [9, 9]]


def test_encoded_image_pickles_and_decodes_like_the_message() -> None:
    msg = raw(BGR, 'bgr8', 2)
    encoded = EncodedImage.from_message(msg)
    assert isinstance(encoded.data, bytes) and encoded.step == 11 and not encoded.compressed
    again = pickle.loads(pickle.dumps(encoded))
    assert again == encoded
    assert decode_image(again).tolist() == GRAY.tolist()
    ok, data = cv2.imencode('.png', BGR)
    compressed = EncodedImage.from_message(FakeCompressed('png', data))
    assert compressed.compressed and compressed.format == 'png'
    assert decode_image(pickle.loads(pickle.dumps(compressed))).tolist() == GRAY.tolist()


# -- bad input ------------------------------------------------------------------------
def test_step_too_small() -> None:
    msg = FakeImage('bgr8', 480, 640, 1000, 0, b'\0' * 480_000)
    with pytest.raises(ImageDecodeError, match=r'^image 640x480 bgr8 needs step >= 1920, '
                                               r'got 1000$'):
        decode_image(msg)


def test_data_size_disagrees_with_step() -> None:
    msg = FakeImage('mono8', 2, 3, 4, 0, b'\0' * 7)
    with pytest.raises(ImageDecodeError,
                       match=r'^image 3x2 mono8 with step 4 needs 8 bytes of data, got 7$'):
        decode_image(msg)
    msg.data = b'\0' * 9  # too long is wrong too
    with pytest.raises(ImageDecodeError, match='needs 8 bytes of data, got 9'):
        check_image(msg)


def test_unsupported_encoding_and_empty_image() -> None:
    with pytest.raises(ImageDecodeError, match=r"unsupported image encoding 'yuv422' "
                                               r'\(supported: mono8, bgr8'):
        decode_image(FakeImage('yuv422', 1, 2, 4, 0, b'\0' * 4))
    with pytest.raises(ImageDecodeError, match='image 0x4 mono8 has no pixels'):
        decode_image(FakeImage('mono8', 4, 0, 0, 0, b''))


def test_bad_compressed_input() -> None:
    with pytest.raises(ImageDecodeError, match="format 'rgb8; tiff compressed' is not supported"):
        decode_image(FakeCompressed('rgb8; tiff compressed', b'II*\0'))
    with pytest.raises(ImageDecodeError, match='compressedDepth'):
        decode_image(FakeCompressed('16UC1; compressedDepth png', b'\x89PNG\r\n\x1a\n'))
    with pytest.raises(ImageDecodeError, match=r'^cannot decode 10 bytes of jpeg data'):
        decode_image(FakeCompressed('jpeg', b'\xff\xd8\xff' + b'\0' * 7))
    with pytest.raises(ImageDecodeError, match='compressed jpeg image has no data'):
        decode_image(FakeCompressed('jpeg', b''))


def test_not_an_image_message() -> None:
    with pytest.raises(VbnCommonError, match='int is not an image message'):
        decode_image(3)
