"""The braking core: configs (``config``), the batched train simulator (``simulator``), the
compiled environment step (``kernel``), the core that steps stops (``braking``), a run's metrics
(``metrics``) and records (``records``). Imports ``physics`` and ``files`` only."""
