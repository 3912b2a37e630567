"""Export a trained policy to ONNX for an embedded WSP (``wsp-env export-policy``).

The exported graph is the deterministic actor with the observation normalisation folded in:

    input  ``obs``    float32 ``(batch, frame_stack * obs_dim)``: the raw observations of
                      ``WSPBraking-v0`` (as the environment returns them), oldest frame first;
    output ``action`` float32 ``(batch, n_valves)``: ``clip(mu(normalise(obs)), -1, 1)``.

Normalisation is VecNormalize's: ``clip((x - mean) / sqrt(var + eps), -clip_obs, clip_obs)``
per frame. At an episode's start, before ``frame_stack`` observations exist, VecFrameStack feeds
zeros *after* normalisation; feed ``frame_fill`` there (stored in the ONNX metadata, the
normalisation's mean, which the graph maps to exactly those zeros). With
``action_mode="residual"`` the output is the residual the environment adds to the classical
WSP's request (``env.py``): the embedded WSP runs the classical logic beside the network; with
``action_mode="slip_target"`` it is each valve's target slip (the environment's mapping), and
the embedded WSP runs the slip-target inner loop (``baselines.slip_target``) beside it; with
``memory_features`` the embedded WSP computes those inputs as the environment does
(``BrakingCore.memory_obs``), with ``memory_target_mean`` the stop's mean slip-target action
(``BrakingCore.target_mean_obs``).

The ONNX metadata carries what rebuilding the inputs and using the output takes:
``env_kwargs`` (the model's environment settings, ``action_repeat`` included) and ``inputs``
(``input_spec``: the settings as the environment resolves them, defaults filled in — the
decision period, the observation's layout and scales, the memory features' scales and
definitions' constants, the vehicle's brake constants the energy estimate uses, the residual's
or the slip-target loop's settings with the classical WSP thresholds of the sensor tier they
run on).

Supported: PPO and A2C with a continuous (Box) action space and MLP features. SAC/TD3/TQC
actors, discrete valve modes and recurrent policies are refused with one line.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from wsp_env.policy import SB3Policy


def _actor_module(policy: SB3Policy) -> Any:
    import torch
    from gymnasium import spaces
    from stable_baselines3.common.policies import ActorCriticPolicy

    sb3_policy = policy.model.policy
    if not isinstance(sb3_policy, ActorCriticPolicy) or policy.recurrent:
        raise ValueError(
            f"policy {policy.name}: export supports PPO / A2C MLP policies, not "
            f"{type(sb3_policy).__name__}"
        )
    if not isinstance(policy.model.action_space, spaces.Box):
        raise ValueError(f"policy {policy.name}: export supports continuous (Box) actions only")
    dim = int(np.prod(policy.model.observation_space.shape))
    n_stack = policy.n_stack
    norm = policy.normalisation()
    if norm is not None:
        mean, scale, clip = np.tile(norm[0], n_stack), np.tile(norm[1], n_stack), norm[2]
    else:
        mean, scale, clip = np.zeros(dim), np.ones(dim), np.inf

    class Actor(torch.nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.policy = sb3_policy
            self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
            self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))
            self.clip = float(min(clip, 1e30))

        def forward(self, obs: Any) -> Any:
            x = torch.clamp((obs - self.mean) / self.scale, -self.clip, self.clip)
            features = self.policy.extract_features(x, self.policy.pi_features_extractor)
            latent = self.policy.mlp_extractor.forward_actor(features)
            return torch.clamp(self.policy.action_net(latent), -1.0, 1.0)

    return Actor().eval(), dim, mean


def export_onnx(model_path: str | Path, out_path: str | Path) -> dict[str, Any]:
    """Write ``out_path`` (ONNX); return what was written and the measured per-decision
    latency of ONNX Runtime on this machine (one observation, median of 2,000 calls)."""
    from wsp_env.policy import make_policy, require_extras

    # torch and SB3 load the model, onnx writes the graph, onnxruntime times it
    require_extras(f"{model_path}: ONNX export needs", "rl", "export")
    import torch

    policy = make_policy(str(model_path))  # a model file or a shipped policy's name
    if not isinstance(policy, SB3Policy):
        raise ValueError(
            f"{model_path}: not a trained model (classical, none and oracle are rules)"
        )
    actor, dim, frame_fill = _actor_module(policy)
    out = Path(out_path)
    if out.suffix != ".onnx":
        raise ValueError(f"--onnx: {out} should end in .onnx")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    dummy = torch.zeros(1, dim, dtype=torch.float32)
    with torch.no_grad():
        torch.onnx.export(
            actor, (dummy,), str(tmp), input_names=["obs"], output_names=["action"],
            dynamic_axes={"obs": {0: "batch"}, "action": {0: "batch"}}, dynamo=False,
        )  # fmt: skip
    import onnx

    graph = onnx.load(str(tmp))
    meta = {
        "policy": policy.name,
        "frame_stack": str(policy.n_stack),
        "obs_dim": str(dim // policy.n_stack),
        "env_kwargs": json.dumps({**policy.env_kwargs, "action_repeat": policy.action_repeat}),
        "inputs": json.dumps(input_spec(policy)),
        "vehicle": str(policy.vehicle),
        "frame_fill": json.dumps([float(x) for x in frame_fill[: dim // policy.n_stack]]),
    }
    for k, v in meta.items():
        entry = graph.metadata_props.add()
        entry.key, entry.value = k, v
    onnx.save(graph, str(tmp))
    tmp.replace(out)
    return {"onnx": str(out), "inputs": dim, **meta, **onnx_latency(out, dim)}


def input_spec(policy: SB3Policy) -> dict[str, Any]:
    """What an embedded WSP needs besides the graph to build its inputs and use its output, as
    the environment of ``policy``'s settings resolves them (the ONNX metadata's ``inputs``)."""
    import dataclasses

    from wsp_env.baselines.slip_target import (
        CAL_MAX_FACTOR,
        CAL_MIN_SPEED_MPS,
        DRIFT_MIN_SPAN_S,
        LOCK_GUARD_DECEL_MPS2,
        LOCK_GUARD_FRACTION,
        LOCK_GUARD_SETTLE_S,
        LOCK_GUARD_SPEED_KMH,
        LOCK_GUARD_TAU_S,
        ONSET_MIN_S,
        REF_HELD_TOL_MPS,
    )
    from wsp_env.core import braking as B
    from wsp_env.core import kernel as K
    from wsp_env.envs import make_core
    from wsp_env.physics import layout as L

    kwargs = dict(policy.env_kwargs)
    if policy.vehicle is not None:
        kwargs["vehicle"] = policy.vehicle
    core = make_core(1, **kwargs)
    par, env_par, axle_par = core.obs_par, core.sim.env_par[0], core.sim.axle_par[0]
    from wsp_env.baselines.classical import core_tier

    tier = core_tier(core)
    period = float(core.sim.control_period_s)
    spec: dict[str, Any] = {
        "vehicle": core.vehicle.id,
        "action_mode": core.action_mode,
        "n_axles": core.n_axles,
        "valve_of_axle": [int(v) for v in core.valve_of_axle],
        "control_period_s": period,
        "action_repeat": policy.action_repeat,
        "decision_period_s": period * policy.action_repeat,
        "obs_dim": core.obs_dim,
        "kernel_obs_dim": core.kernel_obs_dim,
        "obs_clip": float(K.OBS_CLIP),
        "speed_scale_mps": float(par[K.OP_SPEED_SCALE]),
        "decel_scale_mps2": float(par[K.OP_DECEL_SCALE]),
        "age_scale_s": float(par[K.OP_AGE_SCALE]),
        "privileged": bool(core.privileged),
        "accelerometer": bool(core.accelerometer),
        "sensor_tier": tier,
    }
    if core.memory_features:
        spec["memory_features"] = {
            "order": ["slide_s", "since_release_s", "energy_MJ"],  # n_axles entries each
            "time_scale_s": B.MEMORY_TIME_SCALE_S,
            "energy_scale_MJ": B.MEMORY_ENERGY_SCALE_MJ,
            "slide_threshold_mps": float(env_par[L.EP_SLIDE_THRESH]),
            "slide_threshold_rel": float(env_par[L.EP_SLIDE_REL]),
            "release_fraction": float(par[K.OP_WD_RELEASE_FRACTION]),
            "brake_gain_Nm_per_bar": [float(x) for x in axle_par[:, L.AP_BRAKE_GAIN]],
            "brake_threshold_bar": [float(x) for x in axle_par[:, L.AP_P_THRESH]],
            "wheel_radius_m": [float(x) for x in axle_par[:, L.AP_RADIUS]],
            "pad_slope_per_mps": float(env_par[L.EP_PAD_SLOPE]),
            "pad_ref_speed_mps": float(env_par[L.EP_PAD_VREF]),
        }
    if core.memory_target_mean:
        # after the memory features (n_valves entries): each valve's mean of the slip-target
        # actions (clipped to [-1, 1]) over the stop's control periods so far, the tail's value
        # before the first
        spec["memory_target_mean"] = {"periods": "control", "initial": 1.0}
    if core.loop is not None:
        loop = core.loop
        spec["slip_target"] = {
            "min_kmh": core.slip_target_min_kmh,
            "max_kmh": core.slip_target_max_kmh,
            "gain_per_kmh": loop.gain_per_kmh,
            "lead_s": loop.lead_s,
            "release": loop.release,
            # "working": a release begins only while the loop asked for under the demand in the
            # last period or a wheel's measured slip exceeds max(kmh, rel x the reference)
            "working_band_kmh": loop.active_slip * 3.6,
            "working_band_rel": loop.active_slip_rel,
            # each target at most this fraction of the reference speed or the floor, where
            # that is more (0: no cap)
            "max_creep": loop.max_creep,
            "max_creep_floor_kmh": loop.creep_floor_kmh,
            # the aided reference less the drift its last anchor showed and the estimator did
            # not learn (rate over at least drift_min_span_s; baselines/slip_target.py)
            # (the estimator's rule it mirrors: accel_offset_gain of the miss learned at an
            # anchor at least accel_learn_min_span_s after the last)
            "drift_correction": loop.drift_correction,
            "drift_min_span_s": DRIFT_MIN_SPAN_S,
            "accel_offset_gain": loop.learn_gain,
            "accel_learn_min_span_s": K.ACC_LEARN_MIN_SPAN_S,
            # the gain times clip(p / p_d, gain_scale_floor, 1) (1: the fixed gain_per_kmh)
            "gain_scale_floor": loop.gain_scale_floor,
            # the accelerometer's offset read at the onset (every cylinder under its brake's
            # threshold, free_share of the full pressure, for at least onset_min_s)
            "onset_drift": loop.onset_drift,
            "onset_min_s": ONSET_MIN_S,
            # both senses of the offset; the upward correction times only the time no wheel
            # has held the estimator's reference up (within ref_held_tol_kmh of the fastest
            # reading) since the last anchor; its drop when one holds it again is no fall of
            # the reference for the lead term (as the onset's and the anchors' steps)
            "onset_two_sided": loop.onset_two_sided,
            "ref_held_tol_kmh": REF_HELD_TOL_MPS * 3.6,
            "onset_free_share": [float(x) for x in loop.free_share],
            # each wheel's reading (and its deceleration) times the wheels' mean reading over
            # its own in the same window (for at least onset_min_s, every wheel's mean above
            # cal_min_speed_kmh; within cal_max_factor of 1), the reference times the factor
            # of the wheel it last equalled; the anchors read on the uncalibrated readings
            "scale_calibration": loop.scale_calibration,
            "cal_min_speed_kmh": CAL_MIN_SPEED_MPS * 3.6,
            "cal_max_factor": CAL_MAX_FACTOR,
            # below lock_guard_speed_kmh, on a stop where a wheel slipped beyond the working
            # band and the reference's fall, averaged first-order over lock_guard_tau_s from 0
            # at the stop's start, is under lock_guard_decel_mps2, from lock_guard_settle_s into
            # the stop: every request at most lock_guard_fraction
            "lock_guard": loop.lock_guard,
            "lock_guard_speed_kmh": LOCK_GUARD_SPEED_KMH,
            "lock_guard_fraction": LOCK_GUARD_FRACTION,
            "lock_guard_decel_mps2": LOCK_GUARD_DECEL_MPS2,
            "lock_guard_tau_s": LOCK_GUARD_TAU_S,
            "lock_guard_settle_s": LOCK_GUARD_SETTLE_S,
            "tier": tier,
            "wsp": dataclasses.asdict(loop.cfg),
        }
    if core.base is not None:
        spec["residual"] = {
            "scale": core.residual_scale,
            "deadband": core.residual_deadband,
            "tier": tier,
            "wsp": dataclasses.asdict(core.base.cfg),
        }
    return spec


def onnx_latency(path: str | Path, dim: int, calls: int = 2000) -> dict[str, float]:
    """Median and 99th-percentile wall time of one single-observation decision."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    x = np.zeros((1, dim), dtype=np.float32)
    times = []
    for _ in range(calls):
        t0 = time.perf_counter()
        session.run(None, {"obs": x})
        times.append(time.perf_counter() - t0)
    times_us = np.array(times[calls // 10 :]) * 1e6  # first tenth: warm-up
    return {
        "latency_median_us": float(np.median(times_us)),
        "latency_p99_us": float(np.percentile(times_us, 99)),
    }
