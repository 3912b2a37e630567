"""A result depends on its seed and the C library, not on numpy's choice of code for the CPU.

numpy's transcendental ufuncs (``exp``, ``log``, ``power``, ``arccos``, ``cbrt``, ``tanh``, ...)
use numpy's own vector routines where the CPU has them (numpy 2.4 on AVX-512, its ``X86_V4``
dispatch), and those differ from the C library's in the last bit: on the AVX-512 host where this
was found, on about 5 % of arguments for ``exp`` and ``power``, half for ``cbrt``. A last bit in
one axle's creep stiffness moved a sealed stop of the classical WSP by 1.4 m, and one of the
independent generator's frozen records (``test_independent_traces.py``) failed there. So the
set-up calls the C library (``wsp_env.physics.libm``; the generator through ``math`` and its
own kernel), as the compiled kernels do.

Each test runs the same thing in two subprocesses: with numpy's dispatch for this CPU, and with
every target numpy's build dispatches to turned off (``NPY_DISABLE_CPU_FEATURES``: numpy's
baseline loops, which call the C library), and asks for the same bits. On a CPU without the
vector routines the two runs are the same by construction and the tests cannot fail: they check
where it matters (an AVX-512 CI machine or laptop). What they do not cover: the C library's own
choice of code (glibc picks FMA variants of ``exp``, ``log``, ``pow``, ``sin``: the same on every
x86-64 machine with FMA, every AVX2 or AVX-512 one), numba built with Intel's SVML (not
installed here: ``numba -s``), and learned policies (torch's kernels depend on the CPU:
docs/physics.md).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

_FEATURES = """
import json
try:
    from numpy._core import _multiarray_umath as m
except ImportError:  # numpy < 2
    from numpy.core import _multiarray_umath as m
print(json.dumps({"dispatch": list(m.__cpu_dispatch__),
                  "on": [f for f in m.__cpu_dispatch__ if m.__cpu_features__.get(f)]}))
"""


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES")}  # fmt: skip
    return {**env, **extra}


def _run(args: list[str], env: dict[str, str]) -> str:
    done = subprocess.run([sys.executable, *args], env=env, capture_output=True, text=True,
                          check=False, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def _twice(args: list[str]) -> tuple[str, str]:
    """``python args`` with numpy's dispatch for this CPU, then with every target numpy's build
    dispatches to turned off (``NPY_DISABLE_CPU_FEATURES``: numpy's baseline loops, which call
    the C library); their stdout. Checks that the second run's numpy did turn them off."""
    dispatch = json.loads(_run(["-c", _FEATURES], _env()))["dispatch"]
    baseline = _env(NPY_DISABLE_CPU_FEATURES=" ".join(dispatch))
    assert json.loads(_run(["-c", _FEATURES], baseline))["on"] == []
    return _run(args, _env()), _run(args, baseline)


def test_a_benchmark_stop_does_not_depend_on_numpys_cpu_dispatch(tmp_path):
    """The first sealed stop of the UIC-Z1 coach (soap, 158 km/h, -19.6 per mille), the one the
    classical WSP stopped 1.4 m apart on (1,571.5 against 1,570.1 m) when the creep stiffness's
    ``Q^(2/3)`` was numpy's ``power``; and the Régiolis's first, 16 axles."""
    for vehicle in ("uic_z1", "regiolis"):
        path = tmp_path / f"{vehicle}.json"
        code = (
            "import contextlib, io, sys; from pathlib import Path; from wsp_env.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    assert main(['benchmark', '--vehicle', '{vehicle}', '--policy', 'classical', "
            "'--tier', 'wheels+accel', '--runs', '1', '--no-progress', '--json', sys.argv[1]]) "
            "== 0\nprint(Path(sys.argv[1]).read_text())"
        )
        full, base = (json.loads(out)["run_results"] for out in _twice(["-c", code, str(path)]))
        assert {name: len(runs) for name, runs in full.items()} == {"classical": 1, "none": 1}
        assert full == base, vehicle


_GENERATOR = """
import hashlib, json, sys
import numpy as np
from wsp_env.calibration import independent as ind

def digest(parts):
    h = hashlib.sha256()
    for key in sorted(parts):
        value = parts[key]
        if isinstance(value, np.ndarray):
            h.update(key.encode()); h.update(str(value.dtype).encode())
            h.update(np.ascontiguousarray(value).tobytes())
    return h.hexdigest()

out = []
for seed, category, magnitude in json.loads(sys.argv[1]):
    rng = np.random.default_rng(seed)
    sc = ind.random_scenario(rng, adhesion_roughness=0.05)
    effects = [ind.random_effect(category, magnitude, rng, sc)]
    columns, meta = ind.generate(sc, effects, seed=seed)
    record = ind.simulate_record(sc, effects, seed=seed)
    out.append([repr(sc), digest(columns), json.dumps(meta, sort_keys=True), digest(record)])
print(json.dumps(out))
"""
# rough, recovering rails and the effects that reach the set-up's exp, pow and sin (pressure time
# constants, positions, per-axle factors), 4-16 axles: the scenario, every column, the metadata
# and every record array. With numpy's exp and pow the set-up's decays (31), the cleaning's powers
# of the axles (32, 34) and the sensor noise's draw (67) differed on an AVX-512 host.
_GENERATOR_CASES = [(31, "pressure_time_constant", 0.3), (32, "adhesion_position", 0.6),
                    (67, "adhesion_per_axle", 0.6), (34, "pressure_lag", 0.15)]  # fmt: skip


def test_an_independent_trace_does_not_depend_on_numpys_cpu_dispatch():
    """The independent generator (``calibration/independent.py``): its scenario draw, its
    set-up (rail roughness, cleaning powers, pressure decays) and its kernel."""
    full, base = _twice(["-c", _GENERATOR, json.dumps(_GENERATOR_CASES)])
    full, base = json.loads(full), json.loads(base)
    assert len(full) == len(_GENERATOR_CASES)
    for case, a, b in zip(_GENERATOR_CASES, full, base, strict=True):
        assert a == b, case
