"""The paper's experiments and this library's studies, as runnable modules (need the ``experiments`` extra).

* :mod:`interprim.experiments.highfive`: the simulated high-five (Sec. IV, Fig. 5-8; ``interprim demo``);
* :mod:`interprim.experiments.handwriting`: handwriting completion (Fig. 3-4; ``interprim handwriting``);
* :mod:`interprim.experiments.quickstart`: core figures on the built-in synthetic data;
* :mod:`interprim.experiments.phase_nuisi`, :mod:`interprim.experiments.coupling_nuisi`: the phase and
  coupling studies on the NuiSI recordings.
"""
