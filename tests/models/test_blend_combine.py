"""Blend.combine's shortcuts give the numbers of the general rules: the members read are those weighted somewhere on
the grid."""

import numpy as np
import pytest

from interprim.core.preprocessing import unit_grid
from interprim.models.blend import Blend
from interprim.models.grid import GridPrediction

BANDS = [0.25, 0.5, 4.0]


def _same(a, b) -> bool:
    """Equal bit for bit (arrays: dtype, shape and bytes; floats: their bits, NaN included)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (type(a) is type(b) and a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes())
    if isinstance(a, float) and isinstance(b, float):
        return type(a) is type(b) and np.float64(a).tobytes() == np.float64(b).tobytes()
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    return type(a) is type(b) and a == b


def _placed(members, x, dt, phase=None):
    """The members' predictions of the frames ``x``; with ``phase``, tabulated stand-ins that put now there (a
    phase past 1 puts every point of the grid before now)."""
    preds = {m: est.predict(x) for m, est in members.items()}
    if phase is None:
        return preds
    u = unit_grid(Blend.N_GRID)
    return {m: GridPrediction(u, p.trajectory(len(u)), phase=phase * (1.0 - 0.1 * j), duration=len(x) * dt / phase)
            for j, (m, p) in enumerate(preds.items())}


@pytest.mark.parametrize("weights, bands, past, by_side", [
    ({"nn": [0.7, 0.2, 0.1], "prior": [0.3, 0.8, 0.9]}, BANDS, None, True),
    ({"nn": [0.7, 0.2, 0.1], "prior": [0.3, 0.8, 0.9]}, BANDS, {"prior": 1.0}, True),  # nn after now alone
    ({"nn": [0.0, 0.0, 0.0], "prior": [1.0, 1.0, 1.0]}, BANDS, {"nn": 1.0}, True),  # nn before now alone
    ({"nn": [0.0, 0.0, 0.0], "prior": [1.0, 1.0, 1.0]}, BANDS, None, True),  # nn never
    ({"nn": [0.0, 0.0, 0.6], "prior": [1.0, 1.0, 0.4]}, BANDS, {"prior": 1.0}, False),  # nn far ahead alone
    ({"nn": [1e-14, 0.5, 0.5], "prior": [1.0, 0.5, 0.5]}, BANDS, None, False),  # too small to be sure of
    ({"nn": 0.0, "prior": 1.0}, None, {"nn": 0.5, "prior": 0.5}, True),
])
def test_the_members_read_are_those_weighted_somewhere_on_the_grid(blend_parts, weights, bands, past, by_side):
    """The members read from the weights in the bands and the past weights are those the prediction's own weights
    give a nonzero weight somewhere (the rule read from W), with the same numbers, after now and before it."""
    demos, dt, members = blend_parts
    blend = Blend.from_fitted([0, 1], members, weights, None, demos, dt, horizon=0.25, bands=bands, past=past)
    sets = blend._active_by_side
    assert (sets is not None) == by_side
    test = demos[3]
    for k, phase in [(1, None), (2, None), (10, None), (40, None), (79, None), (30, 0.5), (30, 1.0), (30, 1.5)]:
        preds = _placed(members, test[:k, [0, 1]], dt, phase)
        got = blend.combine(preds, k)
        blend._active_by_side = None  # read from the prediction's weights
        try:
            want = blend.combine(preds, k)
        finally:
            blend._active_by_side = sets
        W = want._parts[2]
        assert W.shape[1] == len(blend._names) or np.all(W.any(axis=0))  # only members weighted somewhere kept
        assert all(_same(a, b) for a, b in zip(got._parts[1:], want._parts[1:]))
        assert _same(got.mean, want.mean) and _same(got.std_values, want.std_values)
