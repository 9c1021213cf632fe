"""A public check of the prediction contract, in the spirit of scikit-learn's ``check_estimator``.

:func:`check_predictor` runs over any model family (``interprim.models.registry.FAMILIES``, the blend, a user's own
class written against :class:`interprim.models.base.Predictor`) and raises ``AssertionError`` naming the first
property that fails.  The project's tests run it over every registered family and the default model.
"""

from __future__ import annotations

import json
import tempfile
import warnings
from pathlib import Path

import numpy as np

__all__ = ["check_predictor", "jittered_demonstrations", "object_snapshot"]


def jittered_demonstrations(n: int = 8, seed: int = 0, jitter: float = 0.3):
    """Synthetic two-agent demonstrations (2 observed + 3 controlled columns) with irregular time stamps, as a ROS
    export has them: intervals of 10 ms times ``1 +- jitter`` (uniform), so no common ``dt`` exists.

    Returns ``(Demonstrations, true durations in s)``."""
    from .datasets import Demonstrations
    from .synthetic import two_agent_demos

    rng = np.random.default_rng(seed)
    demos, times = [], []
    for d in two_agent_demos(n, seed=seed):
        steps = 0.01 * (1.0 + jitter * rng.uniform(-1.0, 1.0, len(d) - 1))
        times.append(np.concatenate([[0.0], np.cumsum(steps)]))
        demos.append(d)
    ds = Demonstrations(demos, times, [f"c{i}" for i in range(demos[0].shape[1])], dt=None, observed_dofs=[0, 1])
    return ds, [float(t[-1]) for t in times]


def _state_text(model) -> str:
    arrays, meta = model.to_state()
    digest = {k: np.asarray(v).tobytes().hex()[:4096] + str(np.asarray(v).shape) for k, v in sorted(arrays.items())}
    return json.dumps([digest, meta], sort_keys=True, default=repr)


def object_snapshot(obj, _seen=None):
    """A deep, comparable copy of everything ``obj`` holds: its ``__dict__`` (and ``__slots__``) followed into the
    objects, lists, tuples and dicts it refers to, arrays by value (dtype, shape and bytes).

    Two snapshots compare equal (``==``) when nothing reachable from ``obj`` was written in between (scikit-learn's
    ``check_dict_unchanged``, followed into nested objects).  A :class:`~interprim.core.cache.DerivedCache` (a
    declared store of values computed from the fitted state, filled on first use) is compared by identity only;
    functions, modules and classes by identity.
    """
    seen = {} if _seen is None else _seen
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes)):
        return (type(obj).__name__, repr(obj))
    if isinstance(obj, np.generic):
        return ("np", obj.dtype.str, obj.tobytes())
    if isinstance(obj, np.ndarray):
        if obj.dtype == object:
            return ("ndarray[object]", obj.shape, tuple(object_snapshot(v, seen) for v in obj.ravel()))
        return ("ndarray", obj.dtype.str, obj.shape, np.ascontiguousarray(obj).tobytes())
    from .core.cache import DerivedCache

    if isinstance(obj, DerivedCache) or callable(obj) and not hasattr(obj, "__dict__") \
            or isinstance(obj, (type, type(json))) or hasattr(obj, "__code__"):
        return ("identity", type(obj).__name__, id(obj))
    key = id(obj)
    if key in seen:
        return ("seen", seen[key])
    seen[key] = len(seen)
    if isinstance(obj, (list, tuple)):
        return (type(obj).__name__, tuple(object_snapshot(v, seen) for v in obj))
    if isinstance(obj, (set, frozenset)):
        return (type(obj).__name__, tuple(sorted(repr(v) for v in obj)))
    if isinstance(obj, dict):
        return ("dict", tuple((repr(k), object_snapshot(v, seen)) for k, v in obj.items()))
    fields = dict(getattr(obj, "__dict__", {}))
    for cls in type(obj).__mro__:
        for name in getattr(cls, "__slots__", ()):
            if isinstance(name, str) and hasattr(obj, name):
                fields[name] = getattr(obj, name)
    return (type(obj).__qualname__, tuple((k, object_snapshot(v, seen)) for k, v in sorted(fields.items())))


def _changed(before, after, path="model") -> str:
    """The first place where two :func:`object_snapshot` results differ (for the message)."""
    if before == after:
        return ""
    if (isinstance(before, tuple) and isinstance(after, tuple) and len(before) == len(after) == 2
            and before[0] == after[0] and isinstance(before[1], tuple) and isinstance(after[1], tuple)):
        b, a = before[1], after[1]
        if all(isinstance(x, tuple) and len(x) == 2 and isinstance(x[0], str) for x in b + a):
            bd, ad = dict(b), dict(a)
            for k in list(bd) + [k for k in ad if k not in bd]:
                if k not in ad:
                    return f"{path}.{k} (removed)"
                if k not in bd:
                    return f"{path}.{k} (added)"
                if bd[k] != ad[k]:
                    return _changed(bd[k], ad[k], f"{path}.{k}")
    return path


