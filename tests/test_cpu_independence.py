"""A result depends on its seed and the C library, not on the CPU it was computed on.

numpy's transcendental ufuncs (``exp``, ``log``, ``power``, ``arccos``, ``cbrt``, ...) use numpy's
own vector routines where the CPU has them (AVX-512: numpy 2.4's ``X86_V4`` dispatch), and those
differ from the C library's in the last bit on a few per cent of arguments. A last bit in one
axle's creep stiffness moved a sealed stop of the classical WSP by 1.4 m, and one of the
independent generator's frozen records (``test_independent_traces.py``) failed on such a machine.
So the set-up calls the C library (``wsp_env.physics.libm``; the generator through ``math`` and
its own kernel), as the compiled kernels do.

Each test runs the same thing in two subprocesses: with numpy's dispatch for this CPU, and with
numpy held at its baseline (``NPY_DISABLE_CPU_FEATURES``: there numpy calls the C library), and
asks for the same bits. On a CPU without the vector routines both runs are the same by
construction, and the test cannot fail there: it checks on the machines where it matters (an
AVX-512 CI machine or laptop). Learned policies are left out: torch's kernels depend on the CPU.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

BASELINE = "X86_V3 X86_V4"  # AVX2 and AVX-512 dispatch off: numpy's baseline loops only


def _twice(args: list[str]) -> tuple[str, str]:
    """``python args`` with numpy's full dispatch, then at its baseline; their stdout."""
    env = {k: v for k, v in os.environ.items() if k != "NPY_DISABLE_CPU_FEATURES"}
    out = []
    for extra in ({}, {"NPY_DISABLE_CPU_FEATURES": BASELINE}):
        done = subprocess.run([sys.executable, *args], env={**env, **extra},
                              capture_output=True, text=True, check=False, timeout=600)  # fmt: skip
        assert done.returncode == 0, done.stderr[-3000:]
        out.append(done.stdout)
    return out[0], out[1]


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
# and every record array
_GENERATOR_CASES = [(31, "pressure_time_constant", 0.3), (32, "adhesion_position", 0.6),
                    (33, "adhesion_per_axle", 0.6), (34, "pressure_lag", 0.15)]  # fmt: skip


def test_an_independent_trace_does_not_depend_on_numpys_cpu_dispatch():
    """The independent generator (``calibration/independent.py``): its scenario draw, its
    set-up (rail roughness, cleaning powers, pressure decays) and its kernel."""
    full, base = _twice(["-c", _GENERATOR, json.dumps(_GENERATOR_CASES)])
    full, base = json.loads(full), json.loads(base)
    assert len(full) == len(_GENERATOR_CASES)
    for case, a, b in zip(_GENERATOR_CASES, full, base, strict=True):
        assert a == b, case
