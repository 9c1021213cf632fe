"""Skeleton motion capture from BVH (Biovision Hierarchy) files.

The parser is written here, with forward kinematics by :class:`scipy.spatial.transform.Rotation`,
rather than taken from PyPI.  The one maintained BVH package there, ``bvhio`` (1.5.4), loops
forever on a file that ends before its announced frame count (its line reader never stops at
the end of the file), reports syntax errors without mapping them to a file position that a
caller can show, computes in 32-bit floats (``pyglm``) and pins exact versions of its two
dependencies; the others (``bvh`` 0.3, 2017; ``bvhtoolbox`` 0.1.3, 2020) are unmaintained and
do not compute joint positions.  BVH is a small text format: this parser reads it in 64-bit
floats and reports every problem with its line number.

Format
------
``HIERARCHY``, then one or more ``ROOT name { OFFSET x y z  CHANNELS n ...  JOINT ... }``
blocks (several roots hold several skeletons, e.g. two people), ``End Site { OFFSET ... }``
leaves; then ``MOTION``, ``Frames: N``, ``Frame Time: dt`` and ``N`` lines of channel values
in the order the channels are declared.  Rotation channels are in degrees and applied in the
order they are listed (``Zrotation Xrotation Yrotation`` is ``R = Rz Rx Ry``, intrinsic);
position channels give the joint's translation relative to its parent, replacing the
``OFFSET`` on those axes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import DataFileError
from ._checks import number

__all__ = ["read_bvh"]

_ROT = {"xrotation": "X", "yrotation": "Y", "zrotation": "Z"}
_POS = {"xposition": 0, "yposition": 1, "zposition": 2}


class _Joint:
    def __init__(self, name, parent, line):
        self.name, self.parent, self.line = name, parent, line
        self.offset = np.zeros(3)
        self.channels = []  # canonical names: Xrotation, Yposition, ...
        self.first = 0  # index of its first channel in a frame line
        self.end = None  # End Site offset


def _parse_hierarchy(path, lines):
    """Parse up to ``MOTION``; returns (joints in declaration order, index of the MOTION line)."""
    joints, stack = [], []
    names = set()
    i = 0
    n = len(lines)

    def err(k, msg):
        return DataFileError(f"{path}, line {k + 1}: {msg}")

    def next_nonempty(k):
        while k < n and not lines[k].strip():
            k += 1
        return k

    i = next_nonempty(0)
    if i >= n or lines[i].strip().upper() != "HIERARCHY":
        raise err(min(i, n - 1) if n else 0, "expected 'HIERARCHY' at the start of a BVH file")
    i += 1
    pending = None  # a joint (or 'end') whose '{' is expected
    in_end = None  # the joint whose End Site block is open
    channel_count = 0
    while True:
        i = next_nonempty(i)
        if i >= n:
            raise DataFileError(f"{path}: the file ends inside the HIERARCHY section (line {n}); no MOTION section")
        tok = lines[i].split()
        key = tok[0].upper()
        opens = tok[-1] == "{" and len(tok) > 1
        if opens:
            tok = tok[:-1]
        if key == "MOTION":
            if stack or pending is not None or in_end is not None:
                raise err(i, "MOTION before the hierarchy's braces are closed")
            if not joints:
                raise err(i, "MOTION before any ROOT joint")
            return joints, i, channel_count
        if key in ("ROOT", "JOINT"):
            if pending is not None:
                raise err(i, f"expected '{{' after the declaration of {pending.name!r}")
            if key == "ROOT" and stack:
                raise err(i, "ROOT inside another joint")
            if key == "JOINT" and not stack:
                raise err(i, "JOINT outside a ROOT")
            if in_end is not None:
                raise err(i, "JOINT inside an End Site")
            name = " ".join(tok[1:]).strip()
            if not name:
                raise err(i, f"{tok[0]} without a name")
            if name in names:
                raise err(i, f"duplicate joint name {name!r}")
            names.add(name)
            j = _Joint(name, stack[-1] if stack else None, i + 1)
            joints.append(j)
            pending = j
            if opens:
                stack.append(j)
                pending = None
        elif key == "END":
            if not stack or pending is not None or in_end is not None:
                raise err(i, "misplaced End Site")
            in_end = stack[-1]
            pending = "end"
            if opens:
                pending = None
        elif key == "{":
            if pending is None:
                raise err(i, "unexpected '{'")
            if pending != "end":
                stack.append(pending)
            pending = None
        elif key == "}":
            if pending is not None:
                raise err(i, "'}' before '{'")
            if in_end is not None:
                if in_end.end is None:
                    raise err(i, f"End Site of {in_end.name!r} without OFFSET")
                in_end = None
            elif stack:
                stack.pop()
            else:
                raise err(i, "unmatched '}'")
        elif key == "OFFSET":
            target = in_end if in_end is not None else (stack[-1] if stack else None)
            if target is None or pending is not None:
                raise err(i, "OFFSET outside a joint")
            try:
                vals = np.array([float(v) for v in tok[1:]])
            except ValueError:
                raise err(i, f"OFFSET values must be numbers, got {' '.join(tok[1:])!r}") from None
            if vals.shape != (3,) or not np.all(np.isfinite(vals)):
                raise err(i, f"OFFSET needs 3 finite numbers, got {' '.join(tok[1:])!r}")
            if in_end is not None:
                in_end.end = vals
            else:
                target.offset = vals
        elif key == "CHANNELS":
            if not stack or in_end is not None or pending is not None:
                raise err(i, "CHANNELS outside a joint")
            j = stack[-1]
            if j.channels:
                raise err(i, f"second CHANNELS line for joint {j.name!r}")
            try:
                count = int(tok[1])
            except (IndexError, ValueError):
                raise err(i, "CHANNELS must be followed by the number of channels") from None
            chans = tok[2:]
            if count != len(chans):
                raise err(i, f"CHANNELS announces {count} channels but names {len(chans)}")
            for c in chans:
                low = c.lower()
                if low not in _ROT and low not in _POS:
                    raise err(i, f"unknown channel {c!r}; expected Xposition..Zposition, Xrotation..Zrotation")
            canon = [c[0].upper() + c[1:].lower() for c in chans]
            if len(set(canon)) != len(canon):
                raise err(i, f"a channel is listed twice for joint {j.name!r}")
            j.channels = canon
            j.first = channel_count
            channel_count += count
        else:
            raise err(i, f"unexpected {tok[0]!r} in the HIERARCHY section")
        i += 1


def _header_value(path, lines, i, label):
    """The number after ``label`` (``Frames:`` or ``Frame Time:``) on the next non-empty line from ``i``."""
    while i < len(lines) and not lines[i].strip():
        i += 1
    if i >= len(lines):
        raise DataFileError(f"{path}: the file ends before the '{label}' line of the MOTION section")
    text = lines[i].strip()
    if not text.lower().startswith(label.lower()):
        raise DataFileError(f"{path}, line {i + 1}: expected '{label} ...', got {text[:60]!r}")
    try:
        return float(text[len(label):].strip()), i + 1
    except ValueError:
        raise DataFileError(f"{path}, line {i + 1}: '{label}' must be followed by a number, got {text!r}") from None


def _fk(joints, values, scale):
    """World positions (n, J, 3) of the joints and (n, J', 3) of their End Sites by forward kinematics."""
    from scipy.spatial.transform import Rotation

    n = values.shape[0]
    missing = np.isnan(values)
    values = np.where(missing, 0.0, values)
    rot, pos, bad = {}, {}, {}  # bad: frames where a channel of the joint or of an ancestor is missing
    for j in joints:
        bad[j.name] = missing[:, j.first:j.first + len(j.channels)].any(axis=1)
        if j.parent is not None:
            bad[j.name] |= bad[j.parent.name]
        trans = np.broadcast_to(j.offset, (n, 3)).copy()
        order, cols = "", []
        for k, c in enumerate(j.channels):
            low = c.lower()
            if low in _POS:
                trans[:, _POS[low]] = values[:, j.first + k]
            else:
                order += _ROT[low]
                cols.append(j.first + k)
        local = Rotation.from_euler(order, values[:, cols], degrees=True) if order else Rotation.identity(n)
        if j.parent is None:
            rot[j.name], pos[j.name] = local, trans
        else:
            pr = rot[j.parent.name]
            rot[j.name] = pr * local
            pos[j.name] = pos[j.parent.name] + pr.apply(trans)
    ends = {j.name: pos[j.name] + rot[j.name].apply(np.tile(j.end, (n, 1))) for j in joints if j.end is not None}
    for d in (pos, ends):
        for k in d:
            d[k] = d[k] * scale
            d[k][bad[k]] = np.nan
    return pos, ends


def read_bvh(path, *, mode="positions", joints=None, length_unit=None, end_sites=False, max_nan_gap=0, min_frames=5,
             split=None):
    """Read one BVH file; returns ``(demos, times, columns, labels, meta)`` as the other readers do.

    See :func:`load_bvh` for the parameters; ``split`` holds ``trim``, ``ranges`` and ``gap``
    (:func:`._split.cut_take`).
    """
    from ._checks import check_frames, check_stamps
    from ._split import cut_take
    from .mocap_c3d import metres_per_unit

    path = Path(path)
    if mode not in ("positions", "angles"):
        raise ValueError(f"bvh_mode must be 'positions' or 'angles', got {mode!r}")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataFileError(f"{path}: not a BVH text file (byte {exc.start} is not UTF-8)") from None
    if "\x00" in text:
        raise DataFileError(f"{path}: not a BVH text file (byte {text.index(chr(0))} is a NUL byte)")
    lines = text.splitlines()
    skel, i, n_ch = _parse_hierarchy(path, lines)
    n_frames, i = _header_value(path, lines, i + 1, "Frames:")
    frame_time, i = _header_value(path, lines, i, "Frame Time:")
    if not (np.isfinite(n_frames) and n_frames == int(n_frames) and n_frames >= 0):
        raise DataFileError(f"{path}, line {i - 1}: 'Frames:' must be a whole number, got {n_frames!r}")
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise DataFileError(f"{path}, line {i}: 'Frame Time:' must be a positive number of seconds, got {frame_time!r}")
    n_frames = int(n_frames)
    if n_frames > 1 and not np.isfinite((n_frames - 1) * frame_time):
        raise DataFileError(f"{path}, line {i}: 'Frame Time: {frame_time!r}' over {n_frames} frames gives times "
                            "that are not finite numbers; the frame time is in seconds")
    room = min(n_frames, len(lines) - i)  # not more than the file can hold (a damaged 'Frames:' may be huge)
    values = np.empty((room, n_ch))
    lineno = np.empty(room, dtype=np.int64)
    k = 0
    for li in range(i, len(lines)):
        row = lines[li].split()
        if not row:
            continue
        if k >= n_frames:
            raise DataFileError(f"{path}, line {li + 1}: more frame lines than 'Frames: {n_frames}'")
        if len(row) != n_ch:
            raise DataFileError(
                f"{path}, line {li + 1} (frame {k}): {len(row)} values, the hierarchy declares {n_ch} channels"
            )
        try:
            values[k] = [number(v) for v in row]
        except ValueError:
            bad = next(v for v in row if not _is_number(v))
            raise DataFileError(f"{path}, line {li + 1} (frame {k}): non-numeric value {bad!r}") from None
        if np.isinf(values[k]).any():
            raise DataFileError(f"{path}, line {li + 1} (frame {k}): infinite value")
        lineno[k] = li + 1
        k += 1
    if k < n_frames:
        raise DataFileError(
            f"{path}: truncated file: 'Frames: {n_frames}' but the file ends at line {len(lines)} after {k} frames"
        )
    check_frames(n_frames, min_frames, str(path))
    names = [j.name for j in skel]
    if isinstance(joints, str):
        joints = [x.strip() for x in joints.split(",") if x.strip()]
    if joints is not None:
        for name in joints:
            if name not in names:
                raise DataFileError(
                    f"{path}: unknown joint {name!r} (joints={','.join(joints)}); the joints are: {', '.join(names)}"
                )
        if len(set(joints)) != len(joints):
            raise DataFileError(f"{path}: a joint is selected twice in joints={list(joints)!r}")
    chosen = skel if joints is None else [next(j for j in skel if j.name == name) for name in joints]
    if mode == "angles":
        cols, idx = [], []
        for j in chosen:
            for k2, c in enumerate(j.channels):
                if c.lower() in _ROT:
                    cols.append(f"{j.name}_{c}")
                    idx.append(j.first + k2)
        if not cols:
            raise DataFileError(f"{path}: the selected joints have no rotation channels")
        # NaN-free copy for unwrapping; the NaNs are put back and handled by the gap rules below
        y = np.deg2rad(values[:, idx])
        nan = np.isnan(y)
        y = np.where(nan, 0.0, y)
        y = np.unwrap(y, axis=0)
        y[nan] = np.nan
        units = ["rad"] * len(cols)
    else:
        if length_unit is None:
            scale, unit = 1.0, None
        else:
            scale, unit = metres_per_unit(length_unit, str(path), "length_unit"), "m"
        pos, ends = _fk(skel, values, scale)
        cols, blocks = [], []
        for j in chosen:
            cols += [f"{j.name}_{a}" for a in "xyz"]
            blocks.append(pos[j.name])
            if end_sites and j.name in ends:
                cols += [f"{j.name}_end_{a}" for a in "xyz"]
                blocks.append(ends[j.name])
        y = np.hstack(blocks)
        units = [unit] * len(cols)
    t = np.arange(n_frames) * frame_time
    check_stamps(t, f"{path} ('Frame Time: {frame_time!r}')", lambda r: f"frame {r}")
    split = dict(split or {})
    demos, times, names = cut_take(path, y, t, np.arange(n_frames), split, max_nan_gap=max_nan_gap,
                                   min_frames=min_frames, where_col=lambda d: f"{path}, column {cols[d]!r}",
                                   row_of=lambda r: f"line {lineno[r]} (frame {r})")
    return demos, times, cols, names, {"units": units, "notes": split.get("notes", [])}


def _is_number(v):
    try:
        number(v)
    except ValueError:
        return False
    return True
