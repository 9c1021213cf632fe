"""Real motion-capture files with gaps, Qualisys TSV and OptiTrack Motive CSV exports, and every splitter on CSV
and NPZ takes: files shaped like the ones a lab's recordings are (issue: a lab's recordings, third pass)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from test_loaders_mocap import write_c3d

from interprim.cli import main
from interprim.core.errors import DataFileError, DataFileWarning
from interprim.datasets import load_c3d, load_demonstrations, save_demonstrations


def walk(T, M, rate=100.0, seed=0):
    """M markers (mm) moving smoothly, as a walking subject's."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / rate
    base = rng.uniform(-500, 500, (1, M, 3))
    amp = rng.uniform(20, 80, (1, M, 3))
    return base + amp * np.sin(2 * np.pi * 0.9 * t[:, None, None] + rng.uniform(0, 6, (1, M, 3)))


# ----------------------------------------------------------------------------- C3D files with gaps
def test_probe_markers_never_seen_are_left_out_with_one_warning(tmp_path):
    """Like the kinematics files of another toolkit: 46 markers, 700 frames, 6 probe markers never seen, others
    missing 1-97 % of the frames."""
    T, M = 700, 46
    labels = [f"M{i:02d}" for i in range(40)] + [f"Probe{i}" for i in range(1, 7)]
    zeroed = np.zeros((T, M), bool)
    zeroed[:, 40:] = True  # never seen
    zeroed[100:107, 3] = True  # 1 % of the frames: a 7-frame gap, filled by default
    zeroed[5:684, 7] = True  # 97 %: left out with the probes
    zeroed[300:308, 9] = True
    path = write_c3d(tmp_path / "kin.c3d", walk(T, M), labels, zeroed=zeroed)
    with pytest.warns(DataFileWarning) as rec:
        ds = load_c3d(path)
    msgs = [str(w.message) for w in rec if issubclass(w.category, DataFileWarning)]
    assert len(msgs) == 1, msgs
    assert ("kin.c3d: 7 of 46 markers left out, seen in fewer than 50 % of the 700 frames: M07 (seen in 3 %), "
            "Probe1 (never seen), Probe2 (never seen)") in msgs[0]
    assert msgs[0].endswith("keep them with markers= (naming them) or min_marker_coverage=0")
    assert ds.n_dofs == 3 * 39 and "Probe1_x" not in ds.columns and len(ds) == 1
    y = ds.demos[0].reshape(T, 39, 3)
    assert np.isfinite(y).all()  # the 7- and 8-frame gaps were filled (default: 0.1 s = 10 frames at 100 Hz)