def check_predictor(make, demos=None, dt: float = 0.01, rtol: float = 1e-6) -> dict:
    """Check that a model family honours the prediction contract; returns what was measured.

    Checks, in order: ``predict`` before ``fit`` raises ``NotFittedError``; ``fit`` returns the model; ``predict``
    leaves the fitted state and everything else the model holds unchanged (:func:`object_snapshot`, before and
    after, as scikit-learn's ``check_dict_unchanged``; so does a stream's ``update``); irregular time stamps give
    the recorded durations; ``save`` ->
    :func:`interprim.load_any` gives the same predictions; ``clone`` (``type(m)(**m.get_params())``) fits to the same
    predictions; the stream equals ``predict`` frame by frame; ``input_distance`` is finite and ``out_of_range``
    False on held-out frames, True (with one ``OutOfRangeWarning``) on frames in millimetres.  (That the
    server's worker processes serve every model file is tested with ``interprim serve --processes``.)

    Parameters
    ----------
    make : callable
        A zero-argument factory of an unfitted model whose ``observed_dofs`` are ``[0, 1]`` of the synthetic
        demonstrations (e.g. ``lambda: KernelDemonstrations([0, 1])``).
    demos : list of ndarray, optional
        Training demonstrations (default: :func:`interprim.synthetic.two_agent_demos`, 8 of them); the last one is
        held out.
    rtol : float
        Relative tolerance of "the same prediction" (stream against predict, loaded against saved).
    """
    from .core.errors import NotFittedError, OutOfRangeWarning
    from .models.files import load_any
    from .synthetic import two_agent_demos

    demos = two_agent_demos(8, seed=3) if demos is None else demos
    train, held = list(demos[:-1]), np.asarray(demos[-1], dtype=np.float64)
    out: dict = {}
    model = make()
    try:
        model.predict(held[:10, :2])
    except NotFittedError:
        pass
    else:
        raise AssertionError("predict before fit did not raise NotFittedError")
    assert model.fit(train, dt=dt) is model, "fit must return the model"
    partial = held[: max(10, int(0.5 * len(held))), :2]
    before, whole = _state_text(model), object_snapshot(model)
    pred = model.predict(partial)
    assert _state_text(model) == before, "predict changed the model's fitted state"
    where = _changed(whole, object_snapshot(model))
    assert not where, f"predict changed the model: {where}"
    Y = pred.trajectory(50)
    assert Y.shape == (50, held.shape[1]) and np.all(np.isfinite(Y)), f"trajectory(50) has shape {Y.shape}"

    ds, durations = jittered_demonstrations(len(train) + 1, seed=1)
    jm = make().fit(ds)
    got = float(getattr(jm, "mean_duration_", np.nan))  # every model says its demonstrations' mean duration (s)
    want = float(np.mean(durations))
    out["jittered_duration"] = (got, want)
    assert abs(got - want) <= 0.05 * want, f"irregular time stamps: mean duration {got:.3f} s, recorded {want:.3f} s"

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "model.npz"
        model.save(path)
        back = load_any(path)
        assert type(back) is type(model), f"load_any gave a {type(back).__name__}"
        Yb = back.predict(partial).trajectory(50)
        assert np.allclose(Yb, Y, rtol=rtol, atol=rtol * max(1.0, float(np.abs(Y).max()))), \
            "save -> load_any changed the prediction"

    clone = type(model)(**model.get_params(deep=False)).fit(train, dt=dt)
    assert np.allclose(clone.predict(partial).trajectory(50), Y, rtol=rtol,
                       atol=rtol * max(1.0, float(np.abs(Y).max()))), \
        "a clone fitted on the same demonstrations predicts differently"

    whole = object_snapshot(model)
    stream = model.stream()
    worst = 0.0
    for k, f in enumerate(partial, start=1):
        p = stream.update(f)
        if k == 10:
            where = _changed(whole, object_snapshot(model))
            assert not where, f"the stream changed the model: {where}"
        if k % 7 == 0 or k == len(partial):
            a, b = p.trajectory(50), model.predict(partial[:k]).trajectory(50)
            worst = max(worst, float(np.max(np.abs(a - b)) / max(1.0, float(np.abs(b).max()))))
    out["stream_vs_predict"] = worst
    assert worst <= rtol, f"the stream differs from predict by {worst:.3g} (relative)"

    assert np.isfinite(pred.input_distance) and not pred.out_of_range, \
        f"held-out frames: input_distance {pred.input_distance}, out_of_range {pred.out_of_range}"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        bad = model.predict(partial * 1000.0)
    assert bad.out_of_range, "frames in millimetres were not flagged out_of_range"
    n_warn = sum(issubclass(w.category, OutOfRangeWarning) for w in caught)
    assert n_warn == 1, f"{n_warn} OutOfRangeWarnings for one prediction out of range (expected 1)"
    return out
