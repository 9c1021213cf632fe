"""Loaders for real recorded movements and for users' own demonstration files.

Data sets (read from a path, never copied into the package; see ``docs/datasets.md`` for
sources and licences):

- :func:`load_nuisi` - NuiSI human-human interactions (Prasad et al., 2022; AGPL-3.0).
- :func:`load_character_trajectories` - UCI Character Trajectories (B. H. Williams; CC BY 4.0).
- :func:`load_lasa` - LASA handwriting shapes (EPFL; non-commercial), optional extra
  ``pip install "interprim[lasa]"``.

Users' files (formats in ``docs/data-formats.md``): :func:`load_demonstrations` and
:func:`save_demonstrations` for CSV files, NPZ archives and folders of them;
:func:`load_demonstrations` also reads recordings by their extension: motion capture
(:func:`load_c3d`, :func:`load_bvh`; C3D needs ``pip install 'interprim[mocap]'``) and ROS 1/2
bags (:func:`load_rosbag`; ``pip install 'interprim[ros]'``).

The default data folder is ``$INTERPRIM_DATA`` or ``../shared/data`` beside the checkout
(:func:`data_dir`).
"""

from ._base import DataNotFoundError, Demonstrations, RawStream, data_dir
from .character_trajectories import load_character_trajectories
from .files import load_demonstrations, save_demonstrations
from .lasa import lasa_shapes, load_lasa
from .nuisi import JOINT_GROUPS, NUISI_JOINTS, load_nuisi, nuisi_actions
from .recordings import load_bvh, load_c3d, load_rosbag

__all__ = [
    "Demonstrations",
    "RawStream",
    "DataNotFoundError",
    "data_dir",
    "load_nuisi",
    "nuisi_actions",
    "NUISI_JOINTS",
    "JOINT_GROUPS",
    "load_character_trajectories",
    "load_lasa",
    "lasa_shapes",
    "load_demonstrations",
    "save_demonstrations",
    "load_c3d",
    "load_bvh",
    "load_rosbag",
]
