"""Motion-capture loaders: C3D (written here with the ``c3d`` package) and BVH (text written here).

Every file is small and written by the test; the values read back are compared with what was written
(C3D stores 32-bit floats, so the expected values are the float32 numbers times the unit's metres).
"""

import random
import re
import warnings

import ezc3d  # the [mocap] extra, part of the test extra
import numpy as np
import pytest

from interprim.core.errors import DataFileError, DataFileWarning, MissingExtraError
from interprim.datasets import load_bvh, load_c3d, load_demonstrations


# ----------------------------------------------------------------------------- writers
def write_c3d(path, xyz, labels, *, rate=100.0, units="mm", first_frame=1, lost=None, zeroed=None, angles=(),
              analog=0, point_units=None):
    """Write markers ``xyz`` (T, M, 3) in ``units`` with ezc3d; ``lost``/``zeroed`` (T, M) mark missing markers
    (residual -1, or coordinates written as 0), ``angles`` adds model-output points listed in POINT:ANGLES,
    ``analog`` adds that many analog channels (10 samples per frame; with one channel ezc3d stores ANALOG:SCALE
    and ANALOG:OFFSET as single values without dimensions, as in the kinetics-toolkit sample files), ``point_units``
    writes POINT:UNITS as these strings (one per point, as Optotrak exports do) instead of ``units``."""
    T, M, _ = xyz.shape
    n_pts = M + len(angles)
    c = ezc3d.c3d()
    pts = np.zeros((4, n_pts, T))
    pts[3] = 1.0
    pts[:3, :M, :] = np.transpose(xyz, (2, 1, 0))
    pts[:3, M:, :] = 45.0  # an 'angle' in degrees: must not be read as a marker
    res = np.zeros((1, n_pts, T))
    if lost is not None:
        res[0, :M, :][lost.T] = -1.0
    if zeroed is not None:
        pts[:3, :M, :][:, zeroed.T] = 0.0
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(labels) + list(angles)
    c["parameters"]["POINT"]["UNITS"]["value"] = list(point_units) if point_units is not None else [units]
    c["data"]["points"] = pts
    c["data"]["meta_points"] = {"residuals": res, "camera_masks": np.zeros((7, n_pts, T), dtype=bool)}
    c["header"]["points"]["first_frame"] = first_frame - 1  # ezc3d counts from 0
    if angles:
        c.add_parameter("POINT", "ANGLES", list(angles))
    if analog:
        c["parameters"]["ANALOG"]["RATE"]["value"] = [rate * 10]
        c["parameters"]["ANALOG"]["LABELS"]["value"] = [f"F{i}" for i in range(analog)]
        c["data"]["analogs"] = np.zeros((1, analog, T * 10))
    c.write(str(path))
    return path


def _data_start(path):
    """The byte at which the file's frames start (header word 9: the first block of the data section)."""
    b = path.read_bytes()
    return (int.from_bytes(b[16:18], "little") - 1) * 512


def handover(T=40, seed=0):
    """A small two-person reach (millimetres): A's and B's right hands meet in the middle."""
    rng = np.random.default_rng(seed)
    s = np.linspace(0, 1, T)
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    meet = np.array([500.0, 0.0, 1100.0]) + rng.normal(0, 30, 3)
    a0, b0 = np.array([0.0, 200.0, 900.0]), np.array([1000.0, -200.0, 900.0])
    a = a0 + s[:, None] * (meet - a0)
    b = b0 + s[:, None] * (meet + [60, 0, 0] - b0)
    return np.stack([a, a + [0, 0, -80.0], b, b + [0, 0, -80.0]], axis=1)  # hand, wrist of A and of B


LABELS = ["A:RHand", "A:RWrist", "B:RHand", "B:RWrist"]


def f32(x):
    return np.asarray(x, dtype=np.float32).astype(np.float64)


