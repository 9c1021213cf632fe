"""CSV files as ROS tools export them, and the CSV reader's limits (streamed, linear in the number of columns).

Every file is written here in the shape the tool writes: ``rostopic echo -p`` (``%time`` and ``field.header.stamp``
in nanoseconds, a text ``frame_id``), a ``ros2 bag``/PlotJuggler export (``__time`` in seconds, ``/topic/field``
names), wide files, long lines, a FIFO and a symlink loop.
"""

import os
import tracemalloc

import numpy as np
import pytest

from interprim.core.errors import DataFileError
from interprim.datasets import files as csv_files
from interprim.datasets import load_demonstrations

T0_NS = 1_700_000_000_123_456_789  # an absolute ROS stamp (ns since 1970)


def rostopic_export(path, n=30, hz=50.0, seed=0):
    """``rostopic echo -p /human/pose > human.csv`` of a geometry_msgs/PoseStamped: ns stamps, a text frame."""
    rng = np.random.default_rng(seed)
    step = int(1e9 / hz)
    xyz = np.cumsum(rng.normal(0, 0.01, (n, 3)), axis=0)
    head = ["%time", "field.header.seq", "field.header.stamp", "field.header.frame_id",
            "field.pose.position.x", "field.pose.position.y", "field.pose.position.z",
            "field.pose.orientation.x", "field.pose.orientation.y", "field.pose.orientation.z",
            "field.pose.orientation.w"]
    lines = [",".join(head)]
    for k in range(n):
        stamp = T0_NS + k * step
        lines.append(",".join([str(stamp + 1234), str(k), str(stamp), "world"] + [repr(float(v)) for v in xyz[k]]
                              + ["0.0", "0.0", "0.0", "1.0"]))
    path.write_text("\n".join(lines) + "\n")
    return xyz, step


def test_rostopic_echo_p_export_loads_directly(tmp_path, capsys):
    xyz, step = rostopic_export(tmp_path / "human.csv")
    ds = load_demonstrations(tmp_path / "human.csv")
    # the bookkeeping fields (seq, stamp, frame_id) are not degrees of freedom; %time is the time column
    assert ds.columns == ["field.pose.position.x", "field.pose.position.y", "field.pose.position.z",
                          "field.pose.orientation.x", "field.pose.orientation.y", "field.pose.orientation.z",
                          "field.pose.orientation.w"]
    np.testing.assert_allclose(ds.demos[0][:, :3], xyz)
    np.testing.assert_allclose(np.diff(ds.times[0]), step * 1e-9, rtol=0, atol=1e-6)
    assert ds.dt == pytest.approx(0.02, rel=1e-6)
    assert len(ds.notes) == 1 and "'%time'" in ds.notes[0] and "nanoseconds" in ds.notes[0]
    # a fallback dt (what predict passes: the model's) does not override the export's own stamps
    with_dt = load_demonstrations(tmp_path / "human.csv", dt=0.5)
    np.testing.assert_allclose(with_dt.times[0], ds.times[0])
    # the header stamp instead of the receive time; the unit said explicitly gives the same
    by_stamp = load_demonstrations(tmp_path / "human.csv", time_column="field.header.stamp")
    np.testing.assert_allclose(by_stamp.times[0] - by_stamp.times[0][0], np.arange(30) * 0.02, atol=1e-6)
    same = load_demonstrations(tmp_path / "human.csv", time_column="field.header.stamp", time_unit="ns")
    np.testing.assert_array_equal(same.times[0], by_stamp.times[0])
    assert same.notes == []
    # --columns picks fields and skips the text column it does not name
    sub = load_demonstrations(tmp_path / "human.csv", columns="field.pose.position.z,field.header.seq")
    assert sub.columns == ["field.pose.position.z", "field.header.seq"]
    np.testing.assert_array_equal(sub.demos[0][:, 1], np.arange(30))
    with pytest.raises(DataFileError, match=r"line 2: non-numeric value 'world' in column 'field.header.frame_id'"):
        load_demonstrations(tmp_path / "human.csv", columns="field.header.frame_id")


