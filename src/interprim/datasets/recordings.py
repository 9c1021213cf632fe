"""Motion capture (C3D, BVH) and ROS bags as :class:`~interprim.datasets.Demonstrations`: the public loaders.

Each is :func:`~interprim.datasets.load_demonstrations` with the format's options (the readers are in
:mod:`.mocap_c3d`, :mod:`.mocap_bvh` and :mod:`.ros_bags`; the format is chosen by the file's extension).
"""

from __future__ import annotations

from .files import load_demonstrations

__all__ = ["load_c3d", "load_bvh", "load_rosbag"]


def load_c3d(path, *, markers=None, length_unit=None, max_nan_gap: int | None = None, min_frames: int = 5,
             trim=False, split_events=None, split_frames=None, split_gap=None, split_repetitions=None,
             min_marker_coverage: float | None = None, keep_partial: bool = False):
    """Load the marker trajectories of a C3D motion-capture file (or a folder of them).

    Each file is one demonstration.  Every marker becomes three columns ``<marker>_x``,
    ``<marker>_y``, ``<marker>_z`` in the file's order (labels from ``POINT:LABELS``, then
    ``LABELS2``, ...), **converted to metres** from the file's ``POINT:UNITS`` (``mm`` is the
    usual unit; ``cm``, ``m``, ``in`` and ``ft`` are understood; a file without ``POINT:UNITS``
    is taken as millimetres).  ``Demonstrations.units`` is ``"m"`` for every column.  Points
    the file lists as model outputs (``POINT:ANGLES``, ``FORCES``, ``MOMENTS``, ``POWERS``,
    ``SCALARS``, ``REACTIONS``) are not markers and are left out.

    Time stamps are ``k / POINT:RATE`` seconds for frame ``k`` counted from 0 at the file's
    first frame.  A marker that is missing in a frame (residual < 0, or the coordinates
    ``(0, 0, 0)``, which some exporters write for a lost marker) is a missing value, handled by the
    rule of every marker file (:mod:`interprim.datasets._gaps`): markers seen in fewer than
    ``min_marker_coverage`` of the frames (default half) are left out with one warning; interior
    gaps of up to ``max_nan_gap`` frames (default 0.1 s of frames) are filled by linear
    interpolation; what is left is a :class:`~interprim.core.errors.DataFileError` holding a table of
    the markers, their missing share and their longest gap (frame numbers as the capture software
    numbers them), and the options that fix it.

    Parameters
    ----------
    path : str or Path
        A ``.c3d`` file or a folder of them (natural order, one demonstration per file;
        all files must have the same markers).
    markers : sequence of str or str, optional
        Marker labels to keep, in this order (default all markers).
    length_unit : str, optional
        Overrides the file's ``POINT:UNITS`` (for files that state a wrong unit).
    max_nan_gap : int, optional
        Longest interior gap (frames) filled by interpolation (default: 0.1 s of frames, 10 at 100 Hz).
    min_frames : int
        Fewest frames a demonstration may have (default 5).
    min_marker_coverage : float, optional
        Markers seen in fewer than this share of the frames are left out (default 0.5; 0 keeps all).
    keep_partial : bool
        With ``split_events``: also keep the piece after the last event (not a whole cycle).
    trim : bool
        Drop the leading and trailing frames in which a selected marker is missing (e.g. a marker
        written as 0,0,0 until it is first seen); with splitting, in each demonstration.
    split_events : True or str or sequence of str, optional
        Split the take at the file's events (``EVENT:LABELS``, ``EVENT:TIMES``): each event starts a
        demonstration lasting until the next (``True``: every event; else the labels to use, or
        ``Context:Label``).  An event at ``s`` seconds is frame ``round(s * POINT:RATE) + 1`` of the
        capture (frame 1 at time 0).
    split_frames : str or sequence of (int, int), optional
        The demonstrations as frame ranges ``"FIRST-LAST,..."`` (inclusive, the file's frame numbers).
    split_gap : float, optional
        Seconds: a pause longer than this starts a new demonstration (every marker slower than 5 % of
        the take's 95th-percentile speed, or a marker missing).
    split_repetitions : True or float, optional
        Cut a continuous take into the repetitions of its movement (period found, or given in
        seconds); see :func:`~interprim.datasets.load_demonstrations`.

    Returns
    -------
    Demonstrations
        Split takes have one demonstration per piece, labelled ``<file>@<start>s``, time from 0.
    """

    return load_demonstrations(
        path, markers=markers, length_unit=length_unit, max_nan_gap=max_nan_gap, min_frames=min_frames, trim=trim,
        split_events=split_events, split_frames=split_frames, split_gap=split_gap, split_repetitions=split_repetitions,
        min_marker_coverage=min_marker_coverage, keep_partial=keep_partial,
    )


