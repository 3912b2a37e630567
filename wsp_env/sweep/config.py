"""A sweep file (``configs/sweeps/NAME.yaml``), checked before anything runs: a base training
config and either a grid or a search space over its fields (``docs/sweeps.md``).

Fields:

* ``train``: the base training config (a path or a built-in name, as ``wsp-env train
  --config``); a grid may vary it (``grid.train: [a, b]``: other algorithms, other settings).
* ``n_timesteps``: each trial's budget (default: the base config's).
* ``seeds``: the training seeds each grid point runs with (default ``[0]``); a search trains
  each sampled configuration with one seed (list one; run the best over seeds as a grid).
* ``report_every_timesteps``: a trial trains in chunks of this many steps (each ends with a
  checkpoint) and reports its learning curve after each (default: a tenth of the budget, but
  no shorter than the base's curve cadence and no longer than the budget).
* ``metric``: what ranks trials and prunes them: ``curve_score`` (default: the fixed-seed
  learning curve's last score, 0 locked wheels, 1 the classical WSP), ``curve_mean_return``,
  ``validation_passed``.
* ``resources``: ``cpus`` (default 1) and ``gpus`` (default 0) per trial.
* ``grid``: dotted paths into the training config (``learning_rate``,
  ``env_kwargs.accelerometer``, ``policy_kwargs.net_arch``) mapped to lists of values: every
  combination runs.
* ``search``: ``space`` (dotted path -> ``{type: uniform | loguniform | int | choice, low,
  high, values}``), ``trials`` (how many configurations Optuna samples), ``sampler``
  (``tpe`` or ``random``, seeded), ``pruner`` (``asha`` or ``none``: successive halving on
  the metric at each report), ``grace_reports`` (reports before a trial may be pruned).

Every combination of the grid (or the space's bounds) is applied to the training config and
checked by the training config's own parser, so a bad value is one line naming the sweep file
and its field.
"""

from __future__ import annotations

import copy
import itertools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wsp_env.core.config import ConfigError, read_yaml
from wsp_env.training.config import TrainConfig, load_train_config, parse_train_config

METRICS = ("curve_score", "curve_mean_return", "validation_passed")
SPACE_TYPES = ("uniform", "loguniform", "int", "choice")
SAMPLERS = ("tpe", "random")
PRUNERS = ("asha", "none")
TOP_FIELDS = ("train", "n_timesteps", "seeds", "report_every_timesteps", "metric", "resources",
              "grid", "search")  # fmt: skip


@dataclass(frozen=True)
class Param:
    """One searched field."""

    path: str
    type: str
    low: float | None = None
    high: float | None = None
    values: tuple[Any, ...] = ()


@dataclass(frozen=True)
class Search:
    space: tuple[Param, ...]
    trials: int
    sampler: str = "tpe"
    pruner: str = "asha"
    grace_reports: int = 1


@dataclass(frozen=True)
class SweepConfig:
    source: str
    train: str
    base: dict[str, Any]  # the base training config as its file holds it
    n_timesteps: int
    seeds: tuple[int, ...]
    report_every_timesteps: int
    metric: str = "curve_score"
    cpus: float = 1.0
    gpus: float = 0.0
    grid: dict[str, list[Any]] = field(default_factory=dict)
    search: Search | None = None

    def points(self) -> list[dict[str, Any]]:
        """The grid's combinations (one empty point without a grid), in file order."""
        if not self.grid:
            return [{}]
        keys = list(self.grid)
        return [dict(zip(keys, combo, strict=True))
                for combo in itertools.product(*(self.grid[k] for k in keys))]  # fmt: skip


def _fail(source: str, where: str, problem: str) -> ConfigError:
    return ConfigError(f"{source}: {where}: {problem}")


