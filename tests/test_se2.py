"""SE(2) helpers: a single pose takes a float path that must give the array path's bits; dead reckoning of
commanded twists."""
import numpy as np
import pytest

from omninav.geometry.se2 import compose, inverse, relative, se2_exp


def poses(rng: np.random.Generator, n: int) -> np.ndarray:
    """Small and large values, exact zeros and headings at ±pi: where rounding differs if anything does."""
    return np.concatenate([rng.normal(0.0, 1e-3, (n, 3)), rng.uniform(-5.0, 5.0, (n, 3)), np.zeros((3, 3)),
                           [[0.0, 0.0, np.pi], [0.0, 0.0, -np.pi], [1.0, -2.0, 3.14159265], [0.0, 0.0, 1e-300]]])


@pytest.mark.parametrize("name,one,many", [
    ("compose", lambda a, b: compose(a, b), lambda a, b: compose(a, b)),
    ("inverse", lambda a, _b: inverse(a), lambda a, _b: inverse(a)),
    ("relative", lambda a, b: relative(a, b), lambda a, b: relative(a, b)),
    ("se2_exp", lambda a, _b: se2_exp(a), lambda a, _b: se2_exp(a)),
])
def test_single_poses_give_the_bits_of_the_array_path(name, one, many):
    rng = np.random.default_rng(7)
    a, b = poses(rng, 2000), poses(rng, 2000)
    singles = np.array([one(x, y) for x, y in zip(a, b)])
    assert singles.tobytes() == many(a, b).tobytes(), name      # bytes: signed zeros too


def test_se2_exp_of_a_pure_translation_and_a_quarter_turn():
    assert se2_exp([1.0, 2.0, 0.0]).tolist() == [1.0, 2.0, 0.0]
    x, y, phi = se2_exp([np.pi / 2, 0.0, np.pi / 2])                 # a quarter circle of radius 1
    assert (x, y, phi) == pytest.approx((1.0, 1.0, np.pi / 2))
