"""NPZ archives of demonstrations: ``demo_000``, ``demo_001``, ... ``(T, D)``, ``time_000``, ... ``(T,)`` (or a
scalar ``dt``), optional ``columns`` and ``observed`` (strings).  Read with ``allow_pickle=False``; every member
is judged from its ``.npy`` header first (:mod:`interprim._npz`, the guard of model files too).
"""

from __future__ import annotations

import re
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..._npz import member_header
from ...core.errors import DataFileError
from .._checks import check_column_names, check_frames, check_stamps, fill_nans
from .base import Common, Reader, Table, TakeOptions, register
from .takes import split_table

__all__ = ["NpzReader", "MAX_NPZ_ARRAY_BYTES", "read_npz"]

_DEMO_KEY = re.compile(r"^demo_(\d+)$")
_TIME_KEY = re.compile(r"^time_(\d+)$")
_NPZ_META = {"columns", "dt", "observed"}

MAX_NPZ_ARRAY_BYTES = 4 << 30  # one array of a data .npz once read (4 GiB)
#: what reading a damaged member raises (a bad CRC, a broken deflate stream, a cut member, a malformed ``.npy``
#: header: numpy parses its text with ``tokenize``/``ast``, which raise these and never execute it)
_DAMAGED = (zipfile.BadZipFile, zlib.error, EOFError, OSError, tokenize.TokenError, SyntaxError)


def _check_npz_member(npz, key: str, path: Path) -> None:
    """Refuse an array of a data ``.npz`` from its ``.npy`` header (:func:`interprim._npz.member_header`; no data
    read) when it declares more than :data:`MAX_NPZ_ARRAY_BYTES`, or more than the member holds."""
    zf = getattr(npz, "zip", None)
    if zf is None:
        return
    try:
        h = member_header(zf, zf.getinfo(key + ".npy"))
    except (KeyError, ValueError, *_DAMAGED):
        return  # reading it reports it
    if h.nbytes > MAX_NPZ_ARRAY_BYTES:
        raise DataFileError(f"{path}: key {key!r} declares shape {h.shape} of {h.dtype} ({h.count:.3g} values, "
                            f"{h.nbytes / 2**30:.3g} GiB), over the limit of {MAX_NPZ_ARRAY_BYTES / 2**30:g} GiB "
                            "for one array: a damaged file?")
    if not h.complete:
        raise DataFileError(f"{path}: key {key!r} declares shape {h.shape} of {h.dtype} ({h.nbytes} bytes) but holds "
                            f"only {h.declared - h.offset} bytes: the file is truncated or damaged")


