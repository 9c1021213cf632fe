import os

import numpy as np
import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

SHARED = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", "shared"))


@pytest.fixture(scope="session", autouse=True)
def _compiled_kernels():
    """Load (on a fresh clone: compile) the compiled kernels before the first test, as every run after an
    install has them: results then never depend on how far a background compilation has got, and numba's cache
    is filled for the tests that start fresh interpreters.  The first run after an install, on numpy while the
    kernels compile, is tested in tests/compiled/test_cold_start.py."""
    from interprim.core._compiled import loader

    loader.warmup()


@pytest.fixture(scope="session")
def synthetic():
    from interprim.synthetic import two_agent_demos

    return two_agent_demos(30, seed=0), two_agent_demos(8, seed=5)


@pytest.fixture(scope="session")
def fitted(synthetic):
    import interprim as ip

    train, _ = synthetic
    return ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=20).fit(train, dt=0.01)


@pytest.fixture(scope="session")
def fitted_paper(synthetic):
    """The paper's configuration exactly: forcing-value observation (Eq. 15), sigma2 from the fit residual,
    open-end DTW phase (Eq. 5-9)."""
    import interprim as ip

    train, _ = synthetic
    return ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=20, observation="forcing", sigma2="residual",
                                   phase_method="dtw").fit(train, dt=0.01)


@pytest.fixture(scope="session")
def blend_parts():
    """``(demos, dt, members)``: two cheap fitted members (the nearest demonstration and the mean) of 8 noisy
    synthetic demonstrations, for tests that build blends by hand (:meth:`interprim.models.blend.Blend.from_fitted`)."""
    from interprim.models.demonstrations import NearestNeighbour, PriorMean
    from interprim.synthetic import two_agent_demos

    demos = two_agent_demos(8, seed=2, frames=80, noise=0.01)
    dt = 0.05
    members = {"nn": NearestNeighbour([0, 1]).fit(demos, dt=dt), "prior": PriorMean([0, 1]).fit(demos, dt=dt)}
    return demos, dt, members


@pytest.fixture
def rng():
    return np.random.default_rng(1234)
