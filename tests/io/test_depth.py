"""Depth maps as read: as stored (read_stored_depth), in metres (read_depth), and the one conversion between them."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from o3d_seqcc.errors import InputError
from o3d_seqcc.io.depth import depth_in_metres, read_depth, read_stored_depth
from o3d_seqcc.io.mesh_files import MAX_COORDINATE
from o3d_seqcc.visibility.depthmaps import DepthImage


def _png16(path, counts: np.ndarray):
    ok, buf = cv2.imencode(".png", counts)
    assert ok
    path.write_bytes(buf.tobytes())
    return path


def test_stored_and_metres_are_one_conversion(tmp_path):
    counts = np.arange(12, dtype=np.uint16).reshape(3, 4) * 500
    p = _png16(tmp_path / "d.png", counts)
    stored = read_stored_depth(p, shape=(3, 4))
    assert stored.dtype == np.uint16 and np.array_equal(stored, counts)
    metres = read_depth(p, 1000.0, shape=(3, 4))
    assert metres.dtype == np.float64 and metres.shape == (3, 4)
    assert np.array_equal(metres, depth_in_metres(stored, 1000.0))
    assert np.array_equal(metres, counts / 1000.0)
    held = DepthImage(counts=stored, scale=1000.0)  # a 16-bit map kept as its counts gives the same bits
    assert np.array_equal(held.image(), metres)
    assert np.array_equal(held.at(np.array([2]), np.array([3])), metres[2:3, 3])


def test_conversion_marks_missing_depth():
    d = np.array([1.5, -1.0, np.nan, np.inf, 2 * MAX_COORDINATE], np.float64)
    assert depth_in_metres(d, 1.0).tolist() == [1.5, 0.0, 0.0, 0.0, 0.0]


def test_stored_depth_checks_the_shape(tmp_path):
    p = _png16(tmp_path / "d.png", np.ones((3, 4), np.uint16))
    with pytest.raises(InputError, match="is 4x3 but the view is 5x2"):
        read_stored_depth(p, shape=(2, 5))
    with pytest.raises(InputError, match="depth map not found"):
        read_stored_depth(tmp_path / "missing.png")
