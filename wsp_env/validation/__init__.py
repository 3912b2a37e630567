"""Validation against the seeds: the published targets (``targets``), the fidelity checks
``wsp-env validate`` runs (``checks``) and their report (``report``)."""
