"""The exact distance transform with nearest cells (geometry/distance.py) against scipy's."""
import numpy as np
from scipy import ndimage

from omninav.geometry.distance import distances_to, nearest_cells


def test_nearest_cells_match_scipys_distance_transform_and_are_sources():
    rng = np.random.default_rng(3)
    for _ in range(40):
        shape = tuple(int(n) for n in rng.integers(1, 200, size=2))
        sources = rng.random(shape) < rng.random() * 0.3
        squared, rows, cols = nearest_cells(sources)
        if not sources.any():
            assert np.isinf(squared).all() and (rows == -1).all() and (cols == -1).all()
            continue
        expected = ndimage.distance_transform_edt(~sources)
        np.testing.assert_array_equal(distances_to(sources), expected)      # to the bit: replay compares outputs
        assert sources[rows, cols].all()
        here_rows, here_cols = np.indices(shape)
        np.testing.assert_array_equal((rows - here_rows) ** 2 + (cols - here_cols) ** 2, squared)