def test_ros2_bag_plotjuggler_export_and_seconds(tmp_path):
    """``__time`` in seconds (floats), one column per topic field: read as seconds, and said so."""
    t = 1_700_000_000.0 + np.arange(20) * 0.05
    x = np.sin(np.arange(20) * 0.3)
    rows = [f"{ti!r},{xi!r},{-xi!r},{2 * xi!r}" for ti, xi in zip(t.tolist(), x.tolist())]
    (tmp_path / "bag.csv").write_text("__time,/human/pose/position/x,/robot/joint_states/position[0],"
                                      "/robot/joint_states/header/stamp\n" + "\n".join(rows) + "\n")
    ds = load_demonstrations(tmp_path / "bag.csv")
    assert ds.columns == ["/human/pose/position/x", "/robot/joint_states/position[0]"]
    np.testing.assert_allclose(ds.times[0], t)
    assert "seconds" in ds.notes[0] and "'__time'" in ds.notes[0]
    np.testing.assert_allclose(ds.demos[0][:, 0], x)


def test_columns_skips_unused_text_columns_of_any_csv(tmp_path):
    (tmp_path / "d.csv").write_text("time,subject,x,note,y\n" + "".join(
        f"{0.1 * k},P{k % 3},{k},free text {k},{-k}\n" for k in range(8)))
    with pytest.raises(DataFileError, match=r"non-numeric value 'P0' in column 'subject'; choose the numeric "
                                            r"columns with columns="):
        load_demonstrations(tmp_path / "d.csv")
    ds = load_demonstrations(tmp_path / "d.csv", columns=["y", "x"])
    assert ds.columns == ["y", "x"]
    np.testing.assert_array_equal(ds.demos[0], np.c_[-np.arange(8), np.arange(8)])


def test_missing_time_error_shows_a_capped_header(tmp_path):
    names = [f"field.joint_{i:04d}.position" for i in range(1500)]
    (tmp_path / "wide.csv").write_text(",".join(names) + "\n" + ",".join("0.5" for _ in names) + "\n")
    with pytest.raises(DataFileError) as info:
        load_demonstrations(tmp_path / "wide.csv")
    msg = str(info.value)
    assert len(msg) < 900, len(msg)
    assert "the header has 1500 columns: field.joint_0000.position" in msg and "(1500 in all)" in msg
    assert "time_column=" in msg  # on the command line: --time-column


def test_unknown_time_column_names_the_option(tmp_path):
    rostopic_export(tmp_path / "h.csv", n=6)
    with pytest.raises(DataFileError, match=r"no column 'stamp' \(time_column\); the header has 11 columns: %time"):
        load_demonstrations(tmp_path / "h.csv", time_column="stamp")


def test_a_hundred_thousand_columns_are_read(tmp_path):
    """10^5 columns, whole and selected by name (the quadratic reader took minutes here; its speed is measured in
    benchmarks/csv_columns.py)."""
    n = 100_000
    rng = np.random.default_rng(0)
    vals = np.round(rng.normal(size=(6, n)), 3)
    with open(tmp_path / "wide.csv", "w") as fh:
        fh.write("time," + ",".join(f"c{i}" for i in range(n)) + "\n")
        for r in range(6):
            fh.write(f"{0.01 * r}," + ",".join(map(repr, vals[r].tolist())) + "\n")
    ds = load_demonstrations(tmp_path / "wide.csv")
    sub = load_demonstrations(tmp_path / "wide.csv", columns=[f"c{i}" for i in range(n - 1, -1, -1)])
    assert ds.demos[0].shape == (6, n)
    np.testing.assert_array_equal(ds.demos[0], vals)
    np.testing.assert_array_equal(sub.demos[0], vals[:, ::-1])