def load_bvh(path, *, mode="positions", joints=None, length_unit=None, end_sites=False, max_nan_gap: int = 0,
             min_frames: int = 5, trim=False, split_frames=None, split_gap=None, split_repetitions=None):
    """Load a BVH skeleton recording (or a folder of them; one demonstration per file).

    Parameters
    ----------
    path : str or Path
        A ``.bvh`` file or a folder of ``.bvh`` files (natural order; same skeleton in all).
    mode : {"positions", "angles"}
        ``"positions"``: the world position of every joint by forward kinematics, columns
        ``<joint>_x``, ``<joint>_y``, ``<joint>_z`` (in the file's length unit, or in metres
        when ``length_unit`` is given).  ``"angles"``: every rotation channel, columns
        ``<joint>_<channel>`` (e.g. ``RightArm_Zrotation``) in **radians**, unwrapped over time
        so that a turn through +-180 degrees does not jump; the root's translation channels
        are not included.
    joints : sequence of str or str, optional
        Joints to keep, in this order (default all, in the file's order).
    length_unit : str, optional
        The unit of the file's lengths (BVH does not say; ``"cm"`` is common, some
        exporters use ``"m"`` or ``"in"``).  Given, positions are converted to
        metres and ``Demonstrations.units`` is ``"m"``; otherwise they are kept in the file's
        unit and the units are unknown (``None``).
    end_sites : bool
        With ``mode="positions"``, also the ``End Site`` points, columns ``<joint>_end_x``, ...
    max_nan_gap : int
        Longest interior run of missing values (``nan`` in the file), in frames, filled by
        linear interpolation (default 0: none).
    min_frames : int
        Fewest frames a demonstration may have (default 5).
    trim : bool
        Drop the leading and trailing frames with a missing (``nan``) channel.
    split_frames : str or sequence of (int, int), optional
        The demonstrations as frame ranges ``"FIRST-LAST,..."`` (inclusive, frames from 0).
    split_gap : float, optional
        Seconds: a pause longer than this (every column slower than 5 % of the take's
        95th-percentile speed, or a missing value) starts a new demonstration.
    split_repetitions : True or float, optional
        Cut a continuous take into the repetitions of its movement (period found, or given in
        seconds); see :func:`~interprim.datasets.load_demonstrations`.

    Returns
    -------
    Demonstrations
        Time stamps ``k * Frame Time`` seconds (from 0 in each piece of a split take).
    """

    return load_demonstrations(path, bvh_mode=mode, joints=joints, length_unit=length_unit, end_sites=end_sites,
                               max_nan_gap=max_nan_gap, min_frames=min_frames, trim=trim, split_frames=split_frames,
                               split_gap=split_gap, split_repetitions=split_repetitions)


def load_rosbag(path, topics, *, joints=None, orientation=False, split_topic=None, split_gap=None,
                resample_dt=None, max_nan_gap: int = 0, min_frames: int = 5):
    """Load two-agent demonstrations from a ROS 1 or ROS 2 bag.

    Parameters
    ----------
    path : str or Path
        A ROS 1 ``.bag``, a ROS 2 ``.db3`` or ``.mcap`` file, or a rosbag2 folder (with
        ``metadata.yaml``).
    topics : sequence of str or str
        ``(observed, controlled)``: two topics, or ``tf:FRAME`` / ``TOPIC:FRAME`` for a tf
        frame (a comma-separated string also works).  One topic gives a single-agent set.
        The observed agent's columns become ``observed_dofs``.
    joints : sequence of str, optional
        JointState joints to keep (default every joint seen).
    orientation : bool
        Also read the orientation quaternion of poses and tf frames (default False).
    split_topic : str, optional
        A topic whose messages mark the start of each demonstration.
    split_gap : float, optional
        Seconds: a pause longer than this in either stream starts a new demonstration.
    resample_dt : float, optional
        Interpolate both streams onto a uniform grid of this interval (seconds) instead of
        onto the observed stream's stamps.
    max_nan_gap : int
        Longest interior run of missing values (frames) filled by interpolation.
    min_frames : int
        Fewest frames a demonstration may have.

    Returns
    -------
    Demonstrations
        Time stamps start at 0 in each demonstration; labels are ``<bag>@<start>s`` with the
        start in seconds after the beginning of the bag.
    """

    return load_demonstrations(path, topics=topics, joints=joints, orientation=orientation, split_topic=split_topic,
                               split_gap=split_gap, resample_dt=resample_dt, max_nan_gap=max_nan_gap,
                               min_frames=min_frames)
