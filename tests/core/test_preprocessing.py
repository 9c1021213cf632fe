"""Pre-processing (Sec. IV): the one resampling rule, :func:`interprim.core.preprocessing.interp_columns`."""

import numpy as np

from interprim.core.preprocessing import interp_columns


def test_interp_columns_is_numpy_interp_of_every_column_bit_for_bit():
    """It calls numpy.interp's C routine directly (arrays converted once): the same bits as numpy.interp per column,
    inside, outside and exactly on the sample positions, for any layout of ``y`` and a scalar ``x_new``."""
    rng = np.random.default_rng(0)
    for trial in range(200):
        n, D = int(rng.integers(2, 60)), int(rng.integers(1, 9))
        x = np.sort(rng.uniform(-1.0, 2.0, n)) if trial % 2 else np.linspace(0.0, 1.0, n)
        y = rng.normal(size=(n, D)) * 10.0 ** rng.integers(-4, 5)
        if trial % 3 == 0:
            y = np.asfortranarray(y)
        x_new = rng.uniform(-1.5, 2.5, int(rng.integers(1, 80)))
        x_new[::3] = rng.choice(x, x_new[::3].size)
        got = interp_columns(x_new, x, y)
        want = np.stack([np.interp(x_new, x, y[:, d]) for d in range(D)], axis=-1)
        assert got.shape == want.shape and got.flags.c_contiguous
        assert np.array_equal(got, want)
        assert np.array_equal(interp_columns(float(x_new[0]), list(x), y), want[0])
    assert interp_columns(np.zeros(3), [0.0, 1.0], np.zeros((2, 0))).shape == (3, 0)