def test_limits_refuse_a_long_line_without_reading_it_whole(tmp_path, monkeypatch):
    big = tmp_path / "one_line.csv"
    with open(big, "w") as fh:
        fh.write("time,x\n0,1\n")
        fh.write("1,2." + "9" * (20 * 2**20) + "\n")  # a 20 MB line (one number)
    monkeypatch.setitem(csv_files.CSV_LIMITS, "max_line_chars", 2**20)
    tracemalloc.start()
    try:
        with pytest.raises(DataFileError, match=r"one_line\.csv, line 3: a line longer than the limit \(more than "
                                                r"1048576 characters\) exceeds the CSV reader's limit "
                                                r"max_line_chars=1048576; .*INTERPRIM_CSV_MAX_LINE_CHARS=N"):
            load_demonstrations(big)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 12 * 2**20, f"peak {peak / 2**20:.1f} MB while refusing a 20 MB line"
    monkeypatch.setenv("INTERPRIM_CSV_MAX_LINE_CHARS", str(30 * 2**20))  # raised: read
    assert load_demonstrations(big, min_frames=2).demos[0].shape == (2, 1)


def test_limits_on_columns_and_size_name_the_variable(tmp_path, monkeypatch):
    (tmp_path / "d.csv").write_text("time,a,b,c\n" + "".join(f"{k},1,2,3\n" for k in range(6)))
    monkeypatch.setenv("INTERPRIM_CSV_MAX_COLUMNS", "3")
    with pytest.raises(DataFileError, match=r"d\.csv, line 1: the number of columns \(4\) exceeds the CSV reader's "
                                            r"limit max_columns=3; .*INTERPRIM_CSV_MAX_COLUMNS=N"):
        load_demonstrations(tmp_path / "d.csv")
    monkeypatch.delenv("INTERPRIM_CSV_MAX_COLUMNS")
    monkeypatch.setitem(csv_files.CSV_LIMITS, "max_bytes", 20)
    with pytest.raises(DataFileError, match=r"the file's size \(\d+ bytes\) exceeds .* max_bytes=20"):
        load_demonstrations(tmp_path / "d.csv")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes need a POSIX system")
def test_a_fifo_is_refused_at_once(tmp_path, monkeypatch):
    import builtins

    fifo = tmp_path / "demos.csv"
    os.mkfifo(fifo)
    real_open = builtins.open

    def never_the_fifo(file, *args, **kwargs):  # opening a FIFO without a writer is what hung
        assert os.fspath(file) != os.fspath(fifo), "the FIFO was opened"
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", never_the_fifo)
    with pytest.raises(DataFileError, match=r"demos\.csv: is a named pipe \(FIFO\), not a regular file"):
        load_demonstrations(fifo)


def test_a_symlink_loop_is_named(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.symlink_to(b)
    b.symlink_to(a)
    with pytest.raises(DataFileError, match=r"a\.csv: symlink loop"):
        load_demonstrations(a)
    with pytest.raises(FileNotFoundError, match="demonstrations not found"):  # a missing file is still 'not found'
        load_demonstrations(tmp_path / "missing.csv")


def test_cli_fit_on_a_rostopic_export_says_the_time_unit(tmp_path, capsys):
    from interprim.cli import main

    rng = np.random.default_rng(3)
    lines = ["%time,field.header.seq,field.header.stamp,field.header.frame_id,field.human_x,field.human_y,"
             "field.robot_x"]
    for d in range(4):
        for k in range(25):
            s = T0_NS + (d * 100 + k) * 20_000_000
            h = float(np.sin(k / 24 * np.pi) * (1 + 0.1 * d) + rng.normal(0, 1e-3))
            lines.append(f"{s},{k},{s},map,{h!r},{h / 2!r},{0.8 * h!r}")
    # one demonstration per file, as rostopic writes one file per recording
    body = lines[1:]
    for d in range(4):
        (tmp_path / f"take{d}.csv").write_text("\n".join([lines[0]] + body[25 * d:25 * (d + 1)]) + "\n")
    out = tmp_path / "m.npz"
    code = main(["fit", str(tmp_path), "--observed", "field.human_x,field.human_y", "--model", "ip",
                 "--n-basis", "5", "-o", str(out)])
    text = capsys.readouterr().out
    assert code == 0 and out.exists()
    assert "note: time column '%time': whole numbers 2e+07 apart, taken as nanoseconds" in text
    assert "dt=0.02 s" in text
