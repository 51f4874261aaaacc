"""The clay height-map codec (common/records/heightmap_codec.py) to the exact value: the
reduction factors at the default size limits, the block mean, the uint16 micrometre encoding at
both ends of its range, exact round trips, and the refusal of a payload of the wrong size."""

from __future__ import annotations

import numpy as np
import pytest

from haptic.common.records.heightmap_codec import (
    DEFAULT_MAX_CELLS_X,
    DEFAULT_MAX_CELLS_Y,
    HEIGHT_QUANTUM_M,
    downsample_heights,
    heights_from_bytes,
    heights_to_bytes,
    reduction_factors,
)


def _words(data: bytes) -> list[int]:
    return np.frombuffer(data, "<u2").tolist()


# --- reduction factors ---------------------------------------------------------------------


def test_default_limits_are_256_by_64_cells() -> None:
    """The reduced map is at most 256 x 64 cells by default: one cell more halves that axis."""
    assert (DEFAULT_MAX_CELLS_X, DEFAULT_MAX_CELLS_Y) == (256, 64)
    assert reduction_factors(256, 64) == (1, 1)
    assert reduction_factors(257, 64) == (2, 1)
    assert reduction_factors(256, 65) == (1, 2)
    assert reduction_factors(512, 128) == (2, 2)
    assert reduction_factors(513, 129) == (3, 3)


@pytest.mark.parametrize(("cells", "limits", "factors"), [
    ((0, 0), (256, 64), (1, 1)),
    ((1, 1), (256, 64), (1, 1)),
    ((1, 1), (1, 1), (1, 1)),
    ((10, 7), (1, 1), (10, 7)),
    ((10, 7), (3, 2), (4, 4)),
    ((10, 7), (5, 7), (2, 1)),
    ((1024, 256), (100, 300), (11, 1)),
])
def test_factors_are_the_smallest_integers_that_fit(cells, limits, factors) -> None:
    """Each factor is ceil(cells / limit), at least 1 (an empty grid is not reduced)."""
    assert reduction_factors(*cells, *limits) == factors
    fx, fy = factors
    assert cells[0] // fx <= limits[0] and cells[1] // fy <= limits[1]


# --- the block mean ------------------------------------------------------------------------


def test_block_mean_per_axis_drops_the_edge_cells() -> None:
    """fx averages along x (columns), fy along y (rows); cells short of a block are dropped."""
    heights = np.arange(5 * 7, dtype=float).reshape(5, 7)  # value = 7 y + x
    reduced = downsample_heights(heights, (3, 2))  # blocks of 3 columns by 2 rows
    assert reduced.shape == (2, 2) and reduced.dtype == np.float64
    # block (j, i) covers rows 2j, 2j + 1 and columns 3i .. 3i + 2: mean 7 (2j + 0.5) + 3i + 1
    assert reduced.tolist() == [[4.5, 7.5], [18.5, 21.5]]
    assert downsample_heights(heights, (7, 1)).tolist() == [[3.0], [10.0], [17.0], [24.0], [31.0]]
    assert downsample_heights(heights, (1, 5)).tolist() == [[14.0, 15.0, 16.0, 17.0, 18.0, 19.0,
                                                             20.0]]


def test_factor_one_copies_the_map() -> None:
    """Factors (1, 1) give the map itself as a new float64 array, the input untouched."""
    heights = np.array([[0.001, 0.002, 0.003], [0.004, 0.005, 0.006]])
    reduced = downsample_heights(heights, (1, 1))
    assert np.array_equal(reduced, heights) and reduced is not heights
    reduced[0, 0] = 1.0
    assert heights[0, 0] == 0.001


@pytest.mark.parametrize(("shape", "factors", "reduced_shape"), [
    ((0, 0), (1, 1), (0, 0)),
    ((1, 1), (1, 1), (1, 1)),
    ((1, 1), (2, 1), (1, 0)),
    ((1, 1), (1, 2), (0, 1)),
    ((3, 5), (6, 1), (3, 0)),
])
def test_maps_smaller_than_a_block_reduce_to_empty(shape, factors, reduced_shape) -> None:
    """Empty and 1-cell maps reduce without error; an axis shorter than a block comes out empty."""
    heights = np.full(shape, 0.002)
    reduced = downsample_heights(heights, factors)
    assert reduced.shape == reduced_shape
    assert np.all(reduced == 0.002)
    assert heights_to_bytes(reduced) == (2000).to_bytes(2, "little") * reduced.size


def test_block_mean_of_non_finite_heights_stays_non_finite() -> None:
    """A NaN or inf cell makes its own block's mean NaN or inf and leaves the others alone."""
    heights = np.zeros((2, 4))
    heights[0, 0] = np.nan
    heights[1, 3] = np.inf
    reduced = downsample_heights(heights, (2, 2))
    assert np.isnan(reduced[0, 0]) and reduced[0, 1] == np.inf


