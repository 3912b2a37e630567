"""``wsp-env sweep``: many ``wsp-env train`` runs as one job on Ray Tune — a grid over configs,
options and seeds, or an Optuna search with successive-halving pruning on the fixed-seed
learning curve — locally by default, on a cluster with ``--address`` and no other change
(``docs/sweeps.md``).

**A trial** is one training run in its own folder, ``DIR/trials/<trial>/`` (the run folder of
``wsp-env train``: checkpoints, ``validation.json``, ``curve.json``, logs). It trains in chunks
of ``report_every_timesteps`` (``train(..., chunk_timesteps=...)``, each ending with a
checkpoint) and after each reports the learning curve's last row and the best validation to
Tune, which may stop it there (pruning). A trial started again (a resumed sweep, a worker lost)
resumes from its folder's last checkpoint; a trial whose run finished is not trained again.
Its training threads follow the thread policy for the CPUs it declares (``WSP_CORES``).

**The sweep folder** ``DIR``: ``tune/`` (Tune's experiment state, what ``--resume`` restores:
finished trials stay finished, unfinished ones resume, a search's sampler keeps its history),
``trials/``, and at the end, each written whole or not at all: ``results.json`` (every trial:
overrides, seed, metric, validation, timesteps, wall time, status; the grid summarised over
seeds), ``results.md`` (the same as tables) and ``best.yaml`` (the best trial's training
config, ready for ``wsp-env train --config``).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import statistics
import time
from pathlib import Path
from typing import Any

import yaml

from wsp_env.core.config import ConfigError
from wsp_env.evaluation.distributed import ray_session
from wsp_env.files import write_atomically, write_json
from wsp_env.sweep.config import SweepConfig, load_sweep_config, trial_config
from wsp_env.threads import ENV_CORES
from wsp_env.training.train import latest_checkpoint, train

STATE = "tune"
TRIALS = "trials"
SWEEP_FILE = "sweep.yaml"  # the sweep file as it was run (``--resume`` reads it)
TRIAL_STATE = "sweep_trial.json"  # a trial's own record: wall time over its calls, reports


def _trial_metrics(folder: Path, metric: str) -> dict[str, Any]:
    """What a trial reports, read from its run folder (``curve.json``, ``validation.json``)."""
    out: dict[str, Any] = {"curve_score": None, "curve_mean_return": None,
                           "validation_passed": None, "validation_runs": None,
                           "validation_mean_stop_m": None, "stop_vs_classical": None}  # fmt: skip
    curve = folder / "curve.json"
    if curve.exists():
        rows = json.loads(curve.read_text())["history"]
        if rows:
            out["curve_score"] = rows[-1]["score"]
            out["curve_mean_return"] = rows[-1]["mean_return"]
            out["stop_vs_classical"] = rows[-1]["stop_vs_classical"]
    val = folder / "validation.json"
    if val.exists():
        best = json.loads(val.read_text()).get("best")
        if best:
            out["validation_passed"] = best["passed"]
            out["validation_runs"] = best["runs"]
            out["validation_mean_stop_m"] = best["mean_stopping_distance_m"]
    value = out[metric]
    # Tune needs a number at every report: no scored stop yet counts as locked wheels (0)
    out["metric"] = float(value) if value is not None else 0.0
    return out


def run_trial(config: dict[str, Any]) -> None:
    """Tune's trainable (runs in a Ray worker): train in chunks, report after each."""
    from ray import tune

    # Tune starts a trial in its own folder: relative paths (the sweep's, the training
    # config's suite or rails table) mean what they meant where the sweep was started
    os.chdir(config["cwd"])
    os.environ[ENV_CORES] = str(max(1, int(config["cpus"])))
    folder = Path(config["sweep_dir"]) / TRIALS / tune.get_context().get_trial_id()
    sweep = load_sweep_config(Path(config["sweep_dir"]) / SWEEP_FILE)
    cfg = trial_config(sweep, config["overrides"], int(config["seed"]))
    record_path = folder / TRIAL_STATE
    record = json.loads(record_path.read_text()) if record_path.exists() else {"wall_time_s": 0.0}
    if latest_checkpoint(folder) is None and folder.exists():
        shutil.rmtree(folder)  # killed before its first checkpoint: start it again
    while True:
        done = folder / "train.json"
        if done.exists() and json.loads(done.read_text()).get("finished"):
            result = json.loads(done.read_text())
        else:
            t0 = time.perf_counter()
            resume = folder if latest_checkpoint(folder) is not None else None
            result = train(
                None if resume else cfg, folder, resume=resume, progress=False,
                chunk_timesteps=sweep.report_every_timesteps,
            )  # fmt: skip
            record["wall_time_s"] += time.perf_counter() - t0
            write_json(record_path, record)
        metrics = _trial_metrics(folder, sweep.metric)
        metrics.update(timesteps=int(result["total_timesteps"]),
                       wall_time_s=record["wall_time_s"])  # fmt: skip
        tune.report(metrics)
        if result.get("finished"):
            return


