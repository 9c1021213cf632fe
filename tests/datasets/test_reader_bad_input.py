"""Bad input to the demonstration readers: each case gets a DataFileError that names the problem (never another
exception, a silent wrong answer or lost data), and the repetition finder takes the fundamental period."""

from __future__ import annotations

import io
import math
import struct
import warnings
import zipfile

import ezc3d
import numpy as np
import pytest
from test_loaders_gaps_formats import walk, write_motive_csv, write_qtm_tsv
from test_loaders_mocap import BVH_HEAD, N_CH, write_bvh, write_c3d
from test_loaders_ros import Bag, bag_path, human, robot

from interprim.core.errors import DataFileError, DataFileWarning, InterprimError
from interprim.datasets import load_demonstrations, load_rosbag
from interprim.datasets._split import find_repetitions


def _take(T=40, D=2):
    t = np.arange(T) / 10.0
    return np.column_stack([np.sin(t + k) for k in range(D)])


def _csv(path, text):
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------- NPZ
def test_npz_member_with_a_flipped_byte_names_the_member(tmp_path):
    path = tmp_path / "a.npz"
    np.savez(path, dt=0.01, demo_000=_take(), demo_001=_take() * 2)
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo("demo_001.npy")
    data[info.header_offset + 30 + len(info.filename) + 200] ^= 0xFF  # inside the member's array data
    path.write_bytes(bytes(data))
    with pytest.raises(DataFileError, match=r"key 'demo_001' is damaged \(BadZipFile: Bad CRC-32"):
        load_demonstrations(path)


@pytest.mark.parametrize("text", [b"{'descr':__import__('os')}", b"{'descr':__import__('os')", b"{'descr': '<f8',"])
def test_npz_member_whose_header_is_not_a_header_names_the_member(tmp_path, text):
    header = text + b" " * (118 - len(text)) + b"\n"
    npy = b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header + b"\0" * 64
    dt = io.BytesIO()
    np.save(dt, np.float64(0.01))
    path = tmp_path / "code.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("dt.npy", dt.getvalue())
        zf.writestr("demo_000.npy", npy)
    with pytest.raises(DataFileError, match=r"code\.npz: key 'demo_000'"):
        load_demonstrations(path)


def test_npz_two_keys_of_one_number_are_refused(tmp_path):
    path = tmp_path / "dup.npz"
    np.savez(path, dt=0.01, demo_000=_take(), demo_0=_take() * 2)
    with pytest.raises(DataFileError, match=r"keys 'demo_000' and 'demo_0' are both number 0"):
        load_demonstrations(path)


@pytest.mark.parametrize("name, what", [("", "an empty name"), ("a,b", "a comma"), ("a\nb", "a line break"),
                                        ("a\rb", "a line break"), (" ", "an empty name")])
def test_npz_column_names_a_csv_header_cannot_hold_are_refused(tmp_path, name, what):
    path = tmp_path / "cols.npz"
    np.savez(path, dt=0.01, demo_000=_take(), columns=np.array([name, "b"]))
    with pytest.raises(DataFileError, match=f"column 0 .*{what}"):
        load_demonstrations(path)


def test_npz_demonstration_without_columns_is_refused(tmp_path):
    path = tmp_path / "zero.npz"
    np.savez(path, dt=0.01, demo_000=np.zeros((10, 0)))
    with pytest.raises(DataFileError, match=r"'demo_000' has shape \(10, 0\): no columns"):
        load_demonstrations(path)


def test_csv_header_name_with_a_quoted_comma_is_refused(tmp_path):
    path = _csv(tmp_path / "q.csv", 'time,"a,b",c\n' + "".join(f"{i / 10},{i},{i}\n" for i in range(8)))
    with pytest.raises(DataFileError, match=r"q\.csv: column 0 name 'a,b' holds a comma"):
        load_demonstrations(path)


# ----------------------------------------------------------------------------- CSV numbers and comments
def test_csv_cell_with_an_underscore_is_not_a_number(tmp_path):
    path = _csv(tmp_path / "u.csv", "time,a\n" + "".join(f"{i / 10},{'1_0' if i == 3 else i}\n" for i in range(8)))
    with pytest.raises(DataFileError, match=r"u\.csv, line 5: non-numeric value '1_0' in column 'a'"):
        load_demonstrations(path)


