"""Evaluation of Interaction Primitives against their peers (paper Fig. 7 and beyond).

* :mod:`.protocol`: the one "observe the first ``p`` %" rule of every experiment;
* :mod:`.baselines`: the peer methods (Interaction ProMP, nearest neighbour, prior mean);
* :mod:`.sweep`: leave-one-out "% observed" sweeps and recognition on NuiSI, the synthetic
  set, the simulated high-five and handwriting (``interprim evaluate``);
* :mod:`.plots`: their figures (matplotlib, the ``plot`` extra).

The sweep's public names are importable from here.
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