# ----------------------------------------------------------------------------- C3D
def test_c3d_columns_metres_and_time_stamps(tmp_path):
    xyz = handover(30)
    path = write_c3d(tmp_path / "take.c3d", xyz, LABELS, rate=200.0, first_frame=7)
    ds = load_c3d(path)
    assert ds.columns == [f"{m}_{a}" for m in LABELS for a in "xyz"]
    assert ds.units == ["m"] * 12 and ds.select(["B:RHand_z", "A:RHand_x"]).units == ["m", "m"]
    assert len(ds) == 1 and ds.labels == ["take"]
    np.testing.assert_array_equal(ds.times[0], np.arange(30) / 200.0)
    assert ds.dt == pytest.approx(1 / 200.0)
    np.testing.assert_allclose(ds.demos[0], f32(xyz).reshape(30, 12) * 1e-3, rtol=1e-12, atol=0)


@pytest.mark.parametrize("units, scale", [("cm", 1e-2), ("m", 1.0), ("in", 0.0254)])
def test_c3d_other_units_and_override(tmp_path, units, scale):
    xyz = handover(10) / 100.0
    path = write_c3d(tmp_path / "u.c3d", xyz, LABELS, units=units)
    ds = load_c3d(path)
    np.testing.assert_allclose(ds.demos[0], f32(xyz).reshape(10, 12) * scale, rtol=1e-12)
    over = load_c3d(path, length_unit="mm")  # a file that states the wrong unit
    np.testing.assert_allclose(over.demos[0], f32(xyz).reshape(10, 12) * 1e-3, rtol=1e-12)


def test_c3d_unknown_unit_is_an_error(tmp_path):
    path = write_c3d(tmp_path / "u.c3d", handover(10), LABELS, units="furlong")
    with pytest.raises(DataFileError, match=r"u\.c3d: unknown length unit 'furlong' \(POINT:UNITS\)"):
        load_c3d(path)


def test_c3d_missing_markers_gap_rules(tmp_path):
    xyz = handover(30)
    lost = np.zeros((30, 4), bool)
    lost[10:13, 2] = True  # B:RHand lost in frames 11-13 (numbered from 1)
    zeroed = np.zeros((30, 4), bool)
    zeroed[20, 1] = True  # A:RWrist written as (0, 0, 0) in frame 21
    path = write_c3d(tmp_path / "gap.c3d", xyz, LABELS, lost=lost, zeroed=zeroed)
    with pytest.raises(DataFileError) as err:
        load_c3d(path, max_nan_gap=0)
    assert "gap.c3d: 2 of 4 markers still miss frames after filling no gap (max_nan_gap=0)" in str(err.value)
    assert re.search(r"B:RHand +10 % +3 frames \(0\.03 s\), frames 11-13\n", str(err.value)), str(err.value)
    assert re.search(r"A:RWrist +3\.33 % +1 frame, frame 21\n", str(err.value)), str(err.value)
    assert "max_nan_gap=3: fill gaps of up to 3 frames (0.03 s)" in str(err.value)
    with pytest.raises(DataFileError, match=r"B:RHand +10 % +3 frames .*frames 11-13"):
        load_c3d(path, max_nan_gap=2)
    assert load_c3d(path).demos[0].shape == (30, 12)  # the default fills 0.1 s (10 frames at 100 Hz)
    ds = load_c3d(path, max_nan_gap=3)
    y = ds.demos[0].reshape(30, 4, 3)
    ref = f32(xyz) * 1e-3
    for k in range(10, 13):  # linear interpolation between frames 10 and 14 (indices 9 and 13)
        w = (k - 9) / 4
        np.testing.assert_allclose(y[k, 2], (1 - w) * ref[9, 2] + w * ref[13, 2], rtol=1e-12)
    np.testing.assert_allclose(y[20, 1], (ref[19, 1] + ref[21, 1]) / 2, rtol=1e-12)
    np.testing.assert_allclose(np.delete(y, [10, 11, 12, 20], axis=0), np.delete(ref, [10, 11, 12, 20], axis=0),
                               rtol=1e-12)


def test_c3d_marker_missing_at_the_start_is_an_error(tmp_path):
    lost = np.zeros((20, 4), bool)
    lost[:2, 0] = True
    path = write_c3d(tmp_path / "s.c3d", handover(20), LABELS, lost=lost, first_frame=100)
    with pytest.raises(DataFileError, match=r"A:RHand +10 % +2 frames \(0\.02 s\), frames 100-101 \(at the start "
                                            r"or end: not filled\)\nwhat fixes it:\n  trim=True"):
        load_c3d(path, max_nan_gap=10)
    assert load_c3d(path, trim=True).demos[0].shape == (18, 12)