def test_csv_units_comment_of_another_length_names_its_line(tmp_path):
    body = "time,a,b,c,d,e\n" + "".join(f"{i / 10},{i},{i},{i},{i},{i}\n" for i in range(8))
    path = _csv(tmp_path / "units.csv", "# observed: a\n# units: m,m\n" + body)
    with pytest.raises(DataFileError, match=r"units\.csv, line 2: '# units: m,m' names 2 units for the 5 data "):
        load_demonstrations(path)
    ok = _csv(tmp_path / "ok.csv", "# units: m,m,rad,rad,s\n" + body)
    assert load_demonstrations(ok).units == ["m", "m", "rad", "rad", "s"]
    assert load_demonstrations(ok, columns="c,a").units == ["rad", "m"]  # per file column, then selected
    assert load_demonstrations(_csv(tmp_path / "one.csv", "# units: m\n" + body)).units == ["m"] * 5


# ----------------------------------------------------------------------------- BVH
@pytest.mark.parametrize("frames", ["nan", "inf", "-inf", "1e400"])
def test_bvh_frames_that_are_not_a_whole_number(tmp_path, frames):
    path = write_bvh(tmp_path / "f.bvh", np.zeros((10, N_CH)), frames=frames)
    with pytest.raises(DataFileError, match=r"'Frames:' must be a whole number, got"):
        load_demonstrations(path)


def test_bvh_frame_time_whose_stamps_overflow(tmp_path):
    path = write_bvh(tmp_path / "t.bvh", np.zeros((10, N_CH)), frame_time=1e308)
    with pytest.raises(DataFileError, match=r"'Frame Time: 1e\+308' over 10 frames gives times that are not finite"):
        load_demonstrations(path)
    assert BVH_HEAD  # the header the writer uses


# ----------------------------------------------------------------------------- Qualisys TSV and C3D events
def _tsv(tmp_path, events=()):
    return write_qtm_tsv(tmp_path / "q.tsv", walk(60, 2), ["a", "b"], events=events)


@pytest.mark.parametrize("cell", ["nan", "x", "inf", "2.5", "1_0"])
def test_tsv_frame_number_that_is_not_a_whole_number(tmp_path, cell):
    path = _tsv(tmp_path)
    lines = path.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("4\t"))
    lines[k] = cell + lines[k][1:]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError, match=rf"line {k + 1}: frame number '{cell}' is not a whole number"):
        load_demonstrations(path)


@pytest.mark.parametrize("value", ["nan", "inf", "12.5"])
def test_tsv_no_of_frames_that_is_not_a_whole_number(tmp_path, value):
    path = _tsv(tmp_path)
    path.write_text(path.read_text().replace("NO_OF_FRAMES\t60", f"NO_OF_FRAMES\t{value}"))
    with pytest.raises(DataFileError, match=rf"line 2: NO_OF_FRAMES must be a whole number of frames, got '{value}'"):
        load_demonstrations(path)


def test_tsv_byte_that_is_not_utf8_names_its_line(tmp_path):
    path = _tsv(tmp_path)
    lines = path.read_bytes().split(b"\n")
    lines[20] = lines[20] + b"\xff"
    path.write_bytes(b"\n".join(lines))
    with pytest.raises(DataFileError, match=r"q\.tsv: not a Qualisys TSV text file: a byte that is not UTF-8 "
                                            r"\(line 21"):
        load_demonstrations(path)


@pytest.mark.parametrize("time", ["nan", "inf", "1e308"])
def test_tsv_event_time_that_is_not_finite_is_refused_when_splitting(tmp_path, time):
    path = _tsv(tmp_path, events=[("Start", 5), ("Start", 30)])
    path.write_text(path.read_text().replace("EVENT\tStart\t5\t0.040", f"EVENT\tStart\t5\t{time}"))
    assert len(load_demonstrations(path)) == 1  # not splitting: the events are not used
    with pytest.raises(DataFileError, match=r"event 'Start' has time .* s, not a finite number"):
        load_demonstrations(path, split_events=True)