def read_npz(path: Path, dt, max_nan_gap, min_frames, fill=True):
    """Read one NPZ archive; ``(demos, times, columns, labels, meta)``; ``fill=False`` leaves missing values
    (``nan``) for the take splitter to fill after cutting."""
    try:
        npz = np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001
        raise DataFileError(f"{path}: not a readable .npz file ({type(exc).__name__}: {exc})") from None
    if not hasattr(npz, "files"):
        raise DataFileError(f"{path}: a single .npy array, expected an .npz archive with demo_000, ...")
    meta = {}
    with npz:
        keys = list(npz.files)
        demo_keys: dict[int, str] = {}
        time_keys: dict[int, str] = {}
        for k in keys:
            m = _DEMO_KEY.match(k)
            found = demo_keys if m else time_keys
            m = m or _TIME_KEY.match(k)
            if m:
                i = int(m.group(1))
                if i in found:  # demo_000 and demo_0 are both demonstration 0: one would be lost
                    raise DataFileError(f"{path}: keys {found[i]!r} and {k!r} are both number {i}; every demo_/time_ "
                                        "number must be given once")
                found[i] = k
                continue
            if k not in _NPZ_META:
                raise DataFileError(
                    f"{path}: unknown key {k!r}; expected demo_000, demo_001, ..., time_000, ..., "
                    "and optionally columns, dt, observed"
                )
        if not demo_keys:
            raise DataFileError(f"{path}: no demonstrations (keys demo_000, demo_001, ...); it has {keys}")
        extra = sorted(set(time_keys) - set(demo_keys))
        if extra:
            raise DataFileError(f"{path}: {time_keys[extra[0]]!r} has no matching demo_ key")

        def load(k):
            _check_npz_member(npz, k, path)  # from its header, before any data is read
            try:
                return npz[k]
            except ValueError as exc:
                if "pickle" in str(exc):  # object arrays would need pickle
                    raise DataFileError(f"{path}: key {k!r} cannot be read without pickle ({exc})") from None
                raise DataFileError(f"{path}: key {k!r} is not a readable .npy array (damaged header or data: "
                                    f"{exc})") from None
            except _DAMAGED as exc:
                raise DataFileError(f"{path}: key {k!r} is damaged ({type(exc).__name__}: {exc}); the archive "
                                    "cannot be read") from None
            except MemoryError:
                raise DataFileError(f"{path}: key {k!r} does not fit in memory") from None

        file_dt = None
        if "dt" in npz.files:
            a = load("dt")
            try:
                file_dt = float(np.asarray(a, dtype=np.float64).reshape(()))
            except (TypeError, ValueError):
                raise DataFileError(f"{path}: 'dt' must be one positive number, got shape {a.shape}") from None
            if not (np.isfinite(file_dt) and file_dt > 0):
                raise DataFileError(f"{path}: 'dt' must be a positive number, got {file_dt!r}")
        columns = None
        if "columns" in npz.files:
            a = load("columns")
            if a.dtype.kind not in "US" or a.ndim != 1:
                raise DataFileError(f"{path}: 'columns' must be a 1-D string array, got dtype {a.dtype} "
                                    f"shape {a.shape}")
            columns = [str(c) for c in a.astype(str)]
            dup = sorted({c for c in columns if columns.count(c) > 1})
            if dup:
                raise DataFileError(f"{path}: duplicate column name(s) {dup} in 'columns'")
            check_column_names(columns, f"{path}, 'columns'")
        if "observed" in npz.files:
            a = load("observed")
            meta["observed"] = ",".join(str(c) for c in np.atleast_1d(a).astype(str))
        if time_keys and len(time_keys) != len(demo_keys):
            missing = [demo_keys[i] for i in sorted(demo_keys) if i not in time_keys]
            raise DataFileError(f"{path}: time stamps missing for {missing[:3]} (every demo_ needs a time_ or none)")
        step = file_dt if file_dt is not None else dt
        if not time_keys and step is None:
            raise DataFileError(f"{path}: no time stamps (time_000, ...) and no 'dt'; add either, or pass dt")
        demos, times, labels = [], [], []
        n_cols = None
        for i in sorted(demo_keys):
            k = demo_keys[i]
            y = load(k)
            if y.dtype.kind not in "fiub":
                raise DataFileError(f"{path}: {k!r} is not numeric (dtype {y.dtype})")
            if y.ndim == 1:
                y = y[:, None]
            if y.ndim != 2:
                raise DataFileError(f"{path}: {k!r} must have shape (T, D), got {y.shape}")
            y = y.astype(np.float64)
            if y.shape[1] == 0:
                raise DataFileError(f"{path}: {k!r} has shape {y.shape}: no columns")
            if n_cols is None:
                n_cols = y.shape[1]
                if columns is not None and len(columns) != n_cols:
                    raise DataFileError(f"{path}: 'columns' names {len(columns)} columns but {k!r} has {n_cols}")
            elif y.shape[1] != n_cols:
                raise DataFileError(f"{path}: {k!r} has {y.shape[1]} columns, the first demonstration has {n_cols}")
            where = f"{path}, {k}"
            check_frames(y.shape[0], min_frames, where)
            if np.isinf(y).any():
                r, c = np.argwhere(np.isinf(y))[0]
                raise DataFileError(f"{where}: infinite value at row {r}, column {c}")
            if i in time_keys:
                t = load(time_keys[i])
                if t.dtype.kind not in "fiu" or t.ndim != 1 or t.shape[0] != y.shape[0]:
                    raise DataFileError(
                        f"{path}: {time_keys[i]!r} must be numeric with shape ({y.shape[0]},), got {t.dtype} {t.shape}"
                    )
                t = t.astype(np.float64)
            else:
                t = np.arange(y.shape[0]) * float(step)

            def row_of(r):
                return f"row {r}"

            check_stamps(t, f"{path}, {time_keys.get(i, k)}", row_of)
            cols_now = columns or [f"dof_{j}" for j in range(n_cols)]
            if fill:
                y = fill_nans(y, max_nan_gap, lambda d, _w=where, _c=cols_now: f"{_w}, column {_c[d]!r}", row_of)
            demos.append(y)
            times.append(t)
            labels.append(k)
    if columns is None:
        assert n_cols is not None  # set by the first of the demonstrations (there is at least one)
        columns = [f"dof_{j}" for j in range(n_cols)]
    return demos, times, columns, labels, meta


@register
class NpzReader(Reader):
    """NPZ archives; each demonstration in it is a take that may be split."""

    name = "NPZ"
    suffixes = (".npz",)
    takes = (TakeOptions,)

    def read(self, path: Path, common: Common, options: dict) -> Table:
        """Read ``path`` (see :meth:`Reader.read`)."""
        take = options[TakeOptions]
        splitting = take != TakeOptions()
        table = Table(*read_npz(path, common.dt, int(common.max_nan_gap or 0), common.min_frames, fill=not splitting))
        if splitting:
            table = split_table(path, table, take, common, row_name="row")
        return table
