"""One BLAS thread at the public numeric calls (interprim.core.blas): in force during the call, restored after it,
the same numbers with any thread count, and the path switch of the kernel loader only between calls."""

import threading

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import interprim as ip
from interprim.core import blas as _blas
from interprim.core._compiled import loader
from interprim.models.primitive.prediction import Prediction
from interprim.synthetic import two_agent_demos


def _blas_counts():
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


@pytest.fixture(scope="module")
def model():
    return ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=10).fit(two_agent_demos(8, seed=3, frames=120),
                                                                          dt=0.01)


@pytest.fixture(scope="module")
def human():
    return two_agent_demos(1, seed=11, frames=120)[0][:, :2]


def test_one_thread_during_std_restored_after(model, human, monkeypatch):
    seen = []
    inner = Prediction._posterior_std

    def spy(self, n):
        seen.append(_blas_counts())
        return inner(self, n)

    monkeypatch.setattr(Prediction, "_posterior_std", spy)
    with threadpool_limits(2, user_api="blas"):
        before = _blas_counts()
        assert before and all(c == 2 for c in before)
        p = model.predict(human[:60])
        p.std(50)
        assert seen and all(c == 1 for c in seen[-1]), seen  # in force inside the call
        assert _blas_counts() == before  # restored after it


@pytest.mark.parametrize("entry", ["fit", "predict", "update", "posterior_cov", "samples"])
def test_one_thread_at_every_public_entry(model, human, monkeypatch, entry):
    """The limit is in force in the numeric core of each public call (spied on one inner function each)."""
    from interprim.models.primitive import fitted, prediction

    seen = []

    def spy_on(owner, name):
        inner = getattr(owner, name)

        def spy(*a, **k):
            seen.append(_blas_counts())
            return inner(*a, **k)

        monkeypatch.setattr(owner, name, spy)

    with threadpool_limits(2, user_api="blas"):
        if entry == "fit":
            spy_on(fitted, "fit_prior")
            ip.InteractionPrimitive(observed_dofs=[0, 1], n_basis=6, sigma2=1e-3, phase_method="dtw",
                                    calibrate=False).fit(two_agent_demos(5, seed=1, frames=80), dt=0.01)
        elif entry == "predict":
            spy_on(type(model.fitted_), "condition")
            model.predict(human[:40])
        elif entry == "update":
            spy_on(type(model.fitted_), "predict_latent")
            s = model.stream()
            for f in human[:5]:
                s.update(f)
        elif entry == "posterior_cov":
            s = model.stream()
            for f in human[:30]:
                p = s.update(f)  # mean only: the covariance is computed on first access
            spy_on(type(model.fitted_), "condition")
            _ = p.posterior_cov  # computed on this first access
        else:
            p = model.predict(human[:40])
            spy_on(prediction, "sample")
            spy_on(type(p), "_latent_traj")
            p.samples(3, 20, random_state=0)
        assert seen and all(all(c == 1 for c in counts) for counts in seen), seen
        assert all(c == 2 for c in _blas_counts())


def test_same_numbers_with_any_thread_count(model, human):
    """One input, one answer: the default thread count around the call changes nothing."""
    out = {}
    for n_threads in (1, 2):
        with threadpool_limits(n_threads, user_api="blas"):
            p = model.predict(human[:70])
            s = model.stream()
            for f in human[:30]:
                q = s.update(f)
            out[n_threads] = (p.trajectory(40), p.std(40), p.samples(4, 40, random_state=1), q.response(30)[1],
                              q.std(20))
    for a, b in zip(out[1], out[2]):
        np.testing.assert_array_equal(a, b)


def test_undecorated_call_agrees(model, human):
    """The wrapped function run with two BLAS threads gives the wrapped call's numbers to rounding."""
    p = model.predict(human[:70])
    ref = p.std(40)
    q = model.predict(human[:70])
    with threadpool_limits(2, user_api="blas"):
        raw = Prediction.std.__wrapped__(q, 40)
    np.testing.assert_allclose(raw, ref, rtol=1e-10, atol=1e-14)


