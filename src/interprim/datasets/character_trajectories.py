"""Loader for the UCI "Character Trajectories" handwriting data set.

Source: UCI Machine Learning Repository, "Character Trajectories", Ben H. Williams (2006),
licence CC BY 4.0.  The labelled half (``trajectories_train.mat``): 1,429 single-stroke
lower-case letters (``abcdeghlmnopqrsuvwyz``) by one writer on a WACOM tablet at 200 Hz.
The file stores smoothed, normalised pen-tip *velocities* and the pen force; positions are
their cumulative sum.  The data is read from a path; it is never copied into this package.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import DataFileError
from ._base import Demonstrations, resolve_data_path

__all__ = ["load_character_trajectories", "CHARACTER_TRAJECTORIES_DEFAULT_PATH", "CHARACTER_DT"]

#: Path of the file relative to the data folder (see :func:`interprim.datasets.data_dir`).
CHARACTER_TRAJECTORIES_DEFAULT_PATH = "character_trajectories/trajectories_train.mat"

#: Sampling interval of the tablet, seconds (200 Hz).
CHARACTER_DT = 1.0 / 200.0


def load_character_trajectories(path=None, letters=None, *, force: bool = False, max_per_letter=None) -> dict:
    """Load the UCI handwritten letters as pen-position trajectories.

    For each sample, the trailing zero padding (frames whose velocities and force are all
    exactly zero, after the last non-zero frame) is trimmed, then the x/y velocities are
    integrated by cumulative sum, so every trajectory starts near the origin.  Units are
    those of the distributed (normalised) velocities, integrated per frame; they are the
    "data units" in which completion errors are reported.

    Parameters
    ----------
    path : str or Path, optional
        ``trajectories_train.mat`` (or the folder holding it).  Defaults to
        ``<data>/character_trajectories/trajectories_train.mat``.
    letters : str or sequence of str, optional
        Letters to load, e.g. ``"abc"`` or ``["a", "b"]`` (default: all 20).
    force : bool
        Append the pen-tip force as a third column ``force`` (default ``False``).
    max_per_letter : int, optional
        Keep only the first ``max_per_letter`` samples of each letter (file order).

    Returns
    -------
    dict of str to Demonstrations
        ``{letter: Demonstrations}``, each a list-like of ``(T_i, 2)`` (or ``(T_i, 3)``)
        arrays with columns ``x, y[, force]``, ``dt = 0.005`` s and time stamps; the
        labels are the sample indices in the file.

    Raises
    ------
    DataNotFoundError
        If the file does not exist.
    DataFileError
        If it is not the Character Trajectories ``.mat`` file.
    ValueError
        For a letter that is not in the data set.
    """
    from scipy.io import loadmat

    p = resolve_data_path(path, CHARACTER_TRAJECTORIES_DEFAULT_PATH, "Character Trajectories")
    try:
        m = loadmat(p)
    except Exception as exc:  # noqa: BLE001
        raise DataFileError(f"{p}: not a readable MATLAB file ({exc})") from None
    for k in ("xtrain", "ytrain", "key"):
        if k not in m:
            raise DataFileError(f"{p}: missing variable {k!r}; is this trajectories_train.mat?")
    key = [str(np.asarray(k).ravel()[0]) for k in np.asarray(m["key"]).ravel()]
    x = np.asarray(m["xtrain"]).ravel()
    y = np.asarray(m["ytrain"]).ravel().astype(int)
    if x.shape[0] != y.shape[0]:
        raise DataFileError(f"{p}: {x.shape[0]} samples but {y.shape[0]} labels")
    if letters is None:
        wanted = list(key)
    else:
        wanted = list(letters) if not isinstance(letters, str) else list(letters)
        bad = [c for c in wanted if c not in key]
        if bad:
            raise ValueError(f"letters {bad} are not in the data set; available: {''.join(key)}")
    cols = ["x", "y", "force"] if force else ["x", "y"]
    out = {}
    for letter in wanted:
        label = key.index(letter) + 1
        idx = np.nonzero(y == label)[0]
        if max_per_letter is not None:
            idx = idx[: int(max_per_letter)]
        demos, times, labels = [], [], []
        for i in idx:
            s = np.asarray(x[i], dtype=np.float64)
            if s.ndim != 2 or s.shape[0] != 3:
                raise DataFileError(f"{p}: sample {i} has shape {s.shape}, expected (3, T)")
            nz = np.nonzero(np.any(s != 0, axis=0))[0]
            if nz.size < 3:
                raise DataFileError(f"{p}: sample {i} has fewer than 3 non-padding frames")
            s = s[:, : nz[-1] + 1]
            pos = np.cumsum(s[:2].T, axis=0)
            arr = np.column_stack([pos, s[2]]) if force else pos
            demos.append(np.ascontiguousarray(arr))
            times.append(np.arange(arr.shape[0]) * CHARACTER_DT)
            labels.append(str(int(i)))
        out[letter] = Demonstrations(
            demos=demos, times=times, columns=list(cols), dt=CHARACTER_DT,
            observed_dofs=None, name=letter, source=str(p), labels=labels,
        )  # fmt: skip
    return out