def _param_space(sweep: SweepConfig, sweep_dir: Path) -> dict[str, Any]:
    from ray import tune

    common = {"sweep_dir": str(sweep_dir), "cpus": sweep.cpus, "cwd": os.getcwd()}
    if sweep.search is None:
        points = [{"overrides": p, "seed": s} for p in sweep.points() for s in sweep.seeds]
        return {**common, "trial": tune.grid_search(points)}
    space: dict[str, Any] = {}
    for prm in sweep.search.space:
        space[prm.path] = {
            "uniform": lambda p: tune.uniform(p.low, p.high),
            "loguniform": lambda p: tune.loguniform(p.low, p.high),
            "int": lambda p: tune.randint(int(p.low), int(p.high) + 1),
            "choice": lambda p: tune.choice(list(p.values)),
        }[prm.type](prm)
    return {**common, "search": space, "seed": sweep.seeds[0]}


def _trainable(config: dict[str, Any]) -> None:
    """The trial's config as Tune lays it out -> ``run_trial``'s."""
    if "trial" in config:
        overrides, seed = config["trial"]["overrides"], config["trial"]["seed"]
    else:
        overrides, seed = dict(config["search"]), config["seed"]
    run_trial({"sweep_dir": config["sweep_dir"], "cpus": config["cpus"], "cwd": config["cwd"],
               "overrides": overrides, "seed": seed})  # fmt: skip


def _tuner(sweep: SweepConfig, sweep_dir: Path, restore: bool) -> Any:
    from ray import tune

    trainable = tune.with_resources(_trainable, {"cpu": sweep.cpus, "gpu": sweep.gpus})
    state = str((sweep_dir / STATE).resolve())
    if restore:
        return tune.Tuner.restore(state, trainable, resume_unfinished=True, resume_errored=True)
    search_alg, scheduler, num_samples = None, None, 1
    if sweep.search is not None:
        import optuna
        from ray.tune.schedulers import ASHAScheduler

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        from ray.tune.search.optuna import OptunaSearch

        seed = sweep.seeds[0]
        sampler = (optuna.samplers.TPESampler(seed=seed) if sweep.search.sampler == "tpe"
                   else optuna.samplers.RandomSampler(seed=seed))  # fmt: skip
        search_alg = OptunaSearch(sampler=sampler, metric="metric", mode="max")
        num_samples = sweep.search.trials
        if sweep.search.pruner == "asha":
            scheduler = ASHAScheduler(
                time_attr="timesteps", metric="metric", mode="max", max_t=sweep.n_timesteps,
                grace_period=sweep.search.grace_reports * sweep.report_every_timesteps,
                reduction_factor=3,
            )  # fmt: skip
    return tune.Tuner(
        trainable,
        param_space=_param_space(sweep, sweep_dir),
        tune_config=tune.TuneConfig(
            search_alg=search_alg, scheduler=scheduler, num_samples=num_samples, reuse_actors=False
        ),
        run_config=tune.RunConfig(name=STATE, storage_path=str(sweep_dir.resolve()), verbose=0),
    )