def test_nested_and_concurrent_calls_restore_the_pools(model, human):
    with threadpool_limits(2, user_api="blas"):
        with _blas.single_thread():
            with _blas.single_thread():
                assert _blas.depth() == 2 and all(c == 1 for c in _blas_counts())
            assert _blas.depth() == 1 and all(c == 1 for c in _blas_counts())
        assert _blas.depth() == 0 and all(c == 2 for c in _blas_counts())
        errors = []

        def work():
            try:
                s = model.stream()
                for f in human[:20]:
                    s.update(f).std(10)
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)

        threads = [threading.Thread(target=work) for _ in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert not errors
        assert _blas.depth() == 0 and all(c == 2 for c in _blas_counts())


def test_a_callers_own_limit_outlives_the_calls(model, human):
    """A caller that runs BLAS on one thread (a controller pinning its threads) keeps it after the library's calls,
    from its own thread and from others: the thread-local count was reset with 0, which put OpenBLAS's global count
    back to the machine's default (two threads here), and every later product of the caller's ran on two."""
    with threadpool_limits(1, user_api="blas"):
        assert all(c == 1 for c in _blas_counts())
        model.predict(human[:60]).std(20)
        assert _blas.depth() == 0 and all(c == 1 for c in _blas_counts())
        t = threading.Thread(target=lambda: model.stream().update(human[0]).std(5))
        t.start()
        t.join()
        assert all(c == 1 for c in _blas_counts())


def test_exception_inside_a_call_restores_the_pools(model):
    with threadpool_limits(2, user_api="blas"):
        with pytest.raises(ValueError):
            model.predict(np.full((5, 3), np.nan))
        assert _blas.depth() == 0 and all(c == 2 for c in _blas_counts())


def test_loader_switches_only_between_public_calls(monkeypatch):
    """Cold cache: numpy until the kernels are loaded, then the kernels from the next outermost call on."""
    assert loader.warmup()
    monkeypatch.setattr(loader, "_READY", None)
    monkeypatch.setattr(loader, "_PENDING", True)
    monkeypatch.setattr(loader, "_LOADED", threading.Event())
    try:
        assert loader.ready() is False  # still compiling
        with _blas.single_thread():
            assert loader.ready() is False
            loader._LOADED.set()
            loader._arm_switch()
            assert loader.ready() is False  # loaded, but inside a call: the path stays
            with _blas.single_thread():
                assert loader.ready() is False
        with _blas.single_thread():  # the next call starts on the kernels
            assert loader.ready() is True
        assert _blas._HOOK[0] is None
    finally:
        _blas.on_outer_entry(None)


def _local_counts():
    """The calling thread's OpenBLAS count as ``openblas_set_num_threads_local`` reports it (read by setting it to
    the value it returns, i.e. left unchanged)."""
    out = []
    for fn in _blas._local_setters():
        prev = fn(1)
        fn(prev)
        out.append(prev)
    return out


def test_one_thread_in_a_thread_that_does_not_own_the_count(model, human, monkeypatch):
    """OpenBLAS ignores ``openblas_set_num_threads`` from any thread but the first to set it (the server's event loop
    after a warm-up in an executor thread): the library's calls there still run on one thread, through OpenBLAS's
    thread-local count, and leave it unset afterwards."""
    if not _blas._local_setters():
        pytest.skip("no OpenBLAS with openblas_set_num_threads_local is loaded")  # e.g. an MKL build of numpy
    with threadpool_limits(2, user_api="blas"):  # this (pytest's) thread now owns the global count
        seen, after, errors = [], [], []
        inner = Prediction._posterior_std

        def spy(self, n):
            seen.append(_local_counts())
            return inner(self, n)

        monkeypatch.setattr(Prediction, "_posterior_std", spy)

        def work():
            try:
                _blas._THREAD.__dict__.clear()
                model.predict(human[:60]).std(20)
                after.append(_blas._THREAD.depth)
            except Exception as exc:  # noqa: BLE001
                errors.append(exc)

        t = threading.Thread(target=work)
        t.start()
        t.join()
        assert not errors, errors
        assert seen and all(c == 1 for c in seen[-1]), seen
        assert after == [0]


@pytest.mark.parametrize("family", sorted(__import__("interprim.models.registry", fromlist=["FAMILIES"]).FAMILIES))
def test_every_family_limits_its_numeric_calls(family):
    """The contract wraps every family's fit/predict, its stream's update/extend and its prediction's accessors
    (interprim.models.base: limit_methods), so a family cannot forget one (a server turn's extend did)."""
    from interprim.models import base, registry

    cls = registry.FAMILIES[family].cls
    for name in ("fit", "predict"):
        assert getattr(getattr(cls, name), "__interprim_one_blas__", False), (family, name)
    def walk(c):
        for sub in c.__subclasses__():
            yield sub
            yield from walk(sub)

    for root, names in ((base.BaseStream, ("update", "extend")), (base.BasePrediction, base._PREDICTION_CALLS)):
        subs = list(walk(root))
        assert subs
        for sub in subs:
            for name in names:
                if name in sub.__dict__ and not isinstance(sub.__dict__[name], property):
                    assert getattr(sub.__dict__[name], "__interprim_one_blas__", False), (sub, name)


def test_scipys_blas_is_limited_from_the_first_call_of_a_process():
    """scipy's own BLAS (loaded with scipy.linalg) runs on one thread inside the very first call of a process, even
    when nothing had loaded scipy.linalg before: a fresh interpreter enters the limiter, then imports it."""
    import subprocess
    import sys

    code = ("import sys, interprim\n"
            "from interprim.core.blas import single_thread\n"
            "from threadpoolctl import threadpool_info\n"
            "with single_thread():\n"
            "    import scipy.linalg\n"
            "    print(sorted({i['num_threads'] for i in threadpool_info() if i['user_api'] == 'blas'}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[1]"
