"""Compiled kernels (numba, cached on disk), one module per stage of the paper, and their one loader.

:mod:`~interprim.core._compiled.registry` lists each kernel with its numpy reference and
hands them to callers by name; :mod:`~interprim.core._compiled.loader` decides whether the
kernels or their numpy equivalents run (``ready``, ``warmup``); the kernels are :mod:`.dtw` (Eq. 5-8),
:mod:`.observation` (Eq. 3, 13-15), :mod:`.conditioning` (Eq. 16-18),
:mod:`.linalg` (small dense factorisations), :mod:`.rollout` (Eq. 1), :mod:`.resample` (linear
interpolation of many columns, bit for bit numpy.interp) and
:mod:`.phase_likelihood` (the likelihood phase).  Importing this package does
not import numba.
"""

#: fastmath flags of the kernels: reassociation lets LLVM vectorise reductions; no 'nnan'/'ninf'
#: (inputs are checked finite upstream)
FASTMATH = {"contract", "reassoc", "nsz", "arcp"}

#: log(2 pi) of the Gaussian log-likelihoods (the same float as interprim.core.gaussian.LOG2PI)
LOG2PI = 1.8378770664093453