# --- the encoding --------------------------------------------------------------------------


def test_encoding_is_little_endian_uint16_micrometres_row_major() -> None:
    """Row-major (y rows of x cells), 2 bytes per cell, little-endian, in whole micrometres."""
    assert HEIGHT_QUANTUM_M == 1e-6
    heights = np.array([[1e-6, 258e-6, 0.0], [0.065535, 0.01, 4660e-6]])
    data = heights_to_bytes(heights)
    assert data == bytes([1, 0, 2, 1, 0, 0, 0xFF, 0xFF, 0x10, 0x27, 0x34, 0x12])


@pytest.mark.parametrize(("height_m", "word"), [
    (0.0, 0), (-0.0, 0), (0.4e-6, 0), (0.6e-6, 1), (1.4e-6, 1), (1.6e-6, 2),
    (0.0123454, 12345), (0.0123456, 12346),
    (-1e-9, 0), (-0.4e-6, 0), (-0.001, 0), (-np.inf, 0),
    (0.065534, 65534), (0.065535, 65535), (0.0655354, 65535),
    (0.0655356, 65535), (0.065536, 65535), (0.070, 65535), (1.0, 65535), (np.inf, 65535),
])
def test_quantisation_rounds_to_the_micrometre_and_clips_at_both_ends(height_m, word) -> None:
    """Nearest micrometre; below 0 gives 0, above 65.535 mm gives 65535 (no wrap-around)."""
    assert _words(heights_to_bytes(np.array([height_m]))) == [word]


def test_exact_round_trip_of_whole_micrometres() -> None:
    """Whole micrometres in 0 .. 65535 come back as exactly k x 1e-6 m, in shape (y, x)."""
    k = np.array([[0, 1, 2, 255], [256, 32767, 65534, 65535], [4660, 1000, 50000, 7]])
    heights = k * HEIGHT_QUANTUM_M
    back = heights_from_bytes(heights_to_bytes(heights), 4, 3)
    assert back.shape == (3, 4) and back.dtype == np.float64
    assert np.array_equal(back, heights)
    assert heights_to_bytes(back) == heights_to_bytes(heights)


def test_round_trip_error_is_at_most_half_a_micrometre() -> None:
    """Heights within the range come back within half a micrometre (seeded, 10 000 cells)."""
    heights = np.random.default_rng(5).uniform(0.0, 0.0655, (100, 100))
    back = heights_from_bytes(heights_to_bytes(heights), 100, 100)
    assert np.abs(back - heights).max() <= 0.5e-6 + 1e-15


def test_empty_and_one_cell_maps_round_trip() -> None:
    """An empty map is zero bytes and back; a one-cell map is two bytes and back."""
    assert heights_to_bytes(np.zeros((0, 0))) == b""
    assert heights_from_bytes(b"", 0, 0).shape == (0, 0)
    assert heights_from_bytes(b"", 5, 0).shape == (0, 5)
    one = heights_to_bytes(np.array([[0.00321]]))
    assert one == (3210).to_bytes(2, "little")
    assert heights_from_bytes(one, 1, 1).tolist() == [[3210 * 1e-6]]


@pytest.mark.parametrize(("data", "cells_x", "cells_y"), [
    (b"\x00" * 6, 2, 2),  # one cell short
    (b"\x00" * 10, 2, 2),  # one cell too many
    (b"\x00" * 7, 2, 2),  # half a cell
    (b"\x00" * 3, 1, 1),
    (b"\x00", 0, 0),
    (b"\x00" * 8, 4, 2),
    (b"\x00" * 8, 0, 4),
])
def test_a_payload_of_the_wrong_size_is_refused(data, cells_x, cells_y) -> None:
    """Bytes that are not exactly cells_x x cells_y uint16 words raise ValueError."""
    with pytest.raises(ValueError):
        heights_from_bytes(data, cells_x, cells_y)


def test_a_nan_height_is_zero_micrometres_without_a_warning() -> None:
    """A NaN height quantises to 0 by definition, not by numpy's undefined cast."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data = heights_to_bytes(np.array([[np.nan, 2e-6, np.inf, -np.inf]]))
    assert _words(data) == [0, 2, 65535, 0]


@pytest.mark.parametrize(("data", "cells_x", "cells_y"), [
    (b"\x00" * 4, -1, 2), (b"\x00" * 4, 2, -1), (b"\x00" * 4, -2, -1), (b"", -1, 0),
    (b"", 0, -1)])
def test_a_negative_cell_count_is_refused(data, cells_x, cells_y) -> None:
    """A negative cell count is refused by the codec itself, even where the byte count
    matches (numpy would infer the shape, or fail with its own error)."""
    with pytest.raises(ValueError, match="uint16 heights"):
        heights_from_bytes(data, cells_x, cells_y)
