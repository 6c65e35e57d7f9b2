"""``lts360 calibrate``'s corner detection while rendering (:class:`_EarlyCorners`): the
corners it hands over are the detector's on the written image, and only for the board the
manifest names."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from lts360.recon.calibration.board import BoardGeometry

cv2 = pytest.importorskip("cv2", reason="calibration needs OpenCV")


def _board_image(square_px: int = 24, squares=(9, 7), border: int = 60) -> np.ndarray:
    """A sharp chessboard (dark/light squares), blurred a little, on a light background."""
    h, w = squares[1] * square_px + 2 * border, squares[0] * square_px + 2 * border
    img = np.full((h, w), 200, np.uint8)
    for j in range(squares[1]):
        for i in range(squares[0]):
            if (i + j) % 2 == 0:
                y, x = border + j * square_px, border + i * square_px
                img[y:y + square_px, x:x + square_px] = 30
    return cv2.GaussianBlur(img, (5, 5), 1.0)


def test_early_corners_are_the_detectors_on_the_written_image(tmp_path):
    from lts360.experiments.calibration_run import _EarlyCorners
    from lts360.recon.calibration.camera import detect_corners
    from lts360.recon.images import read_image

    board = SimpleNamespace(pattern_size=(8, 6), square_mm=8.0)
    shots = [SimpleNamespace(name="camera-00", kind="camera", board=board),
             SimpleNamespace(name="mirror-left-00", kind="mirror", board=board)]
    cv2.imwrite(str(tmp_path / "camera-00.png"), _board_image())
    early = _EarlyCorners(shots)
    early.add("camera-00", tmp_path)
    early.add("mirror-left-00", tmp_path)  # not a camera shot: nothing to read
    geo = BoardGeometry((8, 6), 8.0)
    got = early.result(geo)
    assert set(got) == {"camera-00"}
    expected = detect_corners(read_image(tmp_path / "camera-00.png"), geo)
    assert expected is not None and np.array_equal(got["camera-00"], expected)

    other = _EarlyCorners(shots)
    other.add("camera-00", tmp_path)
    assert other.result(BoardGeometry((8, 6), 5.0)) == {}  # another board: nothing handed over
    assert _EarlyCorners(shots[1:]).result(geo) == {}
