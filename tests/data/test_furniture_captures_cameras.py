"""Furniture capture sets under cameras never seen in training: another field of view and size
frame the whole piece; a distance range, which the bounds framing does not use, is refused."""

import math

import numpy as np
import pytest

from nfr_drake.data.capture import read_capture_set
from nfr_drake.data.captures import captures_command
from nfr_drake.errors import ConfigError


def test_another_field_of_view_and_size_frame_the_piece(tmp_path):
    captures_command("furniture", n=1, out=tmp_path, views=2, size=20, fov_y_deg=35.0, seed=1)
    capture = read_capture_set(tmp_path / "furniture_000")
    camera = capture.frames[0].camera
    assert (camera.width, camera.height) == (20, 20)
    assert 2 * math.degrees(math.atan(10 / camera.fy)) == pytest.approx(35.0)
    assert all(np.asarray(image).shape == (20, 20, 3) for image in capture.load_images())


def test_a_distance_range_is_refused_where_the_bounds_frame_the_cameras(tmp_path):
    # Before, --distance-m 1.2 2.3 (the closets' unseen-camera sets) was silently dropped for furniture.
    with pytest.raises(ConfigError, match="--distance-m: unused with framing bounds"):
        captures_command("furniture", n=1, out=tmp_path, views=2, size=20, distance_m=(1.2, 2.3))
    captures_command("furniture", n=1, out=tmp_path, views=2, size=20, distance_m=(1.2, 2.3),
                     framing="distance")
    assert (tmp_path / "furniture_000" / "gt.json").is_file()
