"""The inner cross-validation's case table (interprim.model_selection.stacking._CaseTable): the families' records
gathered family by family into the arrays that ``np.array`` of all the records gives, on the cases every family
shares, whichever path it takes (records copied as they come, or kept when a family's cases differ)."""

import numpy as np
import pytest

from interprim.model_selection.stacking import _CaseTable


def _records(rng, keys, H=6, D=3, G=5, shift=0.0):
    out = {}
    for c in rng.permutation(len(keys)):  # in no particular order, as the records of a sweep may come
        d, k = keys[c]
        out[(d, k)] = {"mean": rng.normal(size=(H, D)) + shift, "trajectory": rng.normal(size=(G, D)),
                       "phase": float(rng.uniform()), "duration": float(rng.uniform(1, 2)),
                       "truth": np.full((H, D), 10.0 * d + k), "fraction": k / 20.0}
    return out


def _plain(per, names):
    """What the arrays were before the table: ``np.array`` of the records on the shared cases."""
    cases = sorted(set.intersection(*(set(per[m]) for m in names)))
    first = per[names[0]]
    return (cases, [first[c]["fraction"] for c in cases], np.array([first[c]["truth"] for c in cases]),
            {f: np.array([[per[m][c][f] for c in cases] for m in names]) for f in _CaseTable.FIELDS})


def _check(table, per, names):
    cases, fraction, truth, arrays = table.arrays()
    want = _plain(per, names)
    assert cases == want[0] and fraction == want[1] and table.names == names
    np.testing.assert_array_equal(truth, want[2])
    for f in _CaseTable.FIELDS:
        assert arrays[f].dtype == np.float64 and arrays[f].flags.c_contiguous
        np.testing.assert_array_equal(arrays[f], want[3][f])


@pytest.mark.parametrize("n_slots", [3, 5])  # as many families as compared, or fewer (some could not be fitted)
def test_copied_records_give_the_arrays_of_all_the_records(n_slots):
    rng = np.random.default_rng(0)
    keys = [(d, k) for d in (0, 1, 4) for k in (3, 6, 9, 12)]
    per = {m: _records(rng, keys, shift=i) for i, m in enumerate(("a", "b", "c"))}
    table = _CaseTable(n_slots)
    for m, by in per.items():
        table.add(m, by)
    assert not table.kept  # every family copied: nothing kept
    _check(table, per, ["a", "b", "c"])


@pytest.mark.parametrize("odd", ["b", "c"])
def test_a_family_with_other_cases_is_kept_and_the_shared_cases_are_used(odd):
    rng = np.random.default_rng(1)
    keys = [(d, k) for d in (0, 2) for k in (4, 8, 12)]
    per = {m: _records(rng, keys if m != odd else keys[1:] + [(3, 4)]) for m in ("a", "b", "c")}
    table = _CaseTable(3)
    for m, by in per.items():
        table.add(m, by)
    assert set(table.kept) == {"b", "c"} if odd == "b" else {"c"}
    _check(table, per, ["a", "b", "c"])


def test_a_family_with_other_shapes_is_kept_and_fails_as_all_the_records_do():
    rng = np.random.default_rng(2)
    keys = [(0, 4), (0, 8), (1, 4)]
    per = {"a": _records(rng, keys), "b": _records(rng, keys, G=7)}
    table = _CaseTable(2)
    for m, by in per.items():
        table.add(m, by)
    assert set(table.kept) == {"b"}
    with pytest.raises(ValueError, match="inhomogeneous"):  # as np.array of the records: no (2, 3, G, D) array
        table.arrays()
    with pytest.raises(ValueError, match="inhomogeneous"):
        _plain(per, ["a", "b"])
