"""Fine-tuning a trained policy on the benchmark's own score with evolution strategies
(``wsp-env finetune``; docs/training.md, "Fine-tuning on the score").

**Why not PPO here.** PPO from an imitation start moved the slip-target student off its start on
most stops (docs/training_log.md, "The fine-tune against its imitation start"): its objective, the
mean discounted return, is carried by a few stops 10-20 times the median, not the score (the
interquartile mean of each stop's return normalised between locked wheels and the classical
WSP); and a better target at one 80 ms decision changes a stop's return by far less than stops
differ from one another, so its advantage estimates are mostly the stops' spread.

**The method**: OpenAI-ES (Salimans, Ho, Chen, Sidor & Sutskever 2017, "Evolution strategies as a
scalable alternative to reinforcement learning", arXiv:1703.03864) — a policy gradient with
exploration in parameter space (Sehnke et al. 2010, "Parameter-exploring policy gradients",
Neural Networks 23(4)). Per generation:

1. ``stops`` stops are drawn from a pool of training stops of the benchmark's distribution
   (``TRAINING_SEED_BASE + i``: far from the sealed and development seeds and from every suite;
   ``tests/test_es.py`` checks), scored ones only (where the classical WSP gains at least
   ``benchmark.MIN_GAIN``); the pool's locked-wheel and classical returns are computed once;
2. ``pairs`` antithetic perturbations ``theta +- sigma * eps`` of the actor's last ``layers``
   linear layers (the action head by default) run those same stops — the same seeds, the same
   sensor errors (common random numbers: members differ by their weights only) — beside the
   current weights and the start, all as one batch of environments through the benchmark's own
   runner (``runner.run_runs``: the tier's sensors, the watchdog, the default reward);
3. each member's fitness is the benchmark's score on those stops (``benchmark.score``), less
   ``ratio_weight`` times its mean distance hinge where ``ratio_cap`` is set (the stops run
   past ``ratio_cap`` times the classical WSP's distance) and ``watchdog_weight`` times the
   share of its stops where the watchdog intervened (issue 23 item 6's criteria); the
   perturbations, weighted by their fitnesses' centred ranks, estimate the gradient, and Adam
   (Kingma & Ba 2015) takes a step.

The start and the current weights run every generation, so ``history.json`` carries the paired
gain of the current weights over the start on fresh stops (the learning curve). State is saved
after every generation (``es_state.npz``, ``history.json``): ``--resume`` continues a run stopped
at any point and ends with the same weights as the run done in one go (each generation's draws
come from ``(seed, generation)``). The result is an ordinary model file (``model.zip`` with the
start's normalisation beside it and its metadata inside), scored like any other.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wsp_env.core.config import load_vehicle
from wsp_env.envs.tiers import VERSION, benchmark_env_kwargs
from wsp_env.evaluation.benchmark import (
    DAMAGE_CRITERIA,
    POLICY_KEYS,
    check_policy,
    iqm,
    normalised,
)
from wsp_env.evaluation.runner import run_runs
from wsp_env.evaluation.suites import Run
from wsp_env.files import write_atomically, write_json
from wsp_env.policy import (
    INFERENCE_BLOCK,
    SB3Policy,
    model_metadata,
    require_extras,
    sensor_tier,
    write_model_metadata,
)
from wsp_env.threads import applied, thread_policy

TRAINING_SEED_BASE = 9_510_000  # the pool's seeds: TRAINING_SEED_BASE + i, i < MAX_POOL
MAX_POOL = 100_000
STATE = "es_state.npz"
SETTINGS = "es.json"
POOL = "pool.json"
HISTORY = "history.json"


@dataclass(frozen=True)
class ESSettings:
    """A fine-tune's settings (``es.json``; docs/training_log.md's first run changed only
    ``learning_rate``, to 0.003; its second also ``average`` to 0.9 and ``guard`` to 0.2).

    ============================  =======  ==================================================
    field                         default  meaning
    ============================  =======  ==================================================
    ``pairs``                     6        antithetic perturbation pairs a generation
    ``stops``                     100      stops a generation (every member runs the same)
    ``pool``                      2000     training stops to draw from
    ``sigma``                     0.01     perturbation scale, in parameter units
    ``learning_rate``             0.001    Adam's step, in parameter units
    ``layers``                    1        the actor's last linear layers that move (1: head)
    ``seed``                      0        every draw comes from ``(seed, generation)``
    ``average``                   0.0      decay of the weights' running average, which is
                                           scored as "current" and written (0: the last step's)
    ``guard``                     0.0      > 0: a member that returns more than ``guard`` (in
                                           the score's units) less than the start on any
                                           stop of its generation, or brings the watchdog
                                           where the start ran without it, ranks below every
                                           member that does neither (0: no guard)
    ``ratio_cap``                 0.0      > 0 (>= 1): each member's fitness loses
                                           ``ratio_weight`` times the mean over its stops of
                                           ``max(0, d / d_classical - ratio_cap)``, its
                                           stopping distance against the classical WSP's
                                           (issue 23 item 6: no stop 10 % longer); 0: off
    ``ratio_weight``              1.0      the weight of that hinge, in the score's units
    ``watchdog_weight``           0.0      each member's fitness loses this times the share
                                           of its stops on which the safety watchdog
                                           intervened (item 6: no intervention); 0: off
    ``unscored``                  0        stops a generation drawn from the pool's unscored
                                           ones (dry rails, where the classical WSP gains
                                           < ``benchmark.MIN_GAIN``): run by every member,
                                           in the hinge, the watchdog share and the guard's
                                           watchdog test, not the score (it cannot weigh
                                           them); ``history.json``'s ``mean_return_*`` and
                                           ``watchdog_stops_*`` then count them too
    ============================  =======  ==================================================

    ``average`` is Polyak-Ruppert averaging (Polyak & Juditsky 1992, SIAM J. Control Optim.
    30(4)) in its exponential form: the Adam iterates jitter around the optimum at the scale of
    the learning rate, and their average sits nearer to it. ``guard`` keeps the score's tails,
    which the IQM does not weigh, from being traded for its middle.
    """

    start: str
    pairs: int = 6
    stops: int = 100
    pool: int = 2000
    sigma: float = 0.01
    learning_rate: float = 0.001
    layers: int = 1
    seed: int = 0
    average: float = 0.0
    guard: float = 0.0
    ratio_cap: float = 0.0
    ratio_weight: float = 1.0
    watchdog_weight: float = 0.0
    unscored: int = 0

    def check(self) -> None:
        """One line naming the first bad field."""
        for name in ("pairs", "stops", "pool", "layers"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name}: must be a whole number >= 1, got {v!r}")
        if self.pool > MAX_POOL:
            raise ValueError(f"pool: at most {MAX_POOL} stops, got {self.pool}")
        if self.stops > self.pool:
            raise ValueError(f"stops: {self.stops} a generation, more than the pool's {self.pool}")
        for name in ("sigma", "learning_rate"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < math.inf:
                raise ValueError(f"{name}: must be a positive number, got {v!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed: must be a whole number >= 0, got {self.seed!r}")
        a = self.average
        if isinstance(a, bool) or not isinstance(a, (int, float)) or not 0 <= a < 1:
            raise ValueError(f"average: must be a number in [0, 1), got {a!r}")
        g = self.guard
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not 0 <= g < math.inf:
            raise ValueError(f"guard: must be a number >= 0, got {g!r}")
        c = self.ratio_cap
        if isinstance(c, bool) or not isinstance(c, (int, float)) or not (c == 0 or 1 <= c < 10):
            raise ValueError(f"ratio_cap: must be 0 (off) or a number in [1, 10), got {c!r}")
        for name in ("ratio_weight", "watchdog_weight"):
            w = getattr(self, name)
            if isinstance(w, bool) or not isinstance(w, (int, float)) or not 0 <= w < math.inf:
                raise ValueError(f"{name}: must be a number >= 0, got {w!r}")
        u = self.unscored
        if isinstance(u, bool) or not isinstance(u, int) or u < 0:
            raise ValueError(f"unscored: must be a whole number >= 0, got {u!r}")
        if u and not (c or self.watchdog_weight):
            raise ValueError(
                "unscored: counts in the distance hinge and the watchdog share only; set "
                "ratio_cap or watchdog_weight"
            )


def actor_layers(model: Any) -> tuple[list[Any], type]:
    """The actor's linear layers in order (its MLP's, then the action head) and its activation,
    for a stable-baselines3 ``ActorCriticPolicy`` on flat observations with continuous actions;
    anything else is refused in one line."""
    import torch

    policy = model.policy
    name = type(model).__name__
    if hasattr(policy, "lstm_actor"):
        raise ValueError(f"{name}: recurrent policies are not fine-tuned here (feed-forward only)")
    extractor = getattr(policy, "mlp_extractor", None)
    if extractor is None or not hasattr(policy, "action_net"):
        raise ValueError(f"{name}: not an actor-critic policy with an action head")
    if getattr(policy, "squash_output", False) or getattr(policy, "use_sde", False):
        raise ValueError(f"{name}: squashed or gSDE actions are not fine-tuned here")
    if not isinstance(policy.pi_features_extractor, torch.nn.Flatten) and (
        type(policy.pi_features_extractor).__name__ != "FlattenExtractor"
    ):
        raise ValueError(f"{name}: its observations are not flat")
    from gymnasium import spaces

    if not isinstance(model.action_space, spaces.Box):
        raise ValueError(f"{name}: {type(model.action_space).__name__} actions (continuous only)")
    act = policy.activation_fn
    layers = []
    for m in extractor.policy_net:
        if isinstance(m, torch.nn.Linear):
            layers.append(m)
        elif not isinstance(m, act):
            raise ValueError(f"{name}: its actor holds a {type(m).__name__} layer")
    layers.append(policy.action_net)
    return layers, act


def get_parameters(layers: list[Any]) -> np.ndarray:
    """The layers' weights and biases as one float64 vector (each weight row-major, then its
    bias)."""
    parts = []
    for lin in layers:
        parts += [lin.weight.detach().cpu().numpy().ravel(), lin.bias.detach().cpu().numpy()]
    return np.concatenate(parts).astype(np.float64)


def set_parameters(layers: list[Any], theta: np.ndarray) -> None:
    """Write ``theta`` (``get_parameters``' layout) into the layers."""
    import torch

    i = 0
    with torch.no_grad():
        for lin in layers:
            for p in (lin.weight, lin.bias):
                k = p.numel()
                p.copy_(torch.as_tensor(theta[i : i + k].reshape(p.shape), dtype=p.dtype))
                i += k
    if i != theta.size:
        raise ValueError(f"parameters: {theta.size} values for layers holding {i}")


class PopulationPolicy(SB3Policy):
    """A trained model whose last ``n_layers`` actor layers take one set of weights per member:
    environment ``e`` runs member ``e // rows`` (``rows`` environments each, in order). Everything
    else — normalisation, frame stack, action repeat, checks — is ``SB3Policy``'s."""

    def __init__(self, path: str | Path, thetas: np.ndarray, rows: int, n_layers: int = 1) -> None:
        import torch

        super().__init__(path)
        layers, act = actor_layers(self.model)
        if not 1 <= n_layers <= len(layers):
            raise ValueError(f"layers: 1-{len(layers)} for this actor, got {n_layers}")
        self.name = "es_population"
        self._rows = int(rows)
        self._members = int(thetas.shape[0])
        self._act = act()
        shared = layers[: len(layers) - n_layers]
        moving = layers[len(layers) - n_layers :]
        self._shared = shared
        self._n_moving = len(moving)
        self._weights: list[tuple[Any, Any]] = []
        i = 0
        for lin in moving:
            out_f, in_f = lin.weight.shape
            w = thetas[:, i : i + out_f * in_f].reshape(-1, out_f, in_f)
            i += out_f * in_f
            b = thetas[:, i : i + out_f]
            i += out_f
            self._weights.append(
                (torch.as_tensor(w, dtype=torch.float32).contiguous(),
                 torch.as_tensor(b, dtype=torch.float32).contiguous())
            )  # fmt: skip
        if i != thetas.shape[1]:
            raise ValueError(f"parameters: {thetas.shape[1]} a member for layers holding {i}")
        space = self.model.action_space
        self._low, self._high = space.low, space.high
        self._sim: Any = None  # the bound core's simulator (``_live``)

    def bind(self, core: Any) -> None:
        if core.n_envs != self._members * self._rows:
            raise ValueError(
                f"{self._members} members x {self._rows} stops, the core has {core.n_envs} "
                "environments"
            )
        super().bind(core)
        self._sim = core.sim

    def _live(self, n: int) -> np.ndarray:
        """Which of ``n`` rows still run: under ``runner.run_runs`` (the only runner of a
        population) an environment at standstill or frozen at its stop's end (``sim.stopped``)
        was scored in the step it ended and is never read again, so its actions change nothing
        (the kernel still takes them in); padding rows are not live. All rows before
        ``bind``."""
        sim = self._sim
        if sim is None:
            return np.ones(n, dtype=bool)
        live = np.zeros(n, dtype=bool)
        live[: sim.n_envs] = ~sim.stopped
        return live

    def _forward(self, x: np.ndarray) -> np.ndarray:
        """As ``SB3Policy._forward``, bit for bit where a member holds the model's own weights:
        every product on blocks of ``INFERENCE_BLOCK`` rows (torch picks its code path by the
        batch's size), the shared layers on the batch's blocks, each member's on its own rows'.
        A block whose rows have all ended is skipped (zeros: ``_live``). No live row's action
        changes: each block is its own product of the same size as before, and a row of a
        product does not depend on the other rows' values (a member's block may hold zeros
        from a skipped shared block beside live rows; tested)."""
        import torch
        import torch.nn.functional as F

        block = INFERENCE_BLOCK
        live = self._live(x.shape[0])
        width = self._shared[-1].out_features if self._shared else x.shape[1]
        n_out = int(self._weights[-1][1].shape[1])
        with torch.no_grad():
            h = torch.as_tensor(x, dtype=torch.float32)
            parts = []
            for b in range(0, h.shape[0], block):
                hb = h[b : b + block]
                if not live[b : b + block].any():
                    parts.append(hb.new_zeros((hb.shape[0], width)))
                    continue
                for lin in self._shared:
                    hb = self._act(lin(hb))
                parts.append(hb)
            h = torch.cat(parts)
            rows, pad = self._rows, (-self._rows) % block
            out = []
            for j in range(self._members):
                hm = h[j * rows : (j + 1) * rows]
                live_m = live[j * rows : (j + 1) * rows]
                if pad:
                    hm = torch.cat([hm, hm.new_zeros((pad, hm.shape[1]))])
                for b in range(0, rows + pad, block):
                    keep = max(0, min(block, rows - b))
                    if not live_m[b : b + block].any():
                        out.append(h.new_zeros((keep, n_out)))
                        continue
                    hb = hm[b : b + block]
                    for k, (w, bias) in enumerate(self._weights):
                        hb = F.linear(hb, w[j], bias[j])
                        if k < self._n_moving - 1:
                            hb = self._act(hb)
                    out.append(hb[:keep])
            act = torch.cat(out).numpy()
        act = np.clip(act, self._low, self._high)
        return np.concatenate([act, np.zeros((x.shape[0] - act.shape[0], act.shape[1]), act.dtype)])


def population(start: np.ndarray, current: np.ndarray, theta: np.ndarray,
               steps: np.ndarray) -> np.ndarray:  # fmt: skip
    """A generation's members in their order: the start, the current weights, then
    ``theta + steps`` and ``theta - steps`` (one antithetic pair a row of ``steps``)."""
    return np.concatenate([start[None], current[None], theta + steps, theta - steps])


def centred_ranks(x: np.ndarray) -> np.ndarray:
    """Ranks scaled to [-0.5, 0.5] (ties share their mean rank): the fitness shaping of
    Salimans et al. (2017), invariant to the fitness' scale."""
    from scipy.stats import rankdata

    return (rankdata(x) - 1.0) / max(len(x) - 1, 1) - 0.5


def env_setup(policy: SB3Policy) -> tuple[Any, dict[str, Any], float, str]:
    """A loaded policy's vehicle, the benchmark's environment settings for its sensor tier
    (``policy.sensor_tier``), the time limit and the tier."""
    tier = sensor_tier(policy) or "wheels"
    kwargs = benchmark_env_kwargs(policy.vehicle or "uic_z1", tier)
    veh = load_vehicle(kwargs.pop("vehicle"))
    return veh, kwargs, float(kwargs.pop("max_time_s")), tier


def pool_seeds(n: int) -> list[int]:
    """The seeds of a pool of ``n`` training stops."""
    return [TRAINING_SEED_BASE + i for i in range(n)]


def training_runs(veh: Any, seeds: list[int], copies: int = 1) -> list[Run]:
    """The pool's stops of ``seeds``, ``copies`` times over (one copy a member, in order)."""
    return [
        Run(f"train_{s - TRAINING_SEED_BASE:05d}", s, {}, dict(DAMAGE_CRITERIA), veh)
        for _ in range(copies)
        for s in seeds
    ]


def training_pool(
    start: SB3Policy, n: int, progress: Callable[[str], None] | None = None
) -> dict[str, Any]:
    """The pool's seeds, their locked-wheel and classical returns (the score's ends) and the
    classical WSP's stopping distances, for the start's vehicle and sensor tier under the
    benchmark's current version (``version``: a pool of another is not reused)."""
    veh, _, _, tier = env_setup(start)
    seeds = pool_seeds(n)
    out: dict[str, Any] = {"seeds": seeds, "tier": tier, "vehicle": veh.id, "version": VERSION}
    for name in ("none", "classical"):
        res = baseline_runs(start, name, seeds, progress)
        out[f"r_{name}"] = [r["return"] for r in res]
        if name == "classical":
            out["d_classical"] = [r["stopping_distance_m"] for r in res]
    return out


def baseline_runs(
    start: SB3Policy, name: str, seeds: list[int], progress: Callable[[str], None] | None = None
) -> list[dict[str, Any]]:
    """The results of the built-in policy ``name`` (``none``, ``classical``) of the start's
    sensor tier on the pool's ``seeds``, through the benchmark's runner. ``training_pool`` uses
    it, and an older pool without the classical WSP's distances gets them from it."""
    from wsp_env.policy import make_policy

    veh, kwargs, max_time_s, tier = env_setup(start)
    if progress is not None:
        progress(f"pool: {name} on {len(seeds)} training stops")
    res, _ = run_runs(veh, training_runs(veh, seeds), make_policy(name, tier=tier),
                      max_time_s=max_time_s, env_kwargs=kwargs,
                      policy_keys=POLICY_KEYS)  # fmt: skip
    return res


def _read_pool(path: Path, start: SB3Policy, n: int) -> dict | None:
    """The pool in ``path`` if it is this start's vehicle and tier, ``n`` stops and the
    benchmark's current version (a first call stopped before its first generation ended, a
    pool copied from another run), else None. A pool without a version was written under
    ``-v1`` or ``-v2``, whose classical WSP's returns and distances are not today's."""
    if not path.exists():
        return None
    pool = _read_json(path, "pool")
    veh, _, _, tier = env_setup(start)
    if not isinstance(pool, dict):
        return None
    same = (
        pool.get("tier") == tier
        and pool.get("vehicle") == veh.id
        and pool.get("seeds") == pool_seeds(n)
        and pool.get("version") == VERSION
    )
    ends = [pool.get(k) for k in ("r_none", "r_classical")]
    if "d_classical" in pool:  # optional: pools written before 2026-11-27 lack it
        ends.append(pool["d_classical"])
    ok = all(isinstance(e, list) and len(e) == n for e in ends)
    if ok:
        ok = all(isinstance(x, (int, float)) and math.isfinite(x) for e in ends for x in e)
    if ok and "d_classical" in pool:
        ok = all(x > 0 for x in pool["d_classical"])
    return pool if same and ok else None


def _read_json(path: Path, what: str) -> Any:
    """``path``'s JSON, or one line naming the file."""
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: missing (the fine-tune's {what})") from None
    except (OSError, ValueError) as err:
        raise ValueError(f"{path}: not the fine-tune's {what} ({type(err).__name__})") from None


def _read_state(path: Path, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int,
                                               np.ndarray]:  # fmt: skip
    """The saved weights, Adam's moments, the generations done and the weights' zero-started
    running average (zeros in a state from before ``average``), or one line naming the
    file."""
    try:
        with np.load(path) as st:
            theta, m, v, done = st["theta"], st["m"], st["v"], int(st["generation"])
            avg = st["theta_average"] if "theta_average" in st.files else np.zeros_like(theta)
    except Exception as err:  # a damaged file: numpy, zipfile and pickle each raise their own
        raise ValueError(f"{path}: not the fine-tune's state ({type(err).__name__})") from None
    if not (theta.shape == m.shape == v.shape == avg.shape == (size,)) or done < 0:
        raise ValueError(f"{path}: holds {theta.size} parameters, the start's layers {size}")
    return theta, m, v, done, avg


def averaged(theta: np.ndarray, total: np.ndarray, decay: float, steps: int) -> np.ndarray:
    """The weights scored as "current" and written: ``theta`` itself without averaging or before
    the first step, else the bias-corrected exponential average of the ``steps`` iterates
    (``total`` is their zero-started running average, as Adam's moments)."""
    if decay <= 0 or steps <= 0:
        return theta
    return total / (1.0 - decay**steps)


def file_sha256(path: Path) -> str:
    """The file's SHA-256 (a fine-tune pins its start with it)."""
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()


def evaluate_population(
    start: Path, thetas: np.ndarray, seeds: list[int], n_layers: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each member's return on each stop, whether the watchdog intervened there and its
    stopping distance [m], each ``(members, stops)``: one batch of environments through the
    benchmark's runner."""
    policy = PopulationPolicy(start, thetas, len(seeds), n_layers)
    veh, kwargs, max_time_s, _ = env_setup(policy)
    res, _ = run_runs(veh, training_runs(veh, seeds, len(thetas)), policy, max_time_s=max_time_s,
                      env_kwargs=kwargs, policy_keys=POLICY_KEYS)  # fmt: skip
    shape = (len(thetas), len(seeds))
    returns = np.array([r["return"] for r in res]).reshape(shape)
    watchdog = np.array([r["watchdog"]["total"] > 0 for r in res]).reshape(shape)
    distance_m = np.array([r["stopping_distance_m"] for r in res]).reshape(shape)
    return returns, watchdog, distance_m


def distance_hinge(ratio: np.ndarray, cap: float) -> np.ndarray:
    """Each member's mean over its stops (the last axis) of ``max(0, ratio - cap)``, ``ratio``
    each stop's distance over the classical WSP's: how far its stops run past ``cap`` times
    the classical WSP's stopping distance."""
    return np.maximum(ratio - cap, 0.0).mean(axis=-1)


def guarded(s: np.ndarray, watchdog: np.ndarray, guard: float) -> np.ndarray:
    """Which members (rows 1.. of ``s``, normalised returns ``(members, stops)`` whose row 0 is
    the start) fail the guard: on some stop they return more than ``guard`` less than the
    start, or the watchdog intervenes where it left the start alone. All False when ``guard``
    is 0."""
    if guard <= 0:
        return np.zeros(s.shape[0] - 1, dtype=bool)
    worse = (s[1:] < s[0] - guard).any(axis=1)
    new_watchdog = (watchdog[1:] & ~watchdog[0]).any(axis=1)
    return worse | new_watchdog


def finetune(
    start: str | Path | None,
    out: str | Path,
    generations: int,
    settings: ESSettings | None = None,
    resume: bool = False,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run ``generations`` generations (module docstring) from the model file ``start`` (a new
    run) or from ``out``'s saved state (``resume``: its own settings), then write ``out/model.zip``
    with the current weights. Returns ``es.json``'s content.

    Threads: the evaluation's policy (``threads.thread_policy("evaluate")``: the kernel in
    parallel on every core, torch's forward passes on one thread), for the call only."""
    require_extras("fine-tuning needs", "rl")
    with applied(thread_policy("evaluate")):
        return _finetune(start, out, generations, settings, resume, progress)


def _finetune(
    start: str | Path | None,
    out: str | Path,
    generations: int,
    settings: ESSettings | None,
    resume: bool,
    progress: Callable[[str], None] | None,
) -> dict[str, Any]:
    if isinstance(generations, bool) or not isinstance(generations, int) or generations < 0:
        raise ValueError(f"generations: must be a whole number >= 0, got {generations!r}")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out}: a file, not a run folder")
    saved: dict[str, Any] = {}
    if resume:
        if not (out / SETTINGS).exists():
            raise ValueError(f"{out}: no fine-tune to resume ({SETTINGS} missing)")
        saved = _read_json(out / SETTINGS, "settings")
        try:
            settings = ESSettings(**saved["settings"])
        except (TypeError, KeyError):
            raise ValueError(f"{out / SETTINGS}: not the fine-tune's settings") from None
    else:
        if start is None:
            raise ValueError("start: the model file to fine-tune is required unless resuming")
        settings = settings or ESSettings(start=str(start))
        settings = ESSettings(**{**asdict(settings), "start": str(Path(start).resolve())})
        if (out / SETTINGS).exists() or (out / STATE).exists():
            raise ValueError(f"{out}: holds a fine-tune already (--resume it, or a new --out)")
    settings.check()
    start_path = Path(settings.start)
    if not start_path.exists():
        raise FileNotFoundError(f"{start_path}: no such model file")
    digest = file_sha256(start_path)
    if resume and saved.get("start_sha256") not in (None, digest):
        raise ValueError(f"{start_path}: changed since the fine-tune began (its SHA-256 differs)")
    if (out / "model.zip").resolve() == start_path.resolve():
        raise ValueError(
            f"{out}: the start's own folder and name; the fine-tune would overwrite it"
        )
    meta = model_metadata(start_path)
    norm_file = start_path.with_suffix(".vecnormalize.pkl")
    if meta.get("obs_normalization") and not norm_file.exists():
        raise ValueError(f"{start_path}: trained on normalised observations, {norm_file} missing")
    base = SB3Policy(start_path)  # refuses what cannot load
    layers, _ = actor_layers(base.model)
    if not 1 <= settings.layers <= len(layers):
        raise ValueError(f"layers: 1-{len(layers)} for this actor, got {settings.layers}")
    veh, kwargs, _, tier = env_setup(base)  # refuses a vehicle the benchmark lacks
    check_policy(base, veh.id, tier, kwargs["control_period_s"])
    moving = layers[len(layers) - settings.layers :]
    theta0 = get_parameters(moving)

    history: list[dict[str, Any]] = []
    if resume:
        pool = _read_pool(out / POOL, base, settings.pool)
        if pool is None:
            raise ValueError(
                f"{out / POOL}: not this fine-tune's pool (or one of an earlier benchmark "
                f"version than -{VERSION}: start a new run from the model)"
            )
        if (out / STATE).exists():
            theta, m, v, done, total = _read_state(out / STATE, theta0.size)
            history = _read_json(out / HISTORY, "history")
            if not isinstance(history, list) or len(history) < done:
                raise ValueError(f"{out / HISTORY}: fewer rows than the {done} generations done")
            history = history[:done]  # a stop between the two writes: the state decides
        else:  # stopped in the first generation
            theta, m, v, done = theta0.copy(), np.zeros_like(theta0), np.zeros_like(theta0), 0
            total = np.zeros_like(theta0)
    else:
        out.mkdir(parents=True, exist_ok=True)
        theta, m, v, done = theta0.copy(), np.zeros_like(theta0), np.zeros_like(theta0), 0
        total = np.zeros_like(theta0)
        pool = _read_pool(out / POOL, base, settings.pool)
        if pool is None:
            pool = training_pool(base, settings.pool, progress)
        elif progress is not None:
            progress(f"pool: {settings.pool} training stops from {out / POOL}")
    seeds = np.array(pool["seeds"])
    r_none, r_cls = np.array(pool["r_none"]), np.array(pool["r_classical"])
    mask = normalised(r_cls, r_none, r_cls)[1]
    scored, unscored = np.flatnonzero(mask), np.flatnonzero(~mask)
    if scored.size < settings.stops:
        raise ValueError(
            f"pool: {scored.size} scored stops, fewer than {settings.stops} a generation"
        )
    if unscored.size < settings.unscored:
        raise ValueError(
            f"unscored: the pool holds {unscored.size} unscored stops, fewer than "
            f"{settings.unscored} a generation"
        )
    if settings.ratio_cap and "d_classical" not in pool:
        res = baseline_runs(base, "classical", [int(x) for x in seeds], progress)
        pool["d_classical"] = [r["stopping_distance_m"] for r in res]
        if resume:
            write_json(out / POOL, pool)
    d_cls = np.array(pool["d_classical"], dtype=float) if settings.ratio_cap else None
    if d_cls is not None and not (np.isfinite(d_cls).all() and (d_cls > 0).all()):
        raise ValueError("pool: d_classical: a stopping distance that is not a positive number")
    if not resume:  # the pool and the settings first, so a run stopped now can be resumed
        write_json(out / POOL, pool)
        write_json(out / SETTINGS, {"settings": asdict(settings), "start_sha256": digest,
                                     "generations": 0})  # fmt: skip
    beta1, beta2, adam_eps = 0.9, 0.999, 1e-8
    t0 = time.time()
    for g in range(done, done + generations):
        tg = time.time()
        rng = np.random.default_rng([settings.seed, g])
        pick = np.sort(rng.choice(scored, size=settings.stops, replace=False))
        eps = rng.standard_normal((settings.pairs, theta.size))
        # drawn after eps, and only when asked: a run without them draws as before
        extra = (np.sort(rng.choice(unscored, size=settings.unscored, replace=False))
                 if settings.unscored else np.zeros(0, dtype=int))  # fmt: skip
        ran = np.concatenate([pick, extra])
        current = averaged(theta, total, settings.average, g)
        thetas = population(theta0, current, theta, settings.sigma * eps)
        returns, watchdog, dist = evaluate_population(start_path, thetas,
                                                      [int(s) for s in seeds[ran]],
                                                      settings.layers)  # fmt: skip
        # every picked stop is scored; the unscored ones (after them) enter the hinge, the
        # watchdog share and the guard's watchdog test, not the score
        s, _ = normalised(returns[:, : pick.size], r_none[pick], r_cls[pick])
        score = iqm(s, axis=1)
        if d_cls is not None:
            ratio = dist / d_cls[ran]
            hinge = distance_hinge(ratio, settings.ratio_cap)
        else:
            ratio, hinge = None, np.zeros(len(thetas))
        fitness = score - settings.ratio_weight * hinge
        fitness = fitness - settings.watchdog_weight * watchdog.mean(axis=1)
        failed = guarded(s, watchdog, settings.guard)  # rows 1..: current, then the members
        # the guard's failures below every other member, in their own order among themselves
        u = centred_ranks(fitness[2:] - failed[1:] * (np.ptp(fitness[2:]) + 1.0))
        k = settings.pairs
        grad = (u[:k] - u[k:]) @ eps / (2 * k * settings.sigma)
        # Adam, ascending the fitness
        before = theta
        m = beta1 * m + (1 - beta1) * grad
        v = beta2 * v + (1 - beta2) * grad * grad
        step = g + 1
        m_hat, v_hat = m / (1 - beta1**step), v / (1 - beta2**step)
        theta = theta + settings.learning_rate * m_hat / (np.sqrt(v_hat) + adam_eps)
        total = settings.average * total + (1 - settings.average) * theta
        row = {
            "generation": g,
            "score_start": float(score[0]),
            "score_current": float(score[1]),
            "score_gain": float(score[1] - score[0]),
            "stops_better": float(np.mean(s[1] > s[0] + 1e-12)),
            "stops_worse": float(np.mean(s[1] < s[0] - 1e-12)),
            "mean_return_start": float(returns[0].mean()),
            "mean_return_current": float(returns[1].mean()),
            "members_best": float(fitness[2:].max()),
            "members_worst": float(fitness[2:].min()),
            "members_guarded": int(failed[1:].sum()),
            "current_guarded": bool(failed[0]),
            "watchdog_stops_start": int(watchdog[0].sum()),
            "watchdog_stops_current": int(watchdog[1].sum()),
            "worst_drop_current": float(np.max(s[0] - s[1])),
            "step_norm": float(np.linalg.norm(theta - before)),
            "distance_from_start": float(np.linalg.norm(theta - theta0)),
            "wall_s": round(time.time() - tg, 1),
        }
        if ratio is not None or settings.watchdog_weight:
            for who, i in (("start", 0), ("current", 1)):
                row[f"fitness_{who}"] = float(fitness[i])
        if ratio is not None:  # the distance hinge's terms, the start's and the current's
            for who, i in (("start", 0), ("current", 1)):
                row[f"hinge_{who}"] = float(hinge[i])
                row[f"ratio_worst_{who}"] = float(ratio[i].max())
                row[f"stops_over_cap_{who}"] = int((ratio[i] > settings.ratio_cap).sum())
        history.append(row)
        # the history first: a stop between the two writes leaves it a row ahead, which a
        # resume cuts back to the state's generations
        write_json(out / HISTORY, history)
        state = {"theta": theta, "m": m, "v": v, "generation": g + 1, "theta_average": total}
        write_atomically(out / STATE, lambda fh, st=state: np.savez(fh, **st), binary=True)
        if progress is not None:
            progress(
                f"generation {g}: current {row['score_current']:.4f} vs start "
                f"{row['score_start']:.4f} ({row['score_gain']:+.4f}), better on "
                f"{row['stops_better']:.0%}, worse on {row['stops_worse']:.0%}"
                + (f", over the distance cap on {row['stops_over_cap_current']} stops (start "
                   f"{row['stops_over_cap_start']}), worst {row['ratio_worst_current']:.3f}"
                   if ratio is not None else "")
                + f", {row['wall_s']} s"
            )  # fmt: skip
    final = averaged(theta, total, settings.average, len(history))  # what "current" was
    model_path = write_model(start_path, out / "model.zip", final, settings.layers, meta)
    payload = {
        "settings": asdict(settings),
        "start_sha256": digest,
        "generations": len(history),
        "model_path": str(model_path),
        "start": str(start_path),
        "tier": pool["tier"],
        "vehicle": pool["vehicle"],
        "wall_time_s_this_call": round(time.time() - t0, 1),
        "wall_time_s": round(sum(r["wall_s"] for r in history), 1),
        "parameters": int(theta.size),
        # the written weights' (history's rows give the last step's)
        "distance_from_start": float(np.linalg.norm(final - theta0)),
        "last": history[-1] if history else None,
    }
    write_json(out / SETTINGS, payload)
    return payload


def write_model(start: Path, path: Path, theta: np.ndarray, n_layers: int,
                meta: dict[str, Any]) -> Path:  # fmt: skip
    """The start's model with its last ``n_layers`` actor layers set to ``theta``, saved to
    ``path`` with the start's metadata (named after ``path``'s folder) and normalisation."""
    policy = SB3Policy(start)
    layers, _ = actor_layers(policy.model)
    set_parameters(layers[len(layers) - n_layers :], theta)
    tmp = path.with_name(path.stem + ".tmp.zip")
    policy.model.save(tmp)
    write_model_metadata(tmp, {**meta, "name": f"{path.parent.name}/{path.stem}",
                               "finetuned_from": str(start)})  # fmt: skip
    norm = start.with_suffix(".vecnormalize.pkl")
    if norm.exists():
        data = norm.read_bytes()
        write_atomically(path.with_suffix(".vecnormalize.pkl"), lambda fh: fh.write(data), True)
    tmp.replace(path)
    return path