def test_c3d_marker_selection_and_model_outputs(tmp_path):
    path = write_c3d(tmp_path / "m.c3d", handover(12), LABELS, angles=["LKneeAngles", "RKneeAngles"])
    ds = load_c3d(path)
    assert all("Angles" not in c for c in ds.columns) and ds.n_dofs == 12
    sel = load_c3d(path, markers="B:RHand, A:RHand")
    assert sel.columns == ["B:RHand_x", "B:RHand_y", "B:RHand_z", "A:RHand_x", "A:RHand_y", "A:RHand_z"]
    np.testing.assert_array_equal(sel.demos[0][:, :3], ds.demos[0][:, 6:9])
    with pytest.raises(DataFileError, match=r"m\.c3d: unknown marker 'Nose'.*the file's markers are: A:RHand, "):
        load_c3d(path, markers=["Nose"])


def test_c3d_folder_is_many_demonstrations_in_natural_order(tmp_path):
    for k in (10, 2, 1):
        write_c3d(tmp_path / f"take_{k}.c3d", handover(15 + k, seed=k), LABELS)
    ds = load_demonstrations(tmp_path)
    assert ds.labels == ["take_1", "take_2", "take_10"]
    assert [d.shape[0] for d in ds.demos] == [16, 17, 25]
    write_c3d(tmp_path / "take_11.c3d", handover(15)[:, :3], LABELS[:3])
    with pytest.raises(DataFileError, match=r"take_11\.c3d: columns differ from take_1\.c3d: missing \['B:RWrist_x'"):
        load_demonstrations(tmp_path)


def test_c3d_damaged_files_name_file_and_position(tmp_path):
    good = write_c3d(tmp_path / "good.c3d", handover(40), LABELS).read_bytes()
    data_start = _data_start(tmp_path / "good.c3d")
    (tmp_path / "cut.c3d").write_bytes(good[: data_start + 20])  # inside the first frame: nothing to keep
    with pytest.raises(DataFileError, match=r"cut\.c3d: truncated file: the header announces frames 1-40 \(40\) but "
                                            r"the data ends at byte \d+ of \d+, in frame 1 \(0 complete frames\)"):
        load_c3d(tmp_path / "cut.c3d")
    (tmp_path / "head.c3d").write_bytes(good[:300])
    with pytest.raises(DataFileError, match=r"head\.c3d: not a readable C3D file \(header or parameter section, byte"):
        load_c3d(tmp_path / "head.c3d")
    (tmp_path / "garbage.c3d").write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 3000, dtype=np.uint8)))
    with pytest.raises(DataFileError, match=r"garbage\.c3d: "):
        load_c3d(tmp_path / "garbage.c3d")
    (tmp_path / "empty.c3d").write_bytes(b"")
    with pytest.raises(DataFileError, match=r"empty\.c3d: empty file"):
        load_c3d(tmp_path / "empty.c3d")


@pytest.mark.parametrize("extra", [0, 7])  # cut at a frame's end, or inside the next frame
def test_c3d_header_announcing_more_frames_than_held_keeps_the_complete_ones(tmp_path, extra):
    """Like ezc3d's Optotrak.c3d (header: frames 1-1149, data: 29 complete frames): the complete frames are
    read, with a warning saying how many announced frames are missing."""
    from interprim.core.errors import DataFileWarning

    xyz = handover(40)
    write_c3d(tmp_path / "good.c3d", xyz, LABELS, first_frame=1)
    good = (tmp_path / "good.c3d").read_bytes()
    data_start = _data_start(tmp_path / "good.c3d")
    frame_bytes = 4 * 4 * len(LABELS)  # x, y, z, residual of each marker, as float32
    assert len(good) >= data_start + 40 * frame_bytes
    (tmp_path / "optotrak.c3d").write_bytes(good[: data_start + 29 * frame_bytes + extra])
    with pytest.warns(DataFileWarning, match=r"optotrak\.c3d: truncated file: the header announces frames 1-40 "
                                             r"\(40\) .*\(29 complete frames\); keeping frames 1-29, 11 announced "
                                             r"frames are missing"):
        ds = load_c3d(tmp_path / "optotrak.c3d")
    assert ds.demos[0].shape == (29, 12)
    np.testing.assert_allclose(ds.demos[0], f32(xyz[:29]).reshape(29, 12) * 1e-3)
    np.testing.assert_allclose(ds.times[0], np.arange(29) / 100.0)