def test_c3d_event_time_that_is_nan_is_refused(tmp_path):
    path = write_c3d(tmp_path / "e.c3d", walk(60, 2) * 10, ["a", "b"])
    c = ezc3d.c3d(str(path))
    c.add_parameter("EVENT", "USED", [2])
    c.add_parameter("EVENT", "TIMES", np.array([[0.0, 0.0], [0.1, math.nan]]))
    c.add_parameter("EVENT", "LABELS", ["Start", "Start"])
    c.add_parameter("EVENT", "CONTEXTS", ["Right", "Right"])
    c.write(str(path))
    with pytest.raises(DataFileError, match=r"event 'Right:Start' has time nan s, not a finite number"):
        load_demonstrations(path, split_events=True)


# ----------------------------------------------------------------------------- OptiTrack Motive CSV
def _motive(tmp_path, n_markers=2):
    xyz = walk(40, 1 + n_markers, rate=120.0) * 1e-3
    return write_motive_csv(tmp_path / "take.csv", xyz[:, 0], xyz[:, 1:])


def test_motive_frame_number_that_is_infinite(tmp_path):
    path = _motive(tmp_path)
    lines = path.read_text().splitlines()
    lines[9] = "inf" + lines[9][1:]
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError, match=r"line 10: frame number 'inf' is not a whole number"):
        load_demonstrations(path)


def test_motive_byte_that_is_not_utf8(tmp_path):
    path = _motive(tmp_path)
    path.write_bytes(path.read_bytes() + b"\xfe\n")
    with pytest.raises(DataFileError, match=r"not a Motive CSV text file: a byte that is not UTF-8 \(line 48"):
        load_demonstrations(path)


def test_motive_field_longer_than_the_csv_module_default(tmp_path):
    path = _motive(tmp_path)
    path.write_text(path.read_text() + "x" * (200 * 1024) + "\n")
    with pytest.raises(DataFileError, match=r"line 48: frame number 'xxxx.*' is not a whole number"):
        load_demonstrations(path)


def test_motive_markers_of_one_name_get_unique_columns_with_one_warning(tmp_path):
    path = _motive(tmp_path, n_markers=3)
    path.write_text(path.read_text().replace("Partner:M1", "Partner:M0").replace("Partner:M2", "Partner:M0"))
    with pytest.warns(DataFileWarning, match=r"share a name.*'Partner:M0' as Marker:Partner:M0#3") as rec:
        ds = load_demonstrations(path)
    assert len([w for w in rec if issubclass(w.category, DataFileWarning)]) == 1
    assert ds.columns[3:] == [f"{m}_{a}" for m in ("Partner:M0", "Marker:Partner:M0", "Marker:Partner:M0#3")
                              for a in "xyz"]
    assert len(set(ds.columns)) == len(ds.columns) == 12


# ----------------------------------------------------------------------------- repetitions
RATE = 100.0
T12 = np.arange(0, 12.0 + 1e-9, 1 / RATE)


@pytest.mark.parametrize("z, period, reps", [
    (np.abs(np.sin(np.pi * T12 / 0.8)), 0.8, (13, 15)),
    (np.sin(2 * np.pi * T12) + 0.01 * np.random.default_rng(0).standard_normal(T12.size), 1.0, (10, 12)),
    (np.cos(2 * np.pi * T12), 1.0, (10, 12)),
])
def test_the_period_found_is_the_fundamental_not_a_multiple(z, period, reps):
    segs, note = find_repetitions(z[:, None], RATE, where="take")
    assert f"period {period:.3g} s" in note
    assert reps[0] <= len(segs) <= reps[1]
    assert np.median([b - a + 1 for a, b in segs]) == pytest.approx(period * RATE, abs=2)


def test_a_given_period_shorter_than_a_few_frames_is_refused(tmp_path):
    t = np.arange(400) / RATE
    path = tmp_path / "rep.csv"
    path.write_text("time,a\n" + "".join(f"{float(ti)!r},{float(np.sin(2 * np.pi * ti))!r}\n" for ti in t))
    with pytest.raises(DataFileError, match=r"split_repetitions period 1e-09 s is 1e-07 frames at 100 Hz; a "
                                            r"repetition needs at least 4 frames"):
        load_demonstrations(path, split_repetitions=1e-9)
    assert len(load_demonstrations(path, split_repetitions=1.0)) >= 2


# ----------------------------------------------------------------------------- sizes and options
def _one_second(tmp_path):
    return _csv(tmp_path / "r.csv", "time,a\n" + "".join(f"{i / 10},{i}\n" for i in range(11)))


