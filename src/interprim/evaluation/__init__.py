"""Evaluation of Interaction Primitives against their peers (paper Fig. 7 and beyond).

* :mod:`.sweep`: leave-one-out "% observed" sweeps and recognition on NuiSI, the synthetic
  set, the simulated high-five and handwriting (``interprim evaluate``);
* :mod:`.realtime`: the protocols in seconds (real-time prediction, phase, calibration) and the verdicts;
* :mod:`.nested`: choices made inside the training data only, and the hold-out (:data:`.nested.HOLDOUT`);
* :mod:`.plots` and :mod:`.realtime_plots`: their figures (matplotlib, the ``plot`` extra).

The "observe the first ``p`` %" rule and causal prefixes are :mod:`interprim.model_selection.prefixes`; the
peer methods are families of :mod:`interprim.models` (:mod:`interprim.models.demonstrations`,
:mod:`interprim.models.promp`, :mod:`interprim.models.kernel`).  The sweep's public names are importable
from here.
"""

from .sweep import (
                    METHODS,
                    EvalConfig,
                    evaluate_fold,
                    load_task,
                    make_estimator,
                    markdown_tables,
                    recognition_fold,
                    recognition_table,
                    run_sweep,
                    save_results,
                    summarise,
                    task_names,
)

__all__ = ["METHODS", "EvalConfig", "evaluate_fold", "make_estimator", "markdown_tables", "recognition_fold",
           "recognition_table", "run_sweep", "save_results", "summarise", "task_names", "load_task"]
