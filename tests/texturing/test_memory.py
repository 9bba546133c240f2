"""Texture memory (issue 35): a page's bytes on a GPU at RGBA8 with its mip chain."""

import numpy as np
import pytest

from o3d_seqcc.texturing.memory import gpu_bytes, texture_memory


def test_gpu_bytes_known_answers():
    assert gpu_bytes(1, 1) == 4
    assert gpu_bytes(4, 4, mipmaps=False) == 64
    assert gpu_bytes(4, 4) == 4 * (16 + 4 + 1)  # 4x4, 2x2, 1x1
    assert gpu_bytes(8, 2) == 4 * (16 + 4 + 2 + 1)  # 8x2, 4x1, 2x1, 1x1: a side stops at 1, the other halves on
    assert gpu_bytes(5, 3) == 4 * (15 + 2 + 1)  # 5x3, 2x1, 1x1: halved and rounded down
    s = 2048
    assert gpu_bytes(s, s) == 4 * sum((s >> k) ** 2 for k in range(12))  # the 4/3 of the base level, less a little
    assert gpu_bytes(s, s) / gpu_bytes(s, s, mipmaps=False) == pytest.approx(4 / 3, rel=1e-6)
    with pytest.raises(ValueError, match="sides >= 1"):
        gpu_bytes(0, 4)


def test_texture_memory_per_page_and_total():
    rec = texture_memory(1208, 1228, np.array([0.5, 0.25]))
    assert [p["coverage"] for p in rec["pages"]] == [0.5, 0.25]
    assert all((p["width"], p["height"]) == (1208, 1228) for p in rec["pages"])
    assert rec["gpu_bytes"] == 2 * gpu_bytes(1208, 1228) and rec["gpu_bytes_base"] == 2 * 1208 * 1228 * 4
