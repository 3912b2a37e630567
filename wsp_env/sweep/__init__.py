"""Scale-out on Ray: ``wsp-env sweep`` (grids and Optuna searches of training runs on Ray Tune,
``run``), its sweep files (``config``). Evaluation split across workers lives in
``evaluation.distributed`` (used here for the Ray session)."""