def _interval(values: list[float]) -> list[float] | None:
    """95 % t-interval of the mean (None with fewer than 2 values)."""
    if len(values) < 2:
        return None
    from scipy import stats

    m, s = statistics.fmean(values), statistics.stdev(values)
    h = float(stats.t.ppf(0.975, len(values) - 1)) * s / math.sqrt(len(values))
    return [m - h, m + h]


def collect(sweep: SweepConfig, sweep_dir: Path, grid: Any = None) -> dict[str, Any]:
    """Every trial's row (from the run folders and Tune's results) and the summary over seeds."""
    rows = []
    for res in grid or []:
        cfg = res.config
        if "trial" in cfg:
            overrides, seed = cfg["trial"]["overrides"], cfg["trial"]["seed"]
        else:
            overrides, seed = dict(cfg["search"]), cfg["seed"]
        metrics = res.metrics or {}
        # Tune adds the id to every report; a trial that failed before its first has none
        trial_id = metrics.get("trial_id") or "?"
        folder = sweep_dir / TRIALS / str(trial_id)  # "?": no folder of its own is known
        done = folder / "train.json"
        finished = done.exists() and json.loads(done.read_text()).get("finished", False)
        row = {
            "trial": str(trial_id),
            "overrides": overrides,
            "seed": int(seed),
            **{k: v for k, v in _trial_metrics(folder, sweep.metric).items() if k != "metric"},
            "metric": metrics.get("metric"),
            "timesteps": metrics.get("timesteps"),
            "wall_time_s": metrics.get("wall_time_s"),
            "status": "error" if res.error else ("finished" if finished else "stopped"),
            "folder": str(folder),
        }
        rows.append(row)
    rows.sort(key=lambda r: (json.dumps(r["overrides"], sort_keys=True), r["seed"], r["trial"]))
    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(json.dumps(r["overrides"], sort_keys=True), []).append(r)
    summary = []
    for key, members in groups.items():
        vals = [float(r["metric"]) for r in members if r["metric"] is not None]
        summary.append({
            "overrides": json.loads(key),
            "seeds": [r["seed"] for r in members],
            "metric_mean": statistics.fmean(vals) if vals else None,
            "metric_ci95": _interval(vals),
            "wall_time_s": sum(float(r["wall_time_s"] or 0.0) for r in members),
        })  # fmt: skip
    # the best: a trial that ran its whole budget, before any stopped (pruned) at a smaller one
    ranked = [r for r in rows if r["metric"] is not None and r["status"] != "error"]
    best = (max(ranked, key=lambda r: (r["status"] == "finished", r["metric"]))
            if ranked else None)  # fmt: skip
    return {"sweep": sweep.source, "metric": sweep.metric, "trials": rows, "summary": summary,
            "best": best}  # fmt: skip


def _fmt(v: Any, spec: str = ".3f") -> str:
    return "-" if v is None else format(v, spec) if isinstance(v, float) else str(v)


