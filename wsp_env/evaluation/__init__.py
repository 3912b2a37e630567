"""Evaluation: scenario suites (``suites``), the one code path that runs any policy on them
(``runner``), the dry and available-adhesion references (``reference``), reports and plots
(``report``, ``plotting``), the trace writer (``trace_writer``) and the speed benchmark
(``bench``)."""

from wsp_env.evaluation.runner import run_one, run_suite, summarise, trace_metadata
from wsp_env.evaluation.suites import CaseConfig, SuiteConfig, expand, load_suite

__all__ = [
    "CaseConfig",
    "SuiteConfig",
    "expand",
    "load_suite",
    "run_one",
    "run_suite",
    "summarise",
    "trace_metadata",
]
