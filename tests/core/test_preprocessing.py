"""Pre-processing (Sec. IV): the one resampling rule, :func:`interprim.core.preprocessing.interp_columns`."""

import os
import subprocess
import sys

import numpy as np
import pytest

from interprim.core._compiled import registry
from interprim.core.preprocessing import interp_columns


@pytest.mark.parametrize("path", ["numpy", "compiled"])
def test_interp_columns_is_numpy_interp_of_every_column_bit_for_bit(path):
    """On numpy (numpy.interp's C routine called directly, arrays converted once) and with the compiled kernel
    (``resample.interp_columns``): the same bits as numpy.interp per column, inside, outside and exactly on the
    sample positions, for any layout of ``y``, a read-only grid and a scalar ``x_new``."""
    with registry.forced(path):
        _check_interp_columns()


def _check_interp_columns():
    rng = np.random.default_rng(0)
    for trial in range(200):
        n, D = int(rng.integers(2, 60)), int(rng.integers(1, 9))
        x = np.sort(rng.uniform(-1.0, 2.0, n)) if trial % 2 else np.linspace(0.0, 1.0, n)
        y = rng.normal(size=(n, D)) * 10.0 ** rng.integers(-4, 5)
        if trial % 3 == 0:
            y = np.asfortranarray(y)
        x_new = rng.uniform(-1.5, 2.5, int(rng.integers(1, 80)))
        x_new[::3] = rng.choice(x, x_new[::3].size)
        if trial % 4 == 0:
            x.setflags(write=False)
        got = interp_columns(x_new, x, y)
        want = np.stack([np.interp(x_new, x, y[:, d]) for d in range(D)], axis=-1)
        assert got.shape == want.shape and got.flags.c_contiguous
        assert np.array_equal(got, want)
        assert np.array_equal(interp_columns(float(x_new[0]), list(x), y), want[0])
    assert interp_columns(np.zeros(3), [0.0, 1.0], np.zeros((2, 0))).shape == (3, 0)


def test_interp_columns_never_loads_the_compiled_kernels():
    """Resampling (e.g. of a data file's rows) uses the compiled kernel only once a fit, predict or stream has
    loaded the kernels: on its own it neither imports numba nor decides the compiled path."""
    code = ("import sys, numpy as np\n"
            "from interprim.core.preprocessing import interp_columns\n"
            "from interprim.core._compiled import loader\n"
            "interp_columns(np.linspace(0, 1, 7), np.linspace(0, 1, 5), np.ones((5, 3)))\n"
            "assert 'numba' not in sys.modules and not loader.loaded()\n")
    subprocess.run([sys.executable, "-c", code], check=True, env={**os.environ, "INTERPRIM_JIT": "auto"})