def apply_overrides(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """The training config's dict with each dotted path set (``train`` excluded: it picks the
    base itself)."""
    out = copy.deepcopy(base)
    for path, value in overrides.items():
        if path == "train":
            continue
        node = out
        parts = path.split(".")
        for part in parts[:-1]:
            child = node.get(part)
            if child is None:
                child = node[part] = {}
            if not isinstance(child, dict):
                raise ConfigError(f"{path}: {part} is not a mapping in the training config")
            node = child
        node[parts[-1]] = copy.deepcopy(value)
    return out


def training_dict(name: str) -> tuple[dict[str, Any], str]:
    """A training config's file content and path (through the training loader's lookup)."""
    cfg = load_train_config(name)  # checks it and resolves a built-in name to its file
    return dict(read_yaml(Path(cfg.source))), cfg.source


def trial_config(
    sweep: SweepConfig, overrides: dict[str, Any], seed: int, where: str = "grid"
) -> TrainConfig:
    """The training config of one trial, checked (a bad value: one line naming ``where``)."""
    base = sweep.base
    if "train" in overrides:
        try:
            base, _ = training_dict(str(overrides["train"]))
        except ConfigError as err:
            raise _fail(sweep.source, f"{where}.train", str(err)) from None
    data = apply_overrides(base, overrides)
    data["n_timesteps"] = sweep.n_timesteps
    data["seed"] = seed
    try:
        return parse_train_config(data, f"{sweep.source} ({where})")
    except ConfigError as err:
        raise _fail(sweep.source, where, str(err)) from None


def _check_curve(sweep: SweepConfig, cfg: TrainConfig, where: str) -> None:
    """A ``curve_*`` metric needs the learning curve on, at least once per report (else every
    report would repeat an old row, or 0)."""
    if not sweep.metric.startswith("curve_"):
        return
    every = cfg.eval.curve_every_timesteps
    if every == 0:
        raise _fail(sweep.source, "metric", f"{sweep.metric} needs the learning curve, but "
                    f"{where}'s eval.curve_every_timesteps is 0")  # fmt: skip
    if every > sweep.report_every_timesteps and sweep.report_every_timesteps < sweep.n_timesteps:
        raise _fail(sweep.source, "report_every_timesteps",
                    f"{sweep.report_every_timesteps} is shorter than {where}'s "
                    f"eval.curve_every_timesteps ({every}): reports would repeat old curve "
                    "rows")  # fmt: skip


def _int(value: Any, source: str, where: str, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise _fail(source, where, f"expected an integer >= {low}, got {value!r}")
    return value


def _number(value: Any, source: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(source, where, f"expected a number, got {value!r}")
    return float(value)


def _param(path: str, spec: Any, source: str) -> Param:
    where = f"search.space.{path}"
    if not isinstance(spec, dict):
        raise _fail(source, where, f"expected a mapping with type, got {spec!r}")
    kind = spec.get("type")
    if kind not in SPACE_TYPES:
        raise _fail(source, f"{where}.type", f"{kind!r} is not one of {', '.join(SPACE_TYPES)}")
    extra = set(spec) - ({"type", "values"} if kind == "choice" else {"type", "low", "high"})
    if extra:
        raise _fail(source, f"{where}.{sorted(extra)[0]}", f"unknown for type {kind}")
    if kind == "choice":
        values = spec.get("values")
        if not isinstance(values, list) or not values:
            raise _fail(source, f"{where}.values", "expected a non-empty list")
        return Param(path, kind, values=tuple(values))
    for key in ("low", "high"):
        if key not in spec:
            raise _fail(source, f"{where}.{key}", "missing")
    if kind == "int":
        low = _int(spec["low"], source, f"{where}.low", low=-(2**62))
        high = _int(spec["high"], source, f"{where}.high", low=-(2**62))
    else:
        low = _number(spec["low"], source, f"{where}.low")
        high = _number(spec["high"], source, f"{where}.high")
    if not low < high:
        raise _fail(source, f"{where}.high", f"must exceed low ({low}), got {high}")
    if kind == "loguniform" and low <= 0:
        raise _fail(source, f"{where}.low", f"must be > 0 for loguniform, got {low}")
    return Param(path, kind, float(low), float(high))


def load_sweep_config(path: str | Path) -> SweepConfig:
    """Read and check a sweep file (module docstring)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"{p}: no such sweep file")
    source = str(p)
    data = read_yaml(p)
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: (top level): expected a mapping")
    for key in data:
        if key not in TOP_FIELDS:
            raise _fail(source, str(key), f"unknown field (allowed: {', '.join(TOP_FIELDS)})")
    if "train" not in data:
        raise _fail(source, "train", "missing required field (the base training config)")
    try:
        base, _ = training_dict(str(data["train"]))
    except ConfigError as err:
        raise _fail(source, "train", str(err)) from None
    n_timesteps = _int(data.get("n_timesteps", base.get("n_timesteps")), source, "n_timesteps")
    seeds = data.get("seeds", [0])
    if not isinstance(seeds, list) or not seeds:
        raise _fail(source, "seeds", f"expected a non-empty list of integers, got {seeds!r}")
    seeds = tuple(_int(s, source, f"seeds[{i}]", low=0) for i, s in enumerate(seeds))
    if len(set(seeds)) < len(seeds):
        raise _fail(source, "seeds", "a seed is listed twice")
    # default: a tenth of the budget, but no shorter than the base's learning-curve cadence
    # (every report a fresh curve row) and no longer than the budget
    curve_every = int((base.get("eval") or {}).get("curve_every_timesteps", 250_000) or 0)
    default_report = min(n_timesteps, max(1, n_timesteps // 10, curve_every))
    report = _int(data.get("report_every_timesteps", default_report), source,
                  "report_every_timesteps")  # fmt: skip
    metric = data.get("metric", "curve_score")
    if metric not in METRICS:
        raise _fail(source, "metric", f"{metric!r} is not one of {', '.join(METRICS)}")
    res = data.get("resources", {}) or {}
    if not isinstance(res, dict):
        raise _fail(source, "resources", f"expected a mapping, got {res!r}")
    for key in res:
        if key not in ("cpus", "gpus"):
            raise _fail(source, f"resources.{key}", "unknown (allowed: cpus, gpus)")
    cpus = _number(res.get("cpus", 1), source, "resources.cpus")
    gpus = _number(res.get("gpus", 0), source, "resources.gpus")
    if cpus <= 0 or gpus < 0:
        raise _fail(source, "resources", f"cpus must be > 0 and gpus >= 0, got {cpus}, {gpus}")
    grid = data.get("grid") or {}
    search_data = data.get("search")
    if grid and search_data:
        raise _fail(source, "search", "a sweep is a grid or a search, not both")
    if not isinstance(grid, dict):
        raise _fail(source, "grid", f"expected a mapping of field -> list, got {grid!r}")
    for key, values in grid.items():
        if not isinstance(values, list) or not values:
            raise _fail(source, f"grid.{key}", f"expected a non-empty list, got {values!r}")
    search = None
    if search_data is not None:
        if not isinstance(search_data, dict):
            raise _fail(source, "search", f"expected a mapping, got {search_data!r}")
        for key in search_data:
            if key not in ("space", "trials", "sampler", "pruner", "grace_reports"):
                raise _fail(source, f"search.{key}", "unknown (allowed: space, trials, sampler, "
                            "pruner, grace_reports)")  # fmt: skip
        space = search_data.get("space")
        if not isinstance(space, dict) or not space:
            raise _fail(source, "search.space", "expected a non-empty mapping of field -> spec")
        sampler = search_data.get("sampler", "tpe")
        if sampler not in SAMPLERS:
            raise _fail(source, "search.sampler", f"{sampler!r} is not one of tpe, random")
        pruner = search_data.get("pruner", "asha")
        if pruner not in PRUNERS:
            raise _fail(source, "search.pruner", f"{pruner!r} is not one of asha, none")
        if len(seeds) > 1:
            raise _fail(source, "seeds", "a search trains each sampled configuration with one "
                        "seed (list one; run the best over seeds as a grid)")  # fmt: skip
        search = Search(
            tuple(_param(k, v, source) for k, v in space.items()),
            _int(search_data.get("trials"), source, "search.trials"),
            sampler,
            pruner,
            _int(search_data.get("grace_reports", 1), source, "search.grace_reports"),
        )
    sweep = SweepConfig(source, str(data["train"]), base, n_timesteps, seeds, report, metric,
                        cpus, gpus, dict(grid), search)  # fmt: skip
    # every trial's training config checked now, before anything runs
    for point in sweep.points():
        where = "grid" if grid else "train"
        if grid:
            where = "grid (" + ", ".join(f"{k}={v!r}" for k, v in point.items()) + ")"
        _check_curve(sweep, trial_config(sweep, point, seeds[0], where), where)
    if search is not None:
        for prm in search.space:
            probes = list(prm.values) if prm.type == "choice" else [prm.low, prm.high]
            for value in probes:
                if prm.type == "int":
                    value = int(value)
                where = f"search.space.{prm.path}"
                _check_curve(sweep, trial_config(sweep, {prm.path: value}, seeds[0], where), where)
    return sweep


__all__ = [
    "METRICS",
    "Param",
    "Search",
    "SweepConfig",
    "apply_overrides",
    "load_sweep_config",
    "trial_config",
]
