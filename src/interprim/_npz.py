"""The one ``.npz`` guard of the package: an archive member's ``.npy`` header read before any of its data.

Both readers of ``.npz`` files use it: model files (:mod:`interprim.io`) and data files
(:mod:`interprim.datasets.formats.npzfile`).  A member is judged from its header (shape and dtype, a few
hundred bytes) and from the size the zip directory declares for it, so a damaged or hostile archive is refused
before it is decompressed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["NpyHeader", "read_npy_header", "member_header"]


@dataclass(frozen=True)
class NpyHeader:
    """What a ``.npy`` member declares: ``shape``, ``fortran`` order, ``dtype``, the byte ``offset`` of its data,
    the data's size ``nbytes`` and the member's uncompressed size ``declared`` (from the zip directory)."""

    shape: tuple
    fortran: bool
    dtype: np.dtype
    offset: int
    nbytes: int
    declared: int

    @property
    def count(self) -> int:
        """Number of values."""
        return math.prod(int(d) for d in self.shape)

    @property
    def complete(self) -> bool:
        """Whether the member holds at least the data its header declares."""
        return self.dtype.hasobject or self.offset + self.nbytes <= self.declared


def read_npy_header(fh):
    """``(shape, fortran, dtype)`` from an open ``.npy`` stream positioned at its start (versions 1.0 and 2.0);
    ``ValueError`` for another version."""
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        return np.lib.format.read_array_header_1_0(fh)
    if version == (2, 0):
        return np.lib.format.read_array_header_2_0(fh)
    raise ValueError(f".npy version {version} is not supported")


def member_header(zf, info) -> NpyHeader:
    """The header of the member ``info`` (a ``zipfile.ZipInfo``) of the open archive ``zf``, no data read."""
    with zf.open(info) as fh:
        shape, fortran, dtype = read_npy_header(fh)
        offset = fh.tell()
    nbytes = math.prod(int(d) for d in shape) * dtype.itemsize
    return NpyHeader(tuple(shape), bool(fortran), dtype, int(offset), int(nbytes), int(info.file_size))