@pytest.mark.parametrize("dt", [1e-9, 1e-300, 5e-324])
def test_resampling_to_too_many_frames_is_refused_before_it_is_allocated(tmp_path, dt):
    with pytest.raises(DataFileError, match=rf"resample_dt={dt!r} s over its 1 s gives .* frames .*over the limit"):
        load_demonstrations(_one_second(tmp_path), resample_dt=dt)


def test_resampling_coarser_than_the_movement_is_refused(tmp_path):
    with pytest.raises(DataFileError, match=r"resample_dt=100 s over its 1 s leaves only 1 frame\(s\), at least 5"):
        load_demonstrations(_one_second(tmp_path), resample_dt=100)
    assert len(load_demonstrations(_one_second(tmp_path), resample_dt=0.05).demos[0]) == 21


@pytest.mark.parametrize("name", ["dt", "resample_dt", "split_gap", "split_repetitions"])
@pytest.mark.parametrize("value", [math.inf, math.nan, -1.0])
def test_options_that_are_not_positive_finite_seconds_are_one_line_errors(tmp_path, name, value):
    with pytest.raises(DataFileError, match=rf"{name}.* must be a positive number of seconds, got {value!r}") as e:
        load_demonstrations(_one_second(tmp_path), **{name: value})
    assert isinstance(e.value, (InterprimError, ValueError))


# ----------------------------------------------------------------------------- ROS bags
def _bag(tmp_path, n=40, same_stamp=1, value=None):
    b = Bag("mcap")
    for k in range(n):
        t = 10.0 + k * 0.02
        stamp = 10.0 + (k // same_stamp) * 0.02 * same_stamp
        xyz = human(t) if value is None or k != 7 else value
        b.pose("/human/wrist", t, xyz, stamp=stamp)
        b.joints("/robot/joint_states", t + 0.007, ["j1", "j2"], robot(t + 0.007))
    return b.write(bag_path(tmp_path, "mcap"))


def test_bag_messages_of_one_stamp_are_said_to_be_left_out(tmp_path):
    path = _bag(tmp_path, n=100, same_stamp=10)
    with pytest.warns(DataFileWarning, match=r"topic /human/wrist: 90 of 100 messages have the same time stamp") as rec:
        ds = load_rosbag(path, ["/human/wrist", "/robot/joint_states"])
    assert len([w for w in rec if issubclass(w.category, DataFileWarning)]) == 1
    assert len(ds.demos[0]) in (9, 10)  # one message per stamp (the last may lie past the other stream)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_rosbag(_bag(tmp_path / "ok"), ["/human/wrist", "/robot/joint_states"])  # distinct stamps: silent


def test_bag_infinite_value_names_topic_and_field(tmp_path):
    path = _bag(tmp_path, value=[0.0, math.inf, 2.0])
    with pytest.raises(DataFileError, match=r"topic /human/wrist, message 7: infinite value inf in field "
                                            r"'human/wrist_y'"):
        load_rosbag(path, ["/human/wrist", "/robot/joint_states"])


@pytest.mark.parametrize("dt, what", [(1e-12, "over the limit"), (5.0, "leaves only 1 frame")])
def test_bag_grid_is_checked_before_it_is_allocated(tmp_path, dt, what):
    path = _bag(tmp_path)
    with pytest.raises(DataFileError, match=rf"resample_dt={dt!r} s over its .* s .*{what}"):
        load_demonstrations(path, topics="/human/wrist,/robot/joint_states", resample_dt=dt)


def test_a_csv_without_a_header_line_is_refused_not_read_one_frame_short(tmp_path):
    """Without a header line the first frame became the column names ('0.0', '1.5', ...) and was lost silently."""
    from interprim.datasets import load_demonstrations

    rows = "\n".join(f"{0.01 * i:.2f},{1.5 + 0.1 * i:.2f},{2.5 - 0.1 * i:.2f}" for i in range(8))
    (tmp_path / "nohdr.csv").write_text(rows + "\n")
    with pytest.raises(DataFileError, match=r"line 1: the first line is numbers \(0\.00, 1\.50, 2\.50\), not column"):
        load_demonstrations(tmp_path / "nohdr.csv")
    # whole numbers are names (a data frame without column names writes 0, 1, 2, ...)
    (tmp_path / "int.csv").write_text("time,0,1\n" + rows + "\n")
    assert load_demonstrations(tmp_path / "int.csv").columns == ["0", "1"]