def test_gap_longer_than_the_default_is_refused_with_a_table_and_the_fixes(tmp_path, capsys):
    """Like Vicon Plug-in Gait: 'HEDO' lost for 30 frames from frame 148."""
    T = 300
    labels = ["LFHD", "RFHD", "HEDO", "LASI"]
    zeroed = np.zeros((T, 4), bool)
    zeroed[147:177, 2] = True
    zeroed[0:4, 3] = True  # LASI unseen for the first 4 frames
    path = write_c3d(tmp_path / "gait.c3d", walk(T, 4), labels, zeroed=zeroed)
    with pytest.raises(DataFileError) as err:
        load_c3d(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: 2 of 4 markers still miss frames after filling gaps of up to 10 frames (0.1 s at "
                          "100 Hz; the default) by linear interpolation:\n")
    assert "  marker  missing  longest gap\n" in msg
    assert re.search(r"\n  HEDO +10 % +30 frames \(0\.3 s\), frames 148-177\n", msg), msg
    assert re.search(r"\n  LASI +1\.33 % +4 frames \(0\.04 s\), frames 1-4 \(at the start or end: not filled\)\n", msg)
    assert "max_nan_gap=30: fill gaps of up to 30 frames (0.3 s)" in msg
    assert "trim=True: cut the frames at the start and end" in msg
    assert "markers=...: keep only the markers you need (complete ones: LFHD,RFHD)" in msg
    assert "min_marker_coverage=" in msg
    # each fix works
    assert load_c3d(path, max_nan_gap=30, trim=True).demos[0].shape == (T - 4, 12)
    assert load_c3d(path, markers="LFHD,RFHD").n_dofs == 6
    # the command line prints the table as a table, with the flags
    code = main(["fit", str(path), "--observed", "LFHD_x", "-o", str(tmp_path / "m.npz")])
    err_text = capsys.readouterr().err
    assert code == 1
    assert re.search(r"\n  HEDO +10 % +30 frames \(0\.3 s\), frames 148-177\n", err_text), err_text
    assert "\n  --max-nan-gap 30: fill gaps of up to 30 frames" in err_text
    assert "\n  --trim: cut the frames" in err_text and "\n  --markers ...: keep only" in err_text
    assert "--min-marker-coverage" in err_text and "max_nan_gap" not in err_text


def test_arm_markers_empty_in_every_frame_are_never_said_to_be_at_the_start_or_end(tmp_path):
    """Like Vicon FunctionalWalk: the arm markers are empty in all 438 frames."""
    T = 438
    labels = ["LSHO", "RSHO", "LELB", "RELB", "LWRA", "RWRA"]
    zeroed = np.zeros((T, 6), bool)
    zeroed[:, 2:] = True
    path = write_c3d(tmp_path / "walk.c3d", walk(T, 6), labels, zeroed=zeroed)
    with pytest.raises(DataFileError) as err:
        load_c3d(path, markers="LSHO,LELB")  # named: kept, and refused with what is wrong
    msg = str(err.value)
    assert re.search(r"\n  LELB +100 % +all 438 frames \(never seen\)\n", msg), msg
    assert "start or end" not in msg
    assert msg.endswith("what fixes it:\n  markers=...: leave out LELB (never seen); complete markers: LSHO"), msg
    with pytest.warns(DataFileWarning, match=r"4 of 6 markers left out.*LELB \(never seen\)"):
        ds = load_c3d(path, trim=True)
    assert ds.columns[:3] == ["LSHO_x", "LSHO_y", "LSHO_z"] and ds.demos[0].shape == (T, 6)
    with pytest.raises(DataFileError, match=r"trimming leaves nothing: LELB_x, LELB_y, LELB_z are missing in every "
                                            r"frame"):
        load_c3d(path, markers="LSHO,LELB", trim=True)


def test_truncated_file_marker_never_seen_is_left_out(tmp_path):
    """Like a truncated Optotrak file: 29 complete frames, 'Marker_52' never seen."""
    labels = [f"Marker_{i}" for i in range(50, 54)]
    zeroed = np.zeros((29, 4), bool)
    zeroed[:, 2] = True
    path = write_c3d(tmp_path / "opto.c3d", walk(29, 4), labels, zeroed=zeroed)
    with pytest.warns(DataFileWarning, match=r"1 of 4 markers left out, seen in fewer than 50 % of the 29 frames: "
                                             r"Marker_52 \(never seen\)"):
        ds = load_c3d(path)
    assert ds.n_dofs == 9


# ----------------------------------------------------------------------------- Qualisys TSV
def write_qtm_tsv(path, xyz, names, rate=100.0, events=(), column_row=True, missing=None):
    """A QTM 3D TSV export as QTM's documentation describes it (header variables, MARKER_NAMES, mm)."""
    T, M, _ = xyz.shape
    lines = ["FILE_VERSION\t2.0.0", f"NO_OF_FRAMES\t{T}", "NO_OF_CAMERAS\t8", f"NO_OF_MARKERS\t{M}",
             f"FREQUENCY\t{rate:g}", "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0", "DESCRIPTION\t--",
             "TIME_STAMP\t2024-05-02, 10:11:12.123\t5187.6", "DATA_INCLUDED\t3D"]
    lines += [f"EVENT\t{name}\t{frame}\t{(frame - 1) / rate:.3f}" for name, frame in events]
    lines += ["MARKER_NAMES\t" + "\t".join(names), "TRAJECTORY_TYPES\t" + "\t".join(["Measured"] * M)]
    if column_row:
        lines.append("Frame\tTime\t" + "\t".join(f"{n} {a}" for n in names for a in "XYZ"))
    for k in range(T):
        vals = []
        for m in range(M):
            if missing is not None and missing[k, m]:
                vals += ["0.000", "0.000", "0.000"]
            else:
                vals += [f"{v:.3f}" for v in xyz[k, m]]
        lines.append("\t".join(([str(k + 1), f"{k / rate:.5f}"] if column_row else []) + vals))
    path.write_text("\n".join(lines) + "\n")
    return path


def test_qualisys_tsv_is_read_in_metres_with_events(tmp_path):
    xyz = walk(200, 3)
    missing = np.zeros((200, 3), bool)
    missing[50:53, 1] = True
    path = write_qtm_tsv(tmp_path / "take.tsv", xyz, ["RFHD", "RWRA", "RTOE"], events=[("Start", 21), ("Start", 101)],
                         missing=missing)
    ds = load_demonstrations(path)
    assert ds.columns == [f"{n}_{a}" for n in ("RFHD", "RWRA", "RTOE") for a in "xyz"] and ds.units == ["m"] * 9
    np.testing.assert_allclose(ds.demos[0][:, :3], np.round(xyz[:, 0], 3) * 1e-3, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ds.times[0], np.arange(200) / 100.0)
    k = 51  # the 3 lost frames are interpolated
    np.testing.assert_allclose(ds.demos[0][k, 3:6], (np.round(xyz[49, 1], 3) * 2 + np.round(xyz[53, 1], 3) * 2) / 4
                               * 1e-3, atol=1e-9)
    ds = load_demonstrations(path, split_events="Start")
    assert [len(d) for d in ds.demos] == [80] and any("after the last event" in n for n in ds.notes)
    assert [len(d) for d in load_demonstrations(path, split_events=True, keep_partial=True).demos] == [80, 100]
    old = write_qtm_tsv(tmp_path / "old.tsv", xyz, ["a", "b", "c"], column_row=False)  # before version 2
    assert load_demonstrations(old).demos[0].shape == (200, 9)
    bad = tmp_path / "bad.tsv"
    bad.write_text("NO_OF_FRAMES\t2\nFREQUENCY\t100\n1\t2\t3\n")
    with pytest.raises(DataFileError, match=r"bad\.tsv: no MARKER_NAMES line"):
        load_demonstrations(bad)


# ----------------------------------------------------------------------------- OptiTrack Motive CSV
def write_motive_csv(path, body, markers, rate=120.0, units="Meters", blank=None):
    """A Motive CSV export (format 1.23) as OptiTrack's documentation describes it: a rigid body (rotation,
    position, mean marker error) and markers, a blank cell where a marker is hidden."""
    T = body.shape[0]
    info = ["Format Version", "1.23", "Take Name", "handover_01", "Take Notes", "", "Capture Frame Rate",
            f"{rate:.6f}", "Export Frame Rate", f"{rate:.6f}", "Capture Start Time", "2024-05-02 10.11.12.123 AM",
            "Total Frames in Take", str(T), "Total Exported Frames", str(T), "Rotation Type", "Quaternion",
            "Length Units", units, "Coordinate Space", "Global"]
    typ, name, ids, qty, axes = ["", "Type"], ["", "Name"], ["", "ID"], ["", ""], ["Frame", "Time (Seconds)"]
    typ += ["Rigid Body"] * 8
    name += ["Hand"] * 8
    ids += ["1"] * 8
    qty += ["Rotation"] * 4 + ["Position"] * 3 + ["Mean Marker Error"]
    axes += ["X", "Y", "Z", "W", "X", "Y", "Z", ""]
    for m in range(markers.shape[1]):
        typ += ["Marker"] * 3
        name += [f"Partner:M{m}"] * 3
        ids += [f"{m + 2}"] * 3
        qty += ["Position"] * 3
        axes += ["X", "Y", "Z"]
    rows = [",".join(info), "", ",".join(typ), ",".join(name), ",".join(ids), ",".join(qty), ",".join(axes)]
    for k in range(T):
        cells = [str(k), f"{k / rate:.6f}", "0", "0", "0", "1"] + [f"{v:.6f}" for v in body[k]] + ["0.0001"]
        for m in range(markers.shape[1]):
            cells += ["", "", ""] if blank is not None and blank[k, m] else [f"{v:.6f}" for v in markers[k, m]]
        rows.append(",".join(cells))
    path.write_text("\n".join(rows) + "\n")
    return path


def test_motive_csv_export_is_read_as_positions(tmp_path):
    xyz = walk(120, 3, rate=120.0) * 1e-3
    blank = np.zeros((120, 2), bool)
    blank[30:34, 1] = True
    path = write_motive_csv(tmp_path / "take.csv", xyz[:, 0], xyz[:, 1:], blank=blank)
    ds = load_demonstrations(path)
    assert ds.columns == ["Hand_x", "Hand_y", "Hand_z", "Partner:M0_x", "Partner:M0_y", "Partner:M0_z",
                          "Partner:M1_x", "Partner:M1_y", "Partner:M1_z"]
    np.testing.assert_allclose(ds.demos[0][:, :3], np.round(xyz[:, 0], 6), atol=1e-12)
    assert np.isfinite(ds.demos[0]).all()  # a 4-frame gap at 120 Hz: under the 12-frame default
    np.testing.assert_allclose(ds.times[0], np.arange(120) / 120.0)
    mm = write_motive_csv(tmp_path / "mm.csv", xyz[:, 0] * 1e3, xyz[:, 1:] * 1e3, units="Millimeters")
    np.testing.assert_allclose(load_demonstrations(mm).demos[0][:, :3], np.round(xyz[:, 0] * 1e3, 6) * 1e-3,
                               atol=1e-9)
    assert load_demonstrations(path, markers="Hand").columns == ["Hand_x", "Hand_y", "Hand_z"]
    assert len(load_demonstrations(path, split_frames="0-49,60-119")) == 2


# ----------------------------------------------------------------------------- every splitter on CSV and NPZ
def continuous_take(reps=4, period=100, still=40, rate=100.0):
    """One continuous recording: ``reps`` reaching movements separated by still pauses, two agents."""
    seg = []
    for r in range(reps):
        s = np.linspace(0, 1, period)
        move = np.stack([np.sin(np.pi * s) * (1 + 0.05 * r), 0.5 * np.sin(2 * np.pi * s), s * (1 - s)], axis=1)
        seg.append(move)
        seg.append(np.zeros((still, 3)))
    y = np.concatenate(seg)
    y = np.concatenate([y, 0.8 * y + 0.01], axis=1)
    return y, np.arange(len(y)) / rate


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_every_splitter_cuts_a_csv_or_npz_take(tmp_path, suffix):
    y, t = continuous_take()
    path = save_demonstrations(tmp_path / f"take{suffix}", [y], [t], columns=["hx", "hy", "hz", "rx", "ry", "rz"])
    assert len(load_demonstrations(path)) == 1
    gap = load_demonstrations(path, split_gap=0.2)
    assert len(gap) == 4 and all(90 <= len(d) <= 110 for d in gap.demos)
    frames = load_demonstrations(path, split_frames="0-99,140-239")
    assert [len(d) for d in frames.demos] == [100, 100]
    np.testing.assert_allclose(frames.demos[1], y[140:240])
    reps = load_demonstrations(path, split_repetitions=True)
    assert len(reps) == 3 and any("split_repetitions: period 1.4 s" in n for n in reps.notes), reps.notes
    with pytest.raises(DataFileError, match=r"split_events applies to files that carry events"):
        load_demonstrations(path, split_events=True)


def test_a_one_demonstration_file_points_at_the_split_options(tmp_path, capsys):
    y, t = continuous_take()
    path = save_demonstrations(tmp_path / "session.csv", [y], [t], columns=["hx", "hy", "hz", "rx", "ry", "rz"])
    code = main(["fit", str(path), "--observed", "hx,hy,hz", "-o", str(tmp_path / "m.npz")])
    err = capsys.readouterr().err
    assert code == 1
    assert ("holds 1 demonstration; at least 2 are needed to learn a distribution. If it is one continuous "
            "recording, cut it with --split-gap SECONDS (pauses), --split-repetitions (a repeated movement) or "
            "--split-frames A-B,C-D") in err
    code = main(["fit", str(path), "--observed", "hx,hy,hz", "--model", "ip", "--n-basis", "5", "--split-gap", "0.2",
                 "-o", str(tmp_path / "m.npz")])
    out = capsys.readouterr().out
    assert code == 0 and "fitted 4 demonstrations" in out


def test_typed_options_are_the_keyword_arguments(tmp_path):
    from interprim.datasets.formats import CsvOptions, MarkerOptions, TakeOptions

    y, t = continuous_take()
    path = save_demonstrations(tmp_path / "take.csv", [y], [t], columns=["hx", "hy", "hz", "rx", "ry", "rz"])
    a = load_demonstrations(path, options=[TakeOptions(split_gap=0.2), CsvOptions(columns=["hx", "rx"])])
    b = load_demonstrations(path, split_gap=0.2, columns=["hx", "rx"])
    assert a.columns == b.columns == ["hx", "rx"] and len(a) == len(b) == 4
    for x, z in zip(a.demos, b.demos):
        np.testing.assert_array_equal(x, z)
    with pytest.raises(DataFileError, match=r"the option markers= applies to C3D, Qualisys TSV, Motive CSV files, "
                                            r"not to this CSV file"):
        load_demonstrations(path, options=MarkerOptions(markers="a"))
    with pytest.raises(ValueError, match=r"split_gap is given twice: 0\.5 and 0\.2"):
        load_demonstrations(path, split_gap=0.5, options=TakeOptions(split_gap=0.2))


def test_a_csv_column_empty_everywhere_is_not_said_to_be_at_the_start_or_end(tmp_path):
    (tmp_path / "e.csv").write_text("time,x,y\n" + "".join(f"{k / 10},{k},\n" for k in range(8)))
    with pytest.raises(DataFileError) as err:
        load_demonstrations(tmp_path / "e.csv", max_nan_gap=3)
    assert "e.csv, column 'y': no value in any of its 8 frames; leave it out (columns=" in str(err.value)
    assert "start or end" not in str(err.value)
