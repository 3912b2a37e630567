"""The compiled step's argument order has one source of truth, ``env_step_one``'s signature:
``kernel.step_args`` (what the core passes) and ``ARG_ENV_PAR`` must follow it."""

from __future__ import annotations

import inspect

from wsp_env.core import kernel as K
from wsp_env.envs import make_core


def test_step_args_follow_the_kernel_signature() -> None:
    core = make_core(2)
    sim = core.sim
    args = K.step_args(sim.n_sub, sim.dt_s, sim.control_period_s, core.params, core.state)
    names = list(inspect.signature(K.env_step_one.py_func).parameters)
    assert names[:3] == ["e", "mode", "actions"]
    rest = names[3:]
    assert len(args) == len(rest)
    scalars = {"n_sub": sim.n_sub, "dt": sim.dt_s, "ctrl_dt": sim.control_period_s}
    for name, value in zip(rest, args, strict=True):
        if name in scalars:
            assert value == scalars[name], name
        else:
            bundle = core.params if name in K.Params._fields else core.state
            assert getattr(bundle, name) is value, name
    # the entry points' arguments are env_step_one's after ``e``
    assert names[K.ARG_ENV_PAR + 1] == "env_par"
