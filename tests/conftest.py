import numpy as np
import pytest


@pytest.fixture
def rng():
    """A fixed-seed generator for exact (non-statistical) tests."""
    return np.random.default_rng(20261122)


def random_unit_quaternions(rng, n):
    q = rng.standard_normal((n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)