def test_c3d_analog_scale_without_dimensions_like_kinetics_toolkit_files(tmp_path):
    """One analog channel: ANALOG:SCALE and ANALOG:OFFSET are stored as single values without dimensions (the
    kinetics-toolkit sample files); the pure-Python c3d package refused such files ('SCALE: cannot get value as
    float32 array!'). The markers are read, the analog data ignored."""
    xyz = handover(30)
    path = write_c3d(tmp_path / "tennis_serve.c3d", xyz, LABELS, analog=1)
    b = path.read_bytes()
    i = b.index(b"SCALE", (b[0] - 1) * 512)
    assert b[i + 5 + 3] == 0  # after the name and the 2-byte offset: the type, then 0 dimensions
    ds = load_c3d(path)
    assert ds.demos[0].shape == (30, 12)
    np.testing.assert_allclose(ds.demos[0], f32(xyz).reshape(30, 12) * 1e-3)
    path2 = write_c3d(tmp_path / "two.c3d", xyz, LABELS, analog=2)  # two channels: one value each
    np.testing.assert_allclose(load_c3d(path2).demos[0], ds.demos[0])


def test_c3d_point_units_one_string_per_point_like_optotrak(tmp_path):
    """POINT:UNITS with one (padded) string per point, in a file whose header announces more frames than it
    holds: the complete frames are kept, in metres; differing units per point are converted point by point."""
    xyz = handover(40)
    path = write_c3d(tmp_path / "full.c3d", xyz, LABELS, point_units=["mm  "] * 4)
    good = path.read_bytes()
    (tmp_path / "optotrak.c3d").write_bytes(good[: _data_start(path) + 29 * 4 * 4 * 4 + 5])
    with pytest.warns(DataFileWarning, match=r"29 complete frames\); keeping frames 1-29"):
        ds = load_c3d(tmp_path / "optotrak.c3d")
    np.testing.assert_allclose(ds.demos[0], f32(xyz[:29]).reshape(29, 12) * 1e-3)
    mixed = write_c3d(tmp_path / "mixed.c3d", xyz, LABELS, point_units=["mm", "mm", "cm", "m"])
    got = load_c3d(mixed).demos[0].reshape(40, 4, 3)
    for j, scale in enumerate([1e-3, 1e-3, 1e-2, 1.0]):
        np.testing.assert_allclose(got[:, j], f32(xyz[:, j]) * scale)
    bad = write_c3d(tmp_path / "bad.c3d", xyz, LABELS, point_units=["mm", "mm", "furlong", "mm"])
    with pytest.raises(DataFileError, match=r"bad\.c3d: unknown length unit 'furlong' \(POINT:UNITS of point 3\)"):
        load_c3d(bad)


def test_c3d_reader_that_does_not_finish_is_a_data_error(tmp_path, monkeypatch):
    """A damaged file on which the reader runs too long (or dies) is reported, not waited for for ever."""
    import interprim.datasets.mocap_c3d as m

    path = write_c3d(tmp_path / "slow.c3d", handover(10), LABELS)
    monkeypatch.setattr(m, "_CHILD", "import time; time.sleep(30)")
    monkeypatch.setattr(m, "READ_TIMEOUT", 0.5)
    with pytest.raises(DataFileError, match=r"slow\.c3d: not a readable C3D file \(the reader did not finish"):
        load_c3d(path)
    monkeypatch.setattr(m, "_CHILD", "import os; os.abort()")
    with pytest.raises(DataFileError, match=r"slow\.c3d: not a readable C3D file .*signal 6"):
        load_c3d(path)


