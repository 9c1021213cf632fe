"""One reader per file format behind one interface (:class:`~interprim.datasets.formats.base.Reader`) with
typed options.

=====================  ==========================  ==========================================
format                 module                      options
=====================  ==========================  ==========================================
CSV                    :mod:`.csvfile`             :class:`CsvOptions`, :class:`TakeOptions`
NPZ                    :mod:`.npzfile`             :class:`TakeOptions`
C3D                    :mod:`.c3dfile`             :class:`MarkerOptions`, :class:`TakeOptions`
Qualisys TSV           :mod:`.qualisys`            :class:`MarkerOptions`, :class:`TakeOptions`
OptiTrack Motive CSV   :mod:`.motive`              :class:`MarkerOptions`, :class:`TakeOptions`
BVH                    :mod:`.bvhfile`             :class:`BvhOptions`, :class:`TakeOptions`
ROS 1/2 bags           :mod:`.rosbag`              :class:`RosOptions`
=====================  ==========================  ==========================================

A new format is one module here: a :class:`Reader` subclass decorated with :func:`register`, named in
:data:`MODULES`.
"""

from __future__ import annotations

import importlib

from .base import (
    OPTION_TYPES,
    READERS,
    BvhOptions,
    Common,
    CsvOptions,
    MarkerOptions,
    Reader,
    RosOptions,
    Table,
    TakeOptions,
    reader_for,
    register,
)

__all__ = ["Reader", "Table", "Common", "TakeOptions", "CsvOptions", "MarkerOptions", "BvhOptions", "RosOptions",
           "OPTION_TYPES", "READERS", "register", "reader_for", "MODULES"]

#: the modules holding the readers (imported on first use: numpy-only, the optional packages inside ``read``)
MODULES = ("csvfile", "npzfile", "c3dfile", "qualisys", "motive", "bvhfile", "rosbag")
_loaded = False


def load_all() -> None:
    global _loaded
    if not _loaded:
        for m in MODULES:
            importlib.import_module(f"{__name__}.{m}")
        _loaded = True
