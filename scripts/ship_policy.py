"""Ship a trained policy: copy a run's best model into `agents/pretrained/` with everything a
user needs to trust and reproduce it.

    .venv/bin/python scripts/ship_policy.py runs/train/ppo_residual_uic_z1 \
        --name ppo_residual_uic_z1 [--model best_model]

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

import yaml

from wsp_env.policy import model_metadata, pretrained_dir, write_model_metadata

ROOT = Path(__file__).resolve().parents[1]


def learning_curve(run: Path, out_png: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = list(csv.DictReader((run / "progress.csv").open()))
    validation = json.loads((run / "validation.json").read_text())
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", help="a run folder of `wsp-env train`")
    ap.add_argument("--name", required=True, help="the shipped policy's name")
    ap.add_argument("--model", default="best_model", help="model stem in the run (best_model)")
    args = ap.parse_args()
    run = Path(args.run)
    out = pretrained_dir()
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
    header = (
        f"# The exact config of the shipped policy {name} (copied from {rel}/config.yaml).\n"
        f"# Trained by:\n#   .venv/bin/wsp-env train --config configs/train/{name}.yaml "
        f"--out {rel}\n# shipped by:\n#   .venv/bin/python scripts/ship_policy.py {rel} "
        f"--name {name} --model {args.model}\n"
    )
    (out / f"{name}.yaml").write_text(header + yaml.safe_dump(config, sort_keys=False))
    info = {
        "name": name,
        "model": f"{rel}/{args.model}.zip",
        "algo": train["algo"],
        "timesteps_trained": train["total_timesteps"],
        "shipped_at_timesteps": validation["best"]["timesteps"],
        "wall_time_s": train["wall_time_s"],
        "wall_time_note": "of the last `wsp-env train` call (the whole run when not resumed)",
        "resumed_from": train.get("resumed_from"),
        "env_steps_per_s": train["env_steps_per_s"],
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.system()}, no GPU",
        "best_validation": validation["best"],
        "classical_validation": validation["classical"],
    }
    (out / f"{name}.json").write_text(json.dumps(info, indent=1) + "\n")
    learning_curve(run, out / f"{name}_learning_curve.png", f"{name} ({train['algo']})")
    for p in sorted(out.glob(f"{name}*")):
        print(f"wrote {p.relative_to(ROOT)} ({p.stat().st_size / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
