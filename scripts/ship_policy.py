"""Ship a trained policy: copy a run's best model into `agents/pretrained/` with everything a
user needs to trust and reproduce it.

    .venv/bin/python scripts/ship_policy.py runs/train/ppo_residual_uic_z1 \
        --name ppo_residual_uic_z1 [--model best_model]

``--model student``: the run's imitation warm start (``student.zip``, written before PPO's
first update), its figures those of the warm start alone.

Writes `agents/pretrained/NAME.zip` (the model, its metadata renamed NAME),
`NAME.vecnormalize.pkl` (its observation normalisation), `NAME.yaml` (the run's exact config,
with the command that trained it), `NAME.json` (timesteps, wall time, throughput, machine, the
validation history's best row and the classical WSP's) and `NAME_learning_curve.png`
(training episodes' mean stop per rail and the validation suite's mean stop against the
classical WSP's, over timesteps). The run folder is read, never changed.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import shutil
from pathlib import Path
from typing import Any

import yaml

from wsp_env.policy import model_metadata, pretrained_dir, write_model_metadata

ROOT = Path(__file__).resolve().parents[1]


def imitation_panel(ax: Any, pre: dict[str, Any], title: str) -> None:
    """The imitation warm start's DAgger rounds (``pretrain.json``): the actor's error on the
    data set, and its distance to the teacher where the student drove."""
    rounds = pre["rounds"]
    ax.plot([r["round"] for r in rounds], [r["actor_mse"] for r in rounds], "o-", ms=3,
            label="actor MSE on the data set")  # fmt: skip
    drove = [(r["round"], r["student_vs_teacher_mae"]) for r in rounds
             if r["student_vs_teacher_mae"] is not None]  # fmt: skip
    ax.plot(*zip(*drove, strict=True), "s-", ms=3, label="|student - teacher|, student drives")
    ax.set(xlabel="DAgger round", ylabel="action error", title=title)
    ax.legend(fontsize=8)


def learning_curve(run: Path, out_png: Path, title: str, student: bool = False) -> None:
    """The run's curves; ``student``: the imitation warm start's alone (its DAgger rounds and
    its validation beside the classical WSP's), the reinforcement learning after it not being
    part of what ships."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(csv.DictReader((run / "progress.csv").open()))
    validation = json.loads((run / "validation.json").read_text())
    pre_path = run / "pretrain.json"
    if student:
        pre = json.loads(pre_path.read_text())
        fig, (ax0, ax2) = plt.subplots(1, 2, figsize=(11, 4))
        steps = pre["env_steps"] / 1e6
        imitation_panel(ax0, pre, f"imitation of {pre['teacher']} ({steps:.1f} M steps)")
        v, c = pre["validation"], validation["classical"]
        keys = (("mean stop [m]", "mean_stopping_distance_m"),
                ("sliding energy [kJ]", "mean_sliding_energy_kJ"),
                ("air [l]", "mean_air_litres"))  # fmt: skip
        x = range(len(keys))
        ax2.bar([i - 0.2 for i in x], [c[k] for _, k in keys], 0.4, label="classical WSP")
        ax2.bar([i + 0.2 for i in x], [v[k] for _, k in keys], 0.4, label="student")
        ax2.set_xticks(list(x), [label for label, _ in keys])
        ax2.set(title=f"validation ({c['runs']} runs): passed {v['passed']} against "
                      f"{c['passed']}")  # fmt: skip
        ax2.legend(fontsize=8)
        fig.suptitle(title)
        fig.tight_layout()
        fig.savefig(out_png, dpi=90)
        plt.close(fig)
        return
    if pre_path.exists():  # the imitation warm start: its rounds first
        fig, (ax0, ax1, ax2) = plt.subplots(1, 3, figsize=(16, 4))
        imitation_panel(ax0, json.loads(pre_path.read_text()), "imitation warm start")
    else:
        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
    steps = [float(r["time/total_timesteps"]) / 1e6 for r in rows]
    for key in sorted(k for k in rows[0] if k.startswith("episode_by_rail/")):
        pts = [(s, float(r[key])) for s, r in zip(steps, rows, strict=True) if r.get(key)]
        if pts:
            ax1.plot(*zip(*pts, strict=True), lw=0.8, label=key.split("/")[1].split("_")[0])
    ax1.set(
        xlabel="timesteps [M]",
        ylabel="training episodes' mean stop [m]",
        title="training (random scenarios, stochastic policy)",
    )
    ax1.legend(fontsize=8)
    hist = validation["history"]
    x = [h["timesteps"] / 1e6 for h in hist]
    ax2.plot(x, [h["mean_stopping_distance_m"] for h in hist], "o-", ms=3, label="policy")
    ax2.axhline(
        validation["classical"]["mean_stopping_distance_m"],
        color="k",
        ls="--",
        label="classical WSP",
    )
    best = validation["best"]
    ax2.plot(
        best["timesteps"] / 1e6,
        best["mean_stopping_distance_m"],
        "r*",
        ms=12,
        label=f"shipped ({best['timesteps'] / 1e6:.0f} M)",
    )
    ax2.set(
        xlabel="timesteps [M]",
        ylabel="mean stop [m]",
        title=f"validation suite ({validation['classical']['runs']} runs, deterministic)",
    )
    ax2.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out_png, dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", help="a run folder of `wsp-env train`")
    ap.add_argument("--name", required=True, help="the shipped policy's name")
    ap.add_argument("--model", default="best_model", help="model stem in the run (best_model)")
    ap.add_argument(
        "--trained-by", action="append", default=None,
        help="the commands that trained the run, as run (default: the plain one)",
    )  # fmt: skip
    ap.add_argument("--out-dir", type=Path, default=None,
                    help="where to write (default: agents/pretrained)")  # fmt: skip
    args = ap.parse_args(argv)
    run = Path(args.run)
    out = args.out_dir or pretrained_dir()
    if args.model == "student" and not (run / "pretrain.json").exists():
        raise SystemExit(f"{run}: no pretrain.json: no imitation warm start to ship")
    out.mkdir(parents=True, exist_ok=True)
    name = args.name
    src = run / f"{args.model}.zip"
    meta = dict(model_metadata(src))  # its own entry, else the run's config.yaml
    meta["name"] = name
    shutil.copy(src, out / f"{name}.zip")
    write_model_metadata(out / f"{name}.zip", meta)
    shutil.copy(run / f"{args.model}.vecnormalize.pkl", out / f"{name}.vecnormalize.pkl")
    config = yaml.safe_load((run / "config.yaml").read_text())
    train = json.loads((run / "train.json").read_text())
    validation = json.loads((run / "validation.json").read_text())
    rel = os.path.relpath(run, ROOT)
    trained_by = args.trained_by or [
        f".venv/bin/wsp-env train --config configs/train/{name}.yaml --out {rel}"
    ]
    header = (
        f"# The exact config of the shipped policy {name} (copied from {rel}/config.yaml).\n"
        "# Trained by:\n"
        + "".join(f"#   {c}\n" for c in trained_by)
        + f"# shipped by:\n#   .venv/bin/python scripts/ship_policy.py {rel} --name {name} "
        f"--model {args.model}\n"
    )
    info_trained_by = trained_by
    (out / f"{name}.yaml").write_text(header + yaml.safe_dump(config, sort_keys=False))
    rows = list(csv.DictReader((run / "progress.csv").open()))
    info = {
        "name": name,
        "model": f"{rel}/{args.model}.zip",
        "algo": train["algo"],
        "trained_by": info_trained_by,
        "timesteps_trained": train["total_timesteps"],
        "shipped_at_timesteps": validation["best"]["timesteps"],
        "wall_time_s": None,  # below: warm start + every call's reinforcement learning
        "resumed_from": train.get("resumed_from"),
        # SB3's own figure over the reinforcement-learning part (the updates included)
        "env_steps_per_s": float(rows[-1]["time/fps"]) if rows else train["env_steps_per_s"],
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.system()}, no GPU",
        "best_validation": validation["best"],
        "classical_validation": validation["classical"],
    }
    calls = sorted((run / "logs").glob("from_step_*/progress.csv"))
    rl_wall = 0.0
    for f in calls:
        last = list(csv.DictReader(f.open()))
        rl_wall += float(last[-1]["time/time_elapsed"]) if last else 0.0
    info["wall_time_s"] = rl_wall
    info["wall_time_note"] = (
        "reinforcement learning: SB3's time_elapsed summed over the run's calls (validations "
        "included); plus the imitation warm start where there is one"
    )
    if (run / "pretrain.json").exists():
        pre = json.loads((run / "pretrain.json").read_text())
        # older runs did not time the warm start: the files' times bound it
        wall = pre.get("wall_time_s") or (
            (run / "pretrain.json").stat().st_mtime - (run / "config.yaml").stat().st_mtime
        )
        info["pretrain"] = {"teacher": pre["teacher"], "env_steps": pre["env_steps"],
                            "rounds": len(pre["rounds"]), "wall_time_s": wall,
                            "validation": pre["validation"]}  # fmt: skip
        info["wall_time_s"] += wall
        if args.model == "student":  # the warm start itself: no RL step made these weights
            info["timesteps_trained"] = 0
            info["shipped_at_timesteps"] = 0
            info["best_validation"] = pre["validation"]  # the warm start's own, not RL's best
            info["wall_time_s"] = wall
            info["env_steps_per_s"] = pre["env_steps"] / wall
            info["wall_time_note"] = (
                "the imitation warm start alone (the student is the policy it wrote before any "
                "reinforcement-learning update); env_steps_per_s: its environment steps (teacher "
                "and student driving) over its wall time"
            )
    (out / f"{name}.json").write_text(json.dumps(info, indent=1) + "\n")
    student = args.model == "student"
    kind = "imitation student" if student else train["algo"]
    learning_curve(run, out / f"{name}_learning_curve.png", f"{name} ({kind})", student)
    for p in sorted(out.glob(f"{name}*")):
        print(f"wrote {p} ({p.stat().st_size / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