def test_c3d_random_damage_never_escapes_as_another_error(tmp_path):
    good = write_c3d(tmp_path / "g.c3d", handover(20), LABELS).read_bytes()
    rnd = random.Random(7)
    outcomes = set()
    for k in range(24):  # each copy is read in a child process (about 0.15 s)
        b = bytearray(good)
        if k % 3 == 0:
            b = b[: rnd.randrange(len(b))]
        else:
            for _ in range(rnd.randint(1, 8)):
                b[rnd.randrange(len(b))] = rnd.randrange(256)
        p = tmp_path / f"d{k}.c3d"
        p.write_bytes(bytes(b))
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DataFileWarning)  # a truncated copy keeps its complete frames
                ds = load_c3d(p, max_nan_gap=20)
            assert np.all(np.isfinite(ds.demos[0]))
            outcomes.add("read")
        except DataFileError as exc:
            assert f"d{k}.c3d" in str(exc)
            outcomes.add("error")
    assert outcomes == {"read", "error"}


def test_c3d_without_the_extra_names_it(monkeypatch, tmp_path):
    import builtins

    path = write_c3d(tmp_path / "x.c3d", handover(10), LABELS)
    real = builtins.__import__

    def fake(name, *args, **kwargs):
        if name == "ezc3d":
            raise ImportError("No module named 'ezc3d'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake)
    with pytest.raises(MissingExtraError, match=r"pip install 'interprim\[mocap\]'"):
        load_c3d(path)


# ----------------------------------------------------------------------------- BVH
BVH_HEAD = """HIERARCHY
ROOT Hips
{
  OFFSET 1 2 3
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Arm
  {
    OFFSET 10 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Hand
    {
      OFFSET 0 20 0
      CHANNELS 3 Xrotation Yrotation Zrotation
      End Site
      {
        OFFSET 0 5 0
      }
    }
  }
}
ROOT B_Hips {
  OFFSET 100 0 0
  CHANNELS 3 Xposition Yposition Zposition
  JOINT B_Hand {
    OFFSET 0 10 0
    CHANNELS 1 Zrotation
    End Site {
      OFFSET 0 5 0
    }
  }
}
MOTION
"""
N_CH = 6 + 3 + 3 + 3 + 1


def _rot(axis, deg):
    a = np.deg2rad(deg)
    c, s = np.cos(a), np.sin(a)
    return {"X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def _fk_reference(row):
    """Joint positions of one frame of BVH_HEAD by explicit matrix products (R = R1 R2 R3 in channel order)."""
    hips_p = np.array(row[0:3])
    r_h = _rot("Z", row[3]) @ _rot("X", row[4]) @ _rot("Y", row[5])
    arm_p = hips_p + r_h @ [10, 0, 0]
    r_a = r_h @ _rot("Z", row[6]) @ _rot("X", row[7]) @ _rot("Y", row[8])
    hand_p = arm_p + r_a @ [0, 20, 0]
    r_hd = r_a @ _rot("X", row[9]) @ _rot("Y", row[10]) @ _rot("Z", row[11])
    end_p = hand_p + r_hd @ [0, 5, 0]
    b_p = np.array([row[12], row[13], row[14]])  # position channels replace the OFFSET
    bh_p = b_p + np.array([0, 10, 0])  # a joint's own rotation moves its children, not itself
    bh_end = bh_p + _rot("Z", row[15]) @ [0, 5, 0]
    return np.concatenate([hips_p, arm_p, hand_p, end_p, b_p, bh_p, bh_end])


def write_bvh(path, rows, frame_time=0.02, frames=None, head=BVH_HEAD):
    lines = [head + f"Frames: {len(rows) if frames is None else frames}\nFrame Time: {frame_time}\n"]
    lines += [" ".join(repr(float(v)) for v in r) + "\n" for r in rows]
    path.write_text("".join(lines))
    return path


def _rows(T=12, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-170, 170, size=(T, N_CH))


def test_bvh_positions_by_forward_kinematics(tmp_path):
    rows = _rows()
    path = write_bvh(tmp_path / "two.bvh", rows, frame_time=0.025)
    ds = load_bvh(path, end_sites=True)
    assert ds.columns == [f"{j}_{a}" for j in ("Hips", "Arm", "Hand", "Hand_end", "B_Hips", "B_Hand", "B_Hand_end")
                          for a in "xyz"]
    want = np.array([_fk_reference(r) for r in rows])
    np.testing.assert_allclose(ds.demos[0], want, rtol=0, atol=1e-9 * np.abs(want).max())
    np.testing.assert_allclose(ds.times[0], np.arange(12) * 0.025, rtol=1e-15, atol=0)
    assert ds.units == [None] * 21
    cm = load_bvh(path, length_unit="cm", joints=["Hand", "Hips"])
    assert cm.columns == ["Hand_x", "Hand_y", "Hand_z", "Hips_x", "Hips_y", "Hips_z"] and cm.units == ["m"] * 6
    np.testing.assert_allclose(cm.demos[0], np.hstack([want[:, 6:9], want[:, 0:3]]) * 0.01, rtol=1e-12, atol=1e-12)


def test_bvh_angles_in_radians_unwrapped(tmp_path):
    rows = np.zeros((8, N_CH))
    rows[:, 15] = [0, 100, 170, -170, -100, 0, 100, 170]  # B_Hand keeps turning the same way through 180 degrees
    rows[:, 3] = np.linspace(-30, 30, 8)
    ds = load_bvh(write_bvh(tmp_path / "a.bvh", rows), mode="angles")
    assert ds.columns == ["Hips_Zrotation", "Hips_Xrotation", "Hips_Yrotation", "Arm_Zrotation", "Arm_Xrotation",
                          "Arm_Yrotation", "Hand_Xrotation", "Hand_Yrotation", "Hand_Zrotation", "B_Hand_Zrotation"]
    assert ds.units == ["rad"] * 10
    np.testing.assert_allclose(ds.demos[0][:, 0], np.deg2rad(np.linspace(-30, 30, 8)), rtol=1e-14)
    np.testing.assert_allclose(ds.demos[0][:, -1], np.deg2rad([0, 100, 170, 190, 260, 360, 460, 530]), rtol=1e-14)


def test_bvh_missing_values_gap_rules(tmp_path):
    rows = _rows(10)
    text = write_bvh(tmp_path / "n.bvh", rows).read_text().splitlines()
    first = text.index("Frame Time: 0.02") + 1
    for k in (4, 5):  # frames 4 and 5: the Arm's Z rotation is missing
        vals = text[first + k].split()
        vals[6] = "nan"
        text[first + k] = " ".join(vals)
    (tmp_path / "n.bvh").write_text("\n".join(text) + "\n")
    with pytest.raises(DataFileError, match=rf"n\.bvh, column 'Arm_x': missing value\(s\) starting at line "
                                            rf"{first + 5} \(frame 4\)"):
        load_bvh(tmp_path / "n.bvh")
    ds = load_bvh(tmp_path / "n.bvh", max_nan_gap=2)
    want = np.array([_fk_reference(r) for r in rows])
    hips = ds.demos[0][:, 0:3]
    np.testing.assert_allclose(hips, want[:, 0:3], rtol=1e-12)  # the root does not depend on the Arm
    np.testing.assert_allclose(ds.demos[0][4, 3:6], want[3, 3:6] + (want[6, 3:6] - want[3, 3:6]) / 3, rtol=1e-9)


@pytest.mark.parametrize(
    "mutate, pattern",
    [
        (lambda t: t.replace("MOTION", "MOTIOM"), r"line 32: unexpected 'MOTIOM' in the HIERARCHY section"),
        (lambda t: t.replace("Xrotation Yrotation Zrotation", "Xrotation Yrotation Wrotation"),
         r"line 13: unknown channel 'Wrotation'"),
        (lambda t: t.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"), r"line 9: CHANNELS announces 4"),
        (lambda t: t.replace("OFFSET 10 0 0", "OFFSET 10 zero 0"), r"line 8: OFFSET values must be numbers"),
        (lambda t: t.replace("JOINT B_Hand", "JOINT Arm"), r"line 24: duplicate joint name 'Arm'"),
        (lambda t: t.replace("Frame Time: 0.02", "Frame Time: -1"), r"line 34: 'Frame Time:' must be a positive"),
        (lambda t: t.replace("Frames: 6", "Frames: 9"), r"truncated file: 'Frames: 9' but the file ends at line 40 "
                                                        r"after 6 frames"),
        (lambda t: t.replace("Frames: 6", "Frames: 4"), r"line 39: more frame lines than 'Frames: 4'"),
        (lambda t: t.replace("Frames: 6", "Frames: 999999999999"), r"truncated file: 'Frames: 999999999999' but"),
        (lambda t: t[: t.rindex(" ")] + "\n", r"line 40 \(frame 5\): 15 values, the hierarchy declares 16"),
        (lambda t: t[: t.rindex(" ")] + " 1e999\n", r"line 40 \(frame 5\): infinite value"),
        (lambda t: t[: t.rindex(" ")] + " oops\n", r"line 40 \(frame 5\): non-numeric value 'oops'"),
        (lambda t: t[:200], r"the file ends inside the HIERARCHY section"),
        (lambda t: "junk\n" + t, r"line 1: expected 'HIERARCHY'"),
    ],
)
def test_bvh_broken_files_name_the_line(tmp_path, mutate, pattern):
    good = write_bvh(tmp_path / "g.bvh", _rows(6)).read_text()
    assert good.splitlines()[31] == "MOTION"  # the line numbers in the patterns refer to this layout
    (tmp_path / "b.bvh").write_text(mutate(good))
    with pytest.raises(DataFileError, match=r"b\.bvh.*" + pattern):
        load_bvh(tmp_path / "b.bvh")


def test_bvh_binary_garbage_and_unknown_joint(tmp_path):
    (tmp_path / "bin.bvh").write_bytes(b"HIERARCHY\n\xff\xfe\x00\x01" * 10)
    with pytest.raises(DataFileError, match=r"bin\.bvh: not a BVH text file \(byte 10 is not UTF-8\)"):
        load_bvh(tmp_path / "bin.bvh")
    path = write_bvh(tmp_path / "j.bvh", _rows(6))
    with pytest.raises(DataFileError, match=r"j\.bvh: unknown joint 'Leg' \(joints=Leg\); the joints are: Hips, Arm"):
        load_bvh(path, joints="Leg")
    with pytest.raises(DataFileError, match=r"the option markers= applies to C3D, Qualisys TSV, Motive CSV files, "
                                            r"not to this BVH file"):
        load_demonstrations(path, markers="x")


# ----------------------------------------------------------------------------- command line
def _cli(argv, capsys):
    from interprim.cli import main

    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow  # fits and predicts on every take through the CLI
def test_cli_fit_and_predict_on_c3d_takes(tmp_path, capsys):
    import interprim as ip

    takes = tmp_path / "takes"
    takes.mkdir()
    for k in range(5):
        write_c3d(takes / f"take{k}.c3d", handover(30 + 3 * k, seed=k), LABELS, rate=50.0)
    model = tmp_path / "m.npz"
    code, out, err = _cli(["fit", "--model", "ip", takes, "--observed", "A:*", "--controlled", "B:RHand_*", "--n-basis",
                           "5",
                           "-o", model], capsys)
    assert code == 0, err
    assert "dropped:    3 columns named in neither --observed nor --controlled" in out
    m = ip.InteractionPrimitive.load(model)
    assert list(m.columns_) == [f"{lab}_{a}" for lab in LABELS[:3] for a in "xyz"]
    assert [m.columns_[i] for i in m.observed_dofs_] == [f"{lab}_{a}" for lab in LABELS[:2] for a in "xyz"]
    code, out, err = _cli(["predict", model, takes / "take1.c3d", "-o", tmp_path / "p.csv"], capsys)
    assert code == 0, err
    assert (tmp_path / "p.csv").read_text().count("\n") > 100
    code, out, err = _cli(["evaluate", "--data", takes, "--observed", "A:*", "--controlled", "B:RHand_*",
                           "--n-basis", "5", "--out", tmp_path / "ev"], capsys)
    assert code == 0, err
    assert "\nverdict: " in out and (tmp_path / "ev" / "report.md").is_file()
    code, out, err = _cli(["evaluate", "--data", takes, "--observed", "A:*", "--folds", "2", "--out", tmp_path / "e2"],
                          capsys)  # 2 folds of 5 leave 2-3 demonstrations to train on
    # what cannot be fitted on 2 demonstrations is left out with a note; the rest is evaluated
    assert code == 0, err
    assert "left out: it cannot be fitted on the 2 demonstrations of a training fold" in err


def test_cli_errors_on_recordings_are_one_line(tmp_path, capsys):
    path = write_c3d(tmp_path / "one.c3d", handover(20), LABELS)
    code, _, err = _cli(["fit", "--model", "ip", path, "--observed", "A:*", "-o", tmp_path / "m.npz"], capsys)
    assert code == 1 and err.count("\n") == 1
    assert "one.c3d holds 1 demonstration; at least 2 are needed" in err
    code, _, err = _cli(["fit", "--model", "ip", path, "--markers", "Nose", "--observed", "0", "-o",
                         tmp_path / "m.npz"], capsys)
    assert code == 1 and err.count("\n") == 1 and "unknown marker 'Nose' (--markers Nose)" in err
    code, _, err = _cli(["fit", "--model", "ip", path, "--observed", "C:*", "-o", tmp_path / "m.npz"], capsys)
    assert code == 1 and "--observed: the pattern 'C:*' matches no column" in err
    code, _, err = _cli(["fit", "--model", "ip", path, "--observed", "A:*", "--controlled", "A:RHand_x", "-o",
                         tmp_path / "m.npz"],
                        capsys)
    assert code == 1 and "--observed and --controlled both name A:RHand_x" in err
    data_start = _data_start(path)
    (tmp_path / "cut.c3d").write_bytes(path.read_bytes()[: data_start + 10])
    code, _, err = _cli(["fit", "--model", "ip", tmp_path / "cut.c3d", "--observed", "0", "-o", tmp_path / "m.npz"],
                        capsys)
    assert code == 1 and err.count("\n") == 1 and "cut.c3d: truncated file" in err and "frame" in err
    code, _, err = _cli(["fit", "--model", "ip", path, "--split-topic", "/x", "--observed", "0", "-o",
                         tmp_path / "m.npz"], capsys)
    assert code == 1 and "the option --split-topic applies to ROS bag files, not to this C3D file" in err


SKELETON = """HIERARCHY
ROOT A_Shoulder
{
  OFFSET 0 140 0
  CHANNELS 3 Zrotation Xrotation Yrotation
  JOINT A_Hand
  {
    OFFSET 60 0 0
    CHANNELS 0
    End Site
    {
      OFFSET 5 0 0
    }
  }
}
ROOT B_Shoulder
{
  OFFSET 100 140 0
  CHANNELS 3 Zrotation Xrotation Yrotation
  JOINT B_Hand
  {
    OFFSET -60 0 0
    CHANNELS 0
    End Site
    {
      OFFSET -5 0 0
    }
  }
}
MOTION
"""


def test_cli_fit_on_bvh_recordings(tmp_path, capsys):
    import interprim as ip

    rng = np.random.default_rng(0)
    folder = tmp_path / "bvh"
    folder.mkdir()
    for k in range(5):
        T = 35 + 2 * k
        s = np.linspace(0, 1, T)
        lift = rng.uniform(30, 60) * (3 * s**2 - 2 * s**3)  # both arms rise towards each other
        rows = np.column_stack([lift, 0 * s, 10 * s, -lift * 0.9, 0 * s, -10 * s])
        write_bvh(folder / f"h{k}.bvh", rows, frame_time=1 / 30, head=SKELETON)
    model = tmp_path / "m.npz"
    code, out, err = _cli(["fit", "--model", "ip", folder, "--joints", "A_Hand,B_Hand", "--length-unit", "cm",
                           "--observed", "A_Hand_*",
                           "--n-basis", "5", "-o", model], capsys)
    assert code == 0, err
    m = ip.InteractionPrimitive.load(model)
    assert list(m.columns_) == ["A_Hand_x", "A_Hand_y", "A_Hand_z", "B_Hand_x", "B_Hand_y", "B_Hand_z"]
    assert m.dt_ == pytest.approx(1 / 30)
    code, out, err = _cli(["fit", "--model", "ip", folder, "--bvh-mode", "angles", "--observed", "A_*", "--n-basis",
                           "5",
                           "-o", tmp_path / "a.npz"], capsys)
    assert code == 0, err
    assert "controlled: B_Shoulder_Zrotation, B_Shoulder_Xrotation, B_Shoulder_Yrotation" in out