def results_markdown(payload: dict[str, Any]) -> str:
    lines = [f"# Sweep `{payload['sweep']}`", "", f"Metric: `{payload['metric']}` (higher is "
             "better; `curve_score`: 0 locked wheels, 1 the classical WSP, on the fixed-seed "
             "learning curve's stops).", "",
             "| trial | overrides | seed | metric | validation passed | timesteps | wall s | "
             "status |", "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in payload["trials"]:
        passed = (f"{r['validation_passed']}/{r['validation_runs']}"
                  if r["validation_passed"] is not None else "-")  # fmt: skip
        lines.append(f"| {r['trial']} | `{json.dumps(r['overrides'])}` | {r['seed']} | "
                     f"{_fmt(r['metric'])} | {passed} | {_fmt(r['timesteps'])} | "
                     f"{_fmt(r['wall_time_s'], '.0f')} | {r['status']} |")  # fmt: skip
    lines += ["", "Over seeds (mean, 95 % t-interval):", "",
              "| overrides | seeds | mean | 95 % interval | wall s (all seeds) |",
              "|---|---|---|---|---|"]  # fmt: skip
    for s in payload["summary"]:
        ci = s["metric_ci95"]
        ci_text = "-" if ci is None else f"{ci[0]:.3f}-{ci[1]:.3f}"
        over = json.dumps(s["overrides"])
        lines.append(f"| `{over}` | {len(s['seeds'])} | {_fmt(s['metric_mean'])} | {ci_text} | "
                     f"{s['wall_time_s']:.0f} |")  # fmt: skip
    return "\n".join(lines) + "\n"


def run_sweep(
    config: str | Path | None, out: str | Path, address: str | None = None, resume: bool = False
) -> dict[str, Any]:
    """Run (or ``resume``) a sweep into ``out`` (module docstring); returns ``results.json``."""
    sweep_dir = Path(out).resolve()  # the trials find it from their own folders
    if resume:
        if not (sweep_dir / SWEEP_FILE).exists() or not (sweep_dir / STATE).is_dir():
            raise ConfigError(f"{sweep_dir}: no sweep to resume (no {SWEEP_FILE} and {STATE}/)")
        if config is not None:
            raise ConfigError("--config: a resumed sweep runs its own sweep.yaml")
        sweep = load_sweep_config(sweep_dir / SWEEP_FILE)
    else:
        if config is None:
            raise ConfigError("--config: required unless --resume")
        sweep = load_sweep_config(config)
        if sweep_dir.exists() and (not sweep_dir.is_dir() or any(sweep_dir.iterdir())):
            raise ConfigError(f"{sweep_dir}: exists and is not empty (use --resume to continue)")
    from wsp_env.threads import available_cores

    started = time.perf_counter()
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")  # Tune's quiet reporter: verbose=0 holds
    with ray_session(address, None if address else available_cores()) as ray:
        have = ray.cluster_resources()
        for key, want, name in (("CPU", sweep.cpus, "cpus"), ("GPU", sweep.gpus, "gpus")):
            if want > float(have.get(key, 0.0)):
                where = f"the cluster at {address}" if address else "this machine"
                raise ConfigError(
                    f"{sweep.source}: resources.{name}: {want:g} per trial, but {where} has "
                    f"{float(have.get(key, 0.0)):g} (no trial could start)"
                )
        if not resume:
            sweep_dir.mkdir(parents=True, exist_ok=True)
            (sweep_dir / TRIALS).mkdir(exist_ok=True)
            write_atomically(
                sweep_dir / SWEEP_FILE,
                lambda fh: fh.write(Path(sweep.source).read_text()),
            )
        tuner = _tuner(sweep, sweep_dir, restore=resume)
        grid = tuner.fit()
    payload = collect(sweep, sweep_dir, grid)
    payload["wall_time_s"] = time.perf_counter() - started
    payload["address"] = address
    write_json(sweep_dir / "results.json", payload)
    write_atomically(sweep_dir / "results.md", lambda fh: fh.write(results_markdown(payload)))
    best = payload["best"]
    if best is not None:
        cfg = trial_config(sweep, best["overrides"], best["seed"], "best")
        head = (f"# best trial of sweep {sweep.source}: {best['trial']} ({sweep.metric} "
                f"{best['metric']:.4f})\n")  # fmt: skip
        text = head + yaml.safe_dump(cfg.as_yaml_dict(), sort_keys=False)
        write_atomically(sweep_dir / "best.yaml", lambda fh: fh.write(text))
        payload["best_config"] = str(sweep_dir / "best.yaml")
    return payload


__all__ = ["collect", "results_markdown", "run_sweep", "run_trial"]
