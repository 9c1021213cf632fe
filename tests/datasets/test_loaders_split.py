"""Trimming and splitting one long motion-capture take (C3D, BVH) into demonstrations, and the shared rule.

The takes are written here (C3D with ``ezc3d``, BVH as text); every piece read back is compared with the
frames that were written for it.
"""

import re

import ezc3d
import numpy as np
import pytest
from test_loaders_mocap import LABELS, _cli, f32, handover, write_bvh, write_c3d

from interprim.core.errors import DataFileError
from interprim.datasets import load_bvh, load_c3d, load_demonstrations
from interprim.datasets._split import spans


def add_events(path, events, rate):
    """Rewrite the C3D file ``path`` with an EVENT group: ``events`` is a list of (label, time in s)."""
    c = ezc3d.c3d(str(path))
    n = len(events)
    times = np.array([[t // 60 for _, t in events], [t % 60 for _, t in events]])  # (minutes, seconds), dims [2, n]
    c.add_parameter("EVENT", "USED", [n])
    c.add_parameter("EVENT", "TIMES", times)
    c.add_parameter("EVENT", "LABELS", [lab for lab, _ in events])
    c.add_parameter("EVENT", "CONTEXTS", ["Right"] * n)
    c.write(str(path))
    return path


def long_take(reps=3, still=50, seed=0):
    """``reps`` handovers there and back (80 frames each, 100 Hz), each after ``still`` frames at rest (with 0.05 mm
    of marker noise), and a rest at the end; returns (xyz, the first frame of each handover)."""
    parts, starts, k = [], [], 0
    rng = np.random.default_rng(seed)
    for r in range(reps):
        move = handover(40, seed=r)
        parts += [move[:1] + rng.normal(0, 0.05, (still, 4, 3)), move, move[::-1]]
        starts.append(k + still)
        k += still + 80
    parts.append(move[:1] + rng.normal(0, 0.05, (still, 4, 3)))
    return np.concatenate(parts), starts


# ----------------------------------------------------------------------------- the rule
def test_spans_is_one_rule_for_markers_ranges_and_pauses():
    assert spans(0, 99) == [(0, 99)]
    assert spans(0, 99, starts=[10, 40]) == [(10, 39), (40, 99)]  # before the first marker: not used
    assert spans(0, 99, cuts=[(29, 50)]) == [(0, 29), (50, 99)]
    assert spans(0, 99, starts=[10, 40], cuts=[(20, 30)]) == [(10, 20), (30, 39), (40, 99)]
    assert spans(0, 99, ranges=[(5, 9), (90, 120)]) == [(5, 9), (90, 99)]
    assert spans(0, 99, cuts=[(-1, 20), (80, 100)]) == [(20, 80)]  # pauses at the ends


# ----------------------------------------------------------------------------- trimming
def test_c3d_trim_leading_zero_marker_like_my_looped_motion(tmp_path):
    """py-c3d's my-looped-motion.c3d writes a marker as 0,0,0 for its first 25 frames: refused, or trimmed."""
    xyz = handover(60)
    zeroed = np.zeros((60, 4), bool)
    zeroed[:25, 2] = True
    zeroed[57:, 1] = True  # and lost again for the last 3 frames
    path = write_c3d(tmp_path / "looped.c3d", xyz, LABELS, first_frame=1, zeroed=zeroed)
    with pytest.raises(DataFileError, match=r"(?s)looped\.c3d: 1 of 1 markers still miss frames.*B:RHand +41\.7 % +25 "
                                            r"frames \(0\.25 s\), frames 1-25 \(at the start or end: not filled\)"
                                            r".*trim=True"):
        load_c3d(path, markers="B:RHand")
    ds = load_c3d(path, trim=True)
    assert ds.labels == ["looped"] and ds.demos[0].shape == (32, 12)
    np.testing.assert_allclose(ds.demos[0], f32(xyz[25:57]).reshape(32, 12) * 1e-3)
    np.testing.assert_allclose(ds.times[0], np.arange(32) / 100.0)
    assert load_c3d(path, trim=True, markers="A:RHand").demos[0].shape == (60, 3)  # that marker is never lost


def test_bvh_trim_nan_frames(tmp_path):
    from test_loaders_mocap import _rows

    rows = _rows(20)
    rows[:3, 15] = np.nan
    path = write_bvh(tmp_path / "t.bvh", rows)
    ds = load_bvh(path, mode="angles", trim=True)
    assert ds.demos[0].shape[0] == 17
    np.testing.assert_allclose(ds.times[0], np.arange(17) * 0.02)


# ----------------------------------------------------------------------------- splitting
def test_c3d_split_by_the_files_events(tmp_path):
    xyz, starts = long_take()
    path = write_c3d(tmp_path / "long.c3d", xyz, LABELS, first_frame=1)
    # an event at s seconds is capture frame round(s * rate) + 1, i.e. row round(s * rate) here
    add_events(path, [("Start", s / 100.0) for s in starts] + [("Foot Strike", 0.07)], rate=100.0)
    ds = load_c3d(path, split_events="Start")
    # the piece after the last event runs to the end of the take, not to a next event: left out, and said so
    assert len(ds) == 2
    assert any("the piece after the last event (frames " in n and "not a whole cycle: left out" in n for n in ds.notes)
    ds = load_c3d(path, split_events="Start", keep_partial=True)
    assert len(ds) == 3
    bounds = starts[1:] + [len(xyz)]
    for d, t, a, b in zip(ds.demos, ds.times, starts, bounds):
        np.testing.assert_allclose(d, f32(xyz[a:b]).reshape(b - a, 12) * 1e-3)
        assert t[0] == 0.0 and len(t) == b - a
    assert ds.labels == [f"long@{s / 100:.3f}s" for s in starts]
    assert len(load_c3d(path, split_events=True)) == 3  # every event, 'Foot Strike' too (the last piece left out)
    assert len(load_c3d(path, split_events="Right:Start")) == 2
    with pytest.raises(DataFileError, match=r"long\.c3d: no event Heel inside frames 1-\d+ to split at "
                                            r"\(split_events\); the file's events: Right:Start at 0\.500 s"):
        load_c3d(path, split_events="Heel")


def test_c3d_and_bvh_split_by_frame_ranges(tmp_path):
    xyz = handover(60)
    path = write_c3d(tmp_path / "r.c3d", xyz, LABELS, first_frame=101)
    ds = load_demonstrations(path, split_frames="111-120,131-150")  # the file's frame numbers
    assert [d.shape[0] for d in ds.demos] == [10, 20]
    np.testing.assert_allclose(ds.demos[1], f32(xyz[30:50]).reshape(20, 12) * 1e-3)
    with pytest.raises(DataFileError, match=r"split_frames 90-120 is not inside the recording's frames 101-160"):
        load_c3d(path, split_frames="90-120")
    with pytest.raises(DataFileError, match=r"split_frames 'x' is not a frame range FIRST-LAST"):
        load_c3d(path, split_frames="x")
    from test_loaders_mocap import _rows

    rows = _rows(30)
    bvh = write_bvh(tmp_path / "r.bvh", rows)
    whole = load_bvh(bvh, mode="angles")
    ds = load_bvh(bvh, mode="angles", split_frames="0-9,20-29")
    np.testing.assert_allclose(ds.demos[1], whole.demos[0][20:30])
    with pytest.raises(DataFileError, match=r"r\.bvh, frames 0-2 \(a larger split_gap, fewer events or longer "
                                            r"split_frames\?\): only 3 frame\(s\), at least 5"):
        load_bvh(bvh, split_frames="0-2,10-20")


def test_c3d_split_by_pauses(tmp_path):
    xyz, starts = long_take(still=60)
    path = write_c3d(tmp_path / "p.c3d", xyz, LABELS)
    ds = load_c3d(path, split_gap=0.3)  # 0.6 s at rest between the movements
    assert len(ds) == 3
    for d, lab, s in zip(ds.demos, ds.labels, starts):
        # each piece is its movement, give or take the few frames at either end that are nearly still
        start = round(float(lab.split("@")[1][:-1]) * 100)
        assert abs(start - s) <= 6 and 68 <= d.shape[0] <= 92
        np.testing.assert_allclose(d[s + 40 - start], f32(xyz[s + 40]).ravel() * 1e-3)
    assert len(load_c3d(path, split_gap=1.0)) == 1  # no pause is that long


def test_bvh_split_by_pauses(tmp_path):
    from test_loaders_mocap import N_CH

    rows = np.zeros((200, N_CH))
    rows[40:80, 3] = np.linspace(0, 90, 40)  # the root turns, rests, turns back, rests
    rows[80:120, 3] = 90.0
    rows[120:160, 3] = np.linspace(90, 0, 40)
    path = write_bvh(tmp_path / "p.bvh", rows, frame_time=0.01)
    ds = load_bvh(path, split_gap=0.2)
    assert len(ds) == 2
    for d, lab, start in zip(ds.demos, ds.labels, (40, 120)):
        assert abs(float(lab.split("@")[1][:-1]) - start / 100) <= 0.06 and 36 <= d.shape[0] <= 52


def test_split_options_belong_to_their_formats(tmp_path):
    from test_loaders_mocap import _rows

    bvh = write_bvh(tmp_path / "x.bvh", _rows(10))
    with pytest.raises(DataFileError, match=r"split_events applies to files that carry events \(C3D, Qualisys TSV\), "
                                            r"not to this BVH file"):
        load_demonstrations(bvh, split_events=True)
    with pytest.raises(ValueError, match="split_gap must be a positive number of seconds"):
        load_demonstrations(bvh, split_gap=-1)


# ----------------------------------------------------------------------------- command line
def test_cli_fit_on_one_take_split_by_events_and_predict_a_fraction(tmp_path, capsys):
    xyz, starts = long_take(reps=4)
    path = write_c3d(tmp_path / "long.c3d", xyz, LABELS)
    add_events(path, [("Start", s / 100.0) for s in starts], rate=100.0)
    model = tmp_path / "m.npz"
    code, out, err = _cli(["fit", "--model", "ip", path, "--split-events", "--observed", "A:*", "--n-basis", "5", "-o",
                           model], capsys)
    assert code == 0, err
    assert "fitted 3 demonstrations" in out  # the piece after the last event is left out, and the command says so
    assert re.search(r"note: .*long\.c3d: --split-events: the piece after the last event "
                     r"\(frames \d+-\d+, [\d.]+ s\) runs to the end of the recording, not to a next event, so it is "
                     r"not a whole cycle: left out \(keep it with --keep-partial\)", out), out
    code, out, err = _cli(["fit", "--model", "ip", path, "--split-events", "--keep-partial", "--observed", "A:*",
                           "--n-basis", "5", "-o", model], capsys)
    assert code == 0 and "fitted 4 demonstrations" in out, err
    one = write_c3d(tmp_path / "one.c3d", handover(40, seed=1), LABELS)
    code, out, err = _cli(["predict", model, one, "--observe-fraction", "0.6", "-o", tmp_path / "p.csv"], capsys)
    assert code == 0, err
    assert "24 frames observed" in out  # ceil(0.6 * 40)
    code, out, err = _cli(["predict", model, one, "--observe-fraction", "0", "-o", tmp_path / "p.csv"], capsys)
    assert code == 1 and "--observe-fraction must be in (0, 1], got 0.0" in err
    code, out, err = _cli(["fit", "--model", "ip", path, "--trim", "--split-frames", "51-90,141-180,231-270",
                           "--observed", "A:*",
                           "--n-basis", "5", "-o", model], capsys)
    assert code == 0, err
    assert "fitted 3 demonstrations" in out


# ----------------------------------------------------------------------------- repetitions in a continuous take
def periodic_take(n_reps=6, seed=0, rate=100.0):
    """A continuous take of ``n_reps`` repetitions (hops or steps) of varying length, without pauses: each
    repetition starts at rest for an instant (a landing: zero speed, no still frames), and those instants are the
    known cut points (millimetres, 4 markers, 0.5 mm of marker noise)."""
    rng = np.random.default_rng(seed)
    lengths = rng.integers(85, 116, n_reps)  # 0.85-1.15 s per repetition

    def rep(n, first=0, last=None):
        u = np.arange(n) / n
        return (2 * np.pi * u - np.sin(2 * np.pi * u))[first:last]  # d(phase)/du = 0 at u = 0

    lead = 37  # the take starts inside a repetition ...
    parts, starts, pos = [rep(100, 100 - lead)], [], lead
    for n in lengths:
        starts.append(pos)
        parts.append(rep(n))
        pos += n
    parts.append(rep(100, 0, 30))  # ... and ends inside one
    ph = np.concatenate(parts)
    base = np.stack([np.sin(ph) * 120, np.cos(ph) * 60, 40 * np.sin(2 * ph) + 300 * (1 - np.cos(ph))], axis=1)
    xyz = np.stack([base + [0, 0, 900], base * 0.5 + [200, 0, 500], base * [1, -1, 1] + [0, 300, 900],
                    base * 0.3 + [400, 300, 100]], axis=1)
    xyz += rng.normal(0, 0.5, xyz.shape)
    return xyz, np.array(starts), int(pos)


def test_split_repetitions_finds_the_cuts_of_a_continuous_take(tmp_path):
    """--split-gap finds no pause in a take without pauses; split_repetitions cuts it into its repetitions,
    within a few frames of the true cut points, and says what it found."""
    from interprim.datasets._split import find_repetitions

    xyz, starts, end = periodic_take()
    path = write_c3d(tmp_path / "hops.c3d", xyz, LABELS)
    whole = load_c3d(path, split_gap=0.3)
    assert len(whole) == 1  # no pause: no cut (the case that failed)
    ds = load_c3d(path, split_repetitions=True)
    got = np.array([round(float(lab.split("@")[1][:-1]) * 100) for lab in ds.labels])  # '@0.370s' -> frame 37
    # every whole repetition, cut within 3 frames (30 ms) of its true start
    assert len(ds) == len(starts), (got, starts)
    np.testing.assert_allclose(got, starts, atol=3)
    assert all(abs(len(d) - np.median(np.diff(starts))) < 0.3 * np.median(np.diff(starts)) for d in ds.demos)
    assert len(ds.notes) == 1 and "split_repetitions: period" in ds.notes[0]
    period = float(ds.notes[0].split("period ")[1].split(" s")[0])
    assert 0.9 < period < 1.1
    # the period given in seconds gives the same cuts, to a frame (1.0 s here; the found period is within 10 %)
    given = load_c3d(path, split_repetitions=1.0)
    assert "given" in given.notes[0] and len(given) == len(ds)
    at = lambda d: np.array([round(float(lab.split("@")[1][:-1]) * 100) for lab in d.labels])  # noqa: E731
    assert np.max(np.abs(at(given) - at(ds))) <= 1
    # a take without repetitions is a clear error
    still = np.cumsum(np.random.default_rng(1).normal(0, 1, (300, 4, 3)), axis=0)
    with pytest.raises(DataFileError, match="split_repetitions found no repeating movement"):
        find_repetitions(still.reshape(300, 12), 100.0, where="walk.c3d")


def test_split_repetitions_on_a_bvh_hop_take(tmp_path):
    """A BVH take of hops without pauses (every channel a function of the hop's phase): cut at the landings."""
    from test_loaders_mocap import N_CH

    xyz, starts, end = periodic_take(n_reps=5, seed=2)
    feats = xyz.reshape(len(xyz), -1)
    rows = np.stack([feats[:, k % feats.shape[1]] / (10 + k) for k in range(N_CH)], axis=1)  # degrees, cm
    bvh = write_bvh(tmp_path / "hops.bvh", rows, frame_time=0.01)
    ds = load_bvh(bvh, mode="angles", split_repetitions=True)
    got = np.array([round(float(lab.split("@")[1][:-1]) * 100) for lab in ds.labels])
    assert len(ds) == len(starts), (got, starts)
    np.testing.assert_allclose(got, starts, atol=3)
    assert "split_repetitions: period" in ds.notes[0]


def test_pieces_too_short_after_splitting_are_dropped_with_one_warning(tmp_path):
    """Two events 3 frames apart leave a 3-frame piece: left out with one warning, not a hard error."""
    from interprim.core.errors import DataFileWarning

    xyz, starts = long_take(reps=2, still=50)
    path = add_events(write_c3d(tmp_path / "ev.c3d", xyz, LABELS),
                      [("Foot Strike", 0.5), ("Foot Strike", 1.0), ("Foot Strike", 1.03), ("Foot Strike", 2.0)], 100.0)
    with pytest.warns(DataFileWarning) as rec:
        ds = load_c3d(path, split_events=True)
    msgs = [str(w.message) for w in rec if issubclass(w.category, DataFileWarning)]
    assert len(msgs) == 1
    assert re.search(r"ev\.c3d: 1 piece\(s\) shorter than 5 frames left out \(frames 101-103\); "
                     r"2 demonstrations kept", msgs[0]), msgs
    assert [len(d) for d in ds.demos] == [50, 97]  # the piece after the last event is not a whole cycle
    assert any("the piece after the last event (frames 201-" in n for n in ds.notes)


def test_split_repetitions_auto_is_refused_with_its_name(tmp_path):
    """'auto' means one thing in interprim (the model chosen on the data): the period is found with True."""
    from interprim.datasets import load_c3d

    path = tmp_path / "hops.c3d"
    write_c3d(path, np.zeros((60, 1, 3)) + np.sin(np.linspace(0, 12 * np.pi, 60))[:, None, None], ["a"])
    with pytest.raises(ValueError, match="split_repetitions must be True"):
        load_c3d(path, split_repetitions="auto")
