"""``WSPBraking``: wheel slide protection as a Gymnasium environment (single and native vector).

Registered as ``WSPBraking-v0`` (every argument free) and, for the benchmark, as one id per
vehicle and sensor tier that fixes every setting a score depends on (``wsp_env.envs.tiers``:
``WSPBraking-UICZ1-v3``, ``WSPBraking-UICZ1-Accel-v3``, ...; each earlier version stays
registered: Version History).

## Description

A train brakes from ``speed_kmh`` to standstill on a rail drawn at ``reset`` (contaminant,
adhesion level and pattern, load, pad friction, gradient, demand). Every control period (20 ms,
the BCU cycle) the agent sets each WSP valve; the physics runs 1 ms substeps inside
(``wsp_env.core``: the braking core; ``wsp_env.physics``: the compiled model). The goal is the
shortest stop without sliding the wheels into flats and without wasting air.

## Action Space

``action_mode="continuous"`` (default): ``Box(-1, 1, (n_valves,), float32)``; valve ``j`` asks
for the fraction ``(a_j + 1) / 2`` of the current demand pressure (the pneumatics decide how fast
the cylinder gets there; nothing can exceed the demand). Out-of-range values are clipped and
counted in ``info["action_clipped"]``; a NaN raises ``ValueError``.
``action_mode="discrete"``: ``MultiDiscrete([3] * n_valves)``, 0 = vent, 1 = hold, 2 = fill
(apply), like real dump/hold valves.
``action_mode="residual"``: a residual on the frozen classical WSP (``configs/wsp/
classical.yaml``), which runs inside the environment on the same observation:
``Box(-1, 1, (n_valves,))``, valve ``j`` asks for ``clip(f_j + residual_scale * a_j, 0, 1)`` of
the demand, ``f_j`` the classical WSP's own request, so the zero action *is* the classical WSP.
``residual_deadband`` zeroes residuals up to that size and rescales the rest continuously
(``sign(a) (|a| - band) / (1 - band)``): small, ever-changing outputs would otherwise move
every *hold* a little, and each small drop of the target vents air.
``action_mode="slip_target"``: ``Box(-1, 1, (n_valves,))``, valve ``j``'s target **measured
sliding speed** ``s*_j = slip_target_min_kmh + (a_j + 1) / 2 (slip_target_max_kmh -
slip_target_min_kmh)`` km/h (0.5-8 km/h by default, ``a = 0`` 4.25 km/h: the oracle's targets on
soap are 1-8 km/h, its rail-aware teacher's 4 km/h), tracked every control period — also inside
an ``action_repeat`` step — by an inner loop that reads only the observation
(``baselines.slip_target.SlipTargetLoop``): the measured slip ahead,
``s_i = v_ref - v_i + slip_target_lead_s (d_i - d_ref)`` (km/h; ``d_i`` the wheel's measured
deceleration, ``d_ref`` the reference speed's, so ``d_i - d_ref`` is the measured slip's rate;
the lead 0.1 s: the pneumatics' lag), a proportional law on the pressure fraction
``clip(p_i / p_d + slip_target_gain_per_kmh (s*_j - s_i), 0, 1)`` of the demand (0.2 per km/h;
``p_i / p_d`` is the classical WSP's *hold*), the classical WSP's recovery
hold, minimum speed and **periodic release** (one axle in turn vented until the reference
re-anchors on it: without it the reference falls below the train while every axle slides at
its target, and the wheels lock with their measured slip on target), on the thresholds of the
sensor tier's frozen classical WSP; each target at most ``slip_target_max_creep`` (20 %) of the
reference speed, or 2 km/h where that is more (a target fixed in km/h near standstill asks for
a nearly locked wheel); a bogie valve takes its most cautious axle's request. The
measured slip settles on the target (median mid-stop 3.85-3.98 km/h for 4 km/h on soap).
**The watchdog still acts** on the loop's valve commands (Safety watchdog): a target of 0
(``slip_target_min_kmh=0``, ``a = -1``) asks for no measured slip, so from a stop's start the
cylinders stay nearly empty; with ideal sensors every axle is released, and the
minimum-deceleration supervision overrides every release 5.8-6.3 s into the stop (the demand's
build-up and its 3 s), after which every axle gets the full demand whatever the target (on soap
the wheels then lock, the override gives way, the loop vents again and the 10 s safety time
restores the axles to standstill, 23 of 24: the longest lock of six stops 78 s from 120 km/h);
with the
wheel-sensor tier's scale errors some axles fill, the others stay empty until the safety time
restores them, and they lock on soap. Hence the default minimum of 0.5 km/h: ``a = -1`` then fills until the wheels
slip that much, and held from the start of 36 stops (dry and soap, 120-160 km/h, ideal and
wheel-tier sensors) it never brought the watchdog in
(``scripts/slip_target_study.py --part zero``). With the wheel-sensor tier, six seeds each,
against its classical WSP (``--part table``): on soap 0.07 at 120 km/h a constant 4 km/h target
stops 3-4 % shorter with 10-23 % less sliding energy (2 km/h: 2-5 % longer, half the energy);
on oil at 100 km/h 4-10 % shorter. On leaves at 100 km/h (adhesion 0.029-0.042) one target on
every axle keeps all the wheels within the estimator's working band of each other, which the
minimum-deceleration supervision reads as gripping wheels while the rail gives too little
deceleration: it trips in 4 of 6 stops at 4 km/h and 1 of 6 at 2 km/h, and its full demand
locks every axle. The override then gives way and the loop vents, but the locked wheels spin
up at only ~4.5 km/h a second on these leaves, so the watchdog's 10 s safety time runs out
before they reach the train and restores every axle's full demand to standstill: locked again
(the longest 260 s) — the targets are the learner's to choose per axle and stop.
``SlipTargetPolicy`` runs the same loop with a constant target from outside, in continuous mode,
bit for bit the same stop. The kernel's previous-action entries hold the loop's valve commands;
the agent's own last action is the observation's tail.
Valves are per axle (``n_valves = n_axles``), or per bogie with ``valve_group="bogie"``.

## Observation Space

``Box(-5, 5, (obs_dim,), float32)``: what a WSP measures, normalised, grouped by channel (all
wheel speeds, then all decelerations, ...), for a vehicle of ``n`` axles and ``m`` valves.
``v_s`` is the vehicle's maximum speed, ``a_s = 10 m/s^2``, ``p_max`` the cylinder's maximum
pressure. Wheel speeds are the **sensors'** readings (``sensors``, ``SensorConfig``: resolution,
noise, scale error; ideal by default), never the true ones. ``v_ref`` is the **shared
reference-speed estimator's** (``estimator``, ``EstimatorConfig``; the classical WSP reads the
same one): the fastest wheel, falling at most 2.5 m/s^2 — above any dry-rail deceleration, so on
good adhesion it is the train speed — and, while the valves work, at an adaptive slope; with
``accelerometer=True`` at the deceleration the accelerometer reads; re-anchored up or down on a
wheel that rolls freely (brake off 0.3 s, not spinning up).

| index | quantity | unit | normalisation |
|---|---|---|---|
| ``0 .. n-1`` | wheel speed of axle ``i`` (``omega_i r_i``) | m/s | ``/ v_s`` |
| ``n .. 2n-1`` | wheel deceleration of axle ``i`` over the last period | m/s^2 | ``/ a_s``, clipped to +-5 |
| ``2n .. 3n-1`` | slip against the reference ``(v_ref - v_i)`` | m/s | ``/ max(v_ref, 1 m/s)``, clipped |
| ``3n .. 4n-1`` | cylinder pressure of axle ``i`` | bar | ``/ p_max`` |
| ``4n`` | demand pressure | bar | ``/ p_max`` |
| ``4n+1`` | reference speed ``v_ref`` | m/s | ``/ v_s`` |
| ``4n+2 .. 4n+m+1`` | previous valve action | - | as the action (discrete: mode - 1) |
| ``privileged=True``: next ``1 + 2n`` | true train speed ``V``; friction level of axle ``i``; true creepage ``(V - v_i)`` | m/s; -; m/s | ``/ v_s``; none; ``/ max(V, 1 m/s)``, clipped |
| ``accelerometer=True``: next 1 | the body accelerometer's deceleration over the period (a specific force: the gradient's ``g sin(theta)`` is missing from it, plus a bias drawn per episode within ``+-accelerometer_bias_mps2``, noise and lag: ``SensorConfig``) | m/s^2 | ``/ a_s``, clipped |
| next 1 | the reference's age: seconds since the estimator's last anchor, counted once the valves have worked since it (a periodic release is due when it grows) | s | ``/ 10 s``, clipped |
| ``memory_features=True``: next ``n`` | time in the current slide of axle ``i``: how long its measured slip ``v_ref - v_i`` has stayed above the metrics' slide threshold ``max(3 km/h, 20 % v_ref)`` (the classical WSP's is 3.1 km/h, 18 %), 0 when it is below | s | ``/ 10 s``, clipped |
| ``memory_features=True``: next ``n`` | time since axle ``i``'s last release (its valve's command, as the watchdog let it through, under the watchdog's release fraction, 5 %, of the demand) or the stop's start | s | ``/ 10 s``, clipped |
| ``memory_features=True``: next ``n`` | axle ``i``'s sliding-energy **estimate**: the sum over periods of ``F_i max(v_ref - v_i, 0) dt``, ``F_i`` the brake force at the rail from the observed cylinder pressure and the vehicle's brake constants (``gain (p_i - p_threshold)^+ / r`` at the pads' nominal friction for ``v_ref``: the stop's pad scale is unknown to a WSP) | MJ | ``/ 1 MJ``, clipped (at 5 MJ) |
| ``memory_target_mean=True`` (slip-target mode): next ``m`` | valve ``j``'s mean slip-target action over the stop's control periods so far (the actions stepped, clipped, the tail's values: the agent's, and at a training run's staggered start the warm-up's middle target; the tail's own value, 1, before the first period) | - | as actions in ``[-1, 1]`` |
| ``action_mode="residual"``: last ``m`` | the classical WSP's requests for this period | - | as actions in ``[-1, 1]`` |
| ``action_mode="slip_target"``: last ``m`` | the agent's last action (the slip targets in force), clipped; 1 at a stop's start | - | as actions in ``[-1, 1]`` |

So ``obs_dim = 4n + 3 + m (+ 1 + 2n privileged) (+ 1 accelerometer) (+ 3n memory) (+ m
target mean) (+ m residual or slip_target)``: 23 for the 4-axle ``uic_z1`` with per-axle valves.

The memory features are what a WSP can keep of the past from what it measures, so that the
damage term (a function of each axle's cumulative sliding energy) is a function of what is
observed: they are zero at a reset (each environment's own autoreset in the vector class) and
advance once per control period (``action_repeat`` k: k periods, ``k * control_period_s`` on
the timers, per step). The energy estimate reads 0.63-1.05 of each axle's true sliding energy
(``info["metrics"]["axles"][i]["sliding_energy_kJ"]``) under the classical WSP and 0.70-0.98
under a constant 4 km/h slip target with ideal sensors, 0.59-1.05 and 0.71-1.02 with the
benchmark's wheel-sensor tier (noise, resolution, +-0.5 % scale errors; soap 0.05-0.08 at
60-160 km/h, four seeds: ``scripts/memory_energy_study.py``): low, as the reference sags a
little below the train between anchors and the stop's pad scale is unknown. Subtracting the
wheelset's inertial term ``J a_i / r^2`` from the force, or counting only the slip beyond what
the scale errors make (``2 e v_ref``), moved it further from the truth on those stops, so
neither is done. On locked wheels (``none``) it overestimates, 1.04-3.15 times the truth on
the same stops with either sensor set: the pads then hold more than the rail carries (most on
the lowest adhesion), which the reference's fall below the train (no wheel to anchor on) only
partly offsets. The observed channel clips at 5 MJ, which locked axles pass on soap from
120 km/h (up to 9 MJ there; 2.2 MJ from 60 km/h); the core's ``memory_energy_J`` does not clip
(``tests/test_memory_features.py``).

The stop's mean slip target (``memory_target_mean``) is the policy's own memory of what it
asked for: what a policy read of the rail while the train was fast stays observed near
standstill, where the rails look more alike, beyond the frame stack's reach. Two sums per valve,
anything a WSP can keep; it starts anew at each reset. Measured on the rail-table teacher's
students (docs/training_log.md, "The stop's mean slip target"), the students without it already ask
for their rail's target at every speed on average, and with it they did no better on the
development stops.

## Safety watchdog

Between the agent and the valves, as in a real brake control unit and the same for every
controller (``watchdog``, ``WatchdogConfig``, on by default): an axle released — its valve
venting (asking for under 5 % of the demand) or its cylinder under 5 % of the full pressure —
for longer than the safety time (10 s) gets the full demand back until standstill; when the
deceleration the sensors measure, less the gradient's part, stays below 0.2 m/s^2 for 3 s while
the full demand stands and every wheel grips, every release is overridden until standstill, or
until every axle has read locked under that full demand for 0.2 s (``give_way_locked_s``): then
the rail, not the controller, was the limit, the override gives way and does not trip again in
the stop (the safety time still stands).
``info["metrics"]["watchdog"]`` counts its interventions. The observation's previous action is
the agent's own (the valve action it gave; in the slip-target mode the inner loop's), not the
watchdog's.

## Rewards

Minus the stop's cost in metres of stopping distance, divided by ``distance_scale_m`` (100 m).
Each term is in ``info["reward_terms"]``; their exchange rates are ``reward`` (``RewardConfig``):

* ``distance``  ``-dx``: over an episode it sums to ``-stopping_distance / distance_scale_m``;
* ``damage``    wheel damage, priced per axle and superlinearly: axle ``i`` with cumulative
  sliding energy ``E_i`` costs ``damage_m_per_MJ E_i (1 + E_i / damage_ref_MJ)`` metres
  (20 m per MJ, doubled at 1 MJ), so a slide concentrated on one wheel costs more than the same
  energy spread over four;
* ``lock``      ``lock_m_per_s`` (10 m) per second each axle is locked (a wheel flat);
* ``air``       ``air_m_per_100l`` (5 m) per 100 free-air litres vented;
* ``shaping``   a training option, off by default (``shaping_decel_mps2 = 0``): potential-based
  shaping ``gamma Phi(V') - Phi(V)`` with ``Phi(V) = -V^2 / (2 a0)``, ``gamma = shaping_gamma``
  (set it to the learner's discount). By Ng, Harada & Russell (1999) it leaves the optimal
  policy unchanged: its *discounted* sum over a stop is ``V0^2 / (2 a0)``, a constant of the
  scenario (the undiscounted sum is not, so logged returns with shaping on are not comparable
  with returns without it). It reads the true train speed: a reward-only privilege;
* ``slide``     an option, off by default (``slide_m_per_s = 0``): metres per second each axle
  slides deeper than the slide threshold ``max(3 km/h, 20 % V)``.

With these defaults the classical WSP's return is about nine tenths distance; a locked-wheel
policy (``none``) and one that brakes less than the demand return clearly less on soap and
leaves (``tests/test_reward.py``). A stop lasts 10-90 s (500-4500 steps): train with a
discount whose horizon covers it (gamma >= 0.999).

## Starting State

``reset(seed=..., options=...)`` draws a scenario from ``scenario`` (``ScenarioConfig``: rails
and their weights, speeds 40 km/h to the vehicle's maximum, load 0.85-1.15, pads 0.9-1.1,
gradient +-5 per mille, 70 % emergency demand), then the rail's adhesion level and pattern from
``configs/rails.yaml``. ``options`` fixes any drawn parameter: ``speed_kmh``, ``rail``,
``mu_contaminated``, ``pattern``, ``load_factor``, ``pad_factor``, ``gradient_permille``,
``demand`` (``"emergency"`` / ``"service"``), ``sections``, ``axle_mu_factor``,
``recovery_basis``, ``background``, ``extra_brake_force_N``, and the stop's sensor errors
``accelerometer_bias_mps2`` (exact, m/s^2) and ``wheel_speed_noise_kmh``. The train starts at that speed,
every wheel rolling, cylinders empty, the demand rising after the brake's delay. ``info`` holds
``"scenario"``.

## Episode End

``terminated`` at standstill; ``truncated`` after ``max_episode_steps = ceil(max_time_s /
control_period_s)`` steps (15,000 by default, 30,000 for the benchmark ids; counted, so the
float sum of the simulated time cannot add a step). ``info["metrics"]`` at the end carries the
run's metrics (``core.metrics.run_metrics``: stopping distance and time, sliding energy per
axle, locks, air, ...). The vector class steps all environments in one compiled call and
autoresets in the same step (``AutoresetMode.SAME_STEP``): an ended environment's last
observation and info are in ``info["final_obs"]`` / ``info["final_info"]`` (masks
``_final_obs`` / ``_final_info``).

The limit is the environment's own, not a ``TimeLimit`` wrapper's (which would end a stop
without its ``metrics``): the registered ids carry no ``max_episode_steps``, and the spec that
``gymnasium.make`` / ``make_vec`` give the made environment carries its limit
(``gymnasium.make("WSPBraking-v0").spec.max_episode_steps == 15000``; with ``max_time_s=60``,
3000). ``gymnasium.make(env.spec)`` then adds a ``TimeLimit`` that truncates on the same step
as the environment, so the final ``info`` is the environment's, with ``metrics``. A shorter
limit through ``gymnasium.make(..., max_episode_steps=N)`` is a ``TimeLimit`` the environment
cannot see (gymnasium does not pass ``N`` on): its truncating step's ``info`` has no
``metrics``. Give ``max_time_s=N * control_period_s`` instead (the environment then truncates
itself at step ``N``, with them), or read ``env.unwrapped.core.episode_info(0)``. The vector
class takes ``max_episode_steps=N`` itself (``gymnasium.make_vec`` passes it on).

## Action repeat

``action_repeat=k`` (1-50) makes one step ``k`` control periods: the action is held for ``k``
periods while sensors, the shared estimator, the watchdog and the valves go on at
``control_period_s``; the reward is the sum of the ``k`` periods' rewards (and
``info["reward_terms"]`` their sums); the observation is the last period's. A decision every
60-100 ms (``k`` = 3-5) matches the pneumatics' time scale, where a 20 ms decision is mostly
filtered out. A stop that ends within a step ends there: the step returns its last
observation and ``metrics`` (the vector class autoresets after the step). The step limit is
``ceil(ceil(max_time_s / control_period_s) / k)``; a learner's discount per step should be
``gamma ** k`` of the per-period one. A trained model remembers its ``action_repeat`` (its
config) and, evaluated on the 20 ms core, decides every ``k`` periods and holds its action in
between (``policy.SB3Policy``), so the benchmark scores it with the same sensors and watchdog.

## Arguments

``gymnasium.make("WSPBraking-v0", **kwargs)``, ``gymnasium.make_vec("WSPBraking-v0",
num_envs=N, **kwargs)``:

| parameter | type | default | description |
|---|---|---|---|
| ``vehicle`` | str or VehicleConfig | ``"uic_z1"`` | a ``configs/vehicles`` id or YAML path |
| ``action_mode`` | str | ``"continuous"`` | ``continuous``, ``discrete`` or ``residual`` (Action Space) |
| ``residual_scale`` | float | ``1.0`` | residual mode: how far the action moves the classical request, (0, 1] |
| ``residual_deadband`` | float | ``0.0`` | residual mode: residuals up to this size are zero, [0, 1) |
| ``valve_group`` | str or None | None | ``axle`` or ``bogie``; None: the vehicle config's |
| ``privileged`` | bool | False | append true speed, friction levels and creepage (an oracle's view) |
| ``accelerometer`` | bool | False | the WSP has a body accelerometer (observed; aids the reference) |
| ``accelerometer_bias_mps2`` | float or None | None | its bias is drawn per episode within +- this (None: ``sensors``', 0.05) |
| ``sensors`` | SensorConfig or dict | ideal wheel sensors | the sensor model (Observation Space) |
| ``estimator`` | EstimatorConfig or dict | defaults | the shared reference-speed estimator |
| ``watchdog`` | WatchdogConfig or dict | on | the safety watchdog (Safety watchdog) |
| ``reward`` | RewardConfig or dict | defaults | the reward's exchange rates (Rewards) |
| ``scenario`` | ScenarioConfig or dict | defaults | what ``reset`` draws from (Starting State) |
| ``rails_config`` | str or None | None | a rails YAML instead of ``configs/rails.yaml`` |
| ``extra_rails`` | dict or None | None | further ``RailConfig`` objects by name |
| ``control_period_s`` | float | ``0.02`` | the BCU cycle: sensors, estimator, watchdog and valves run at it |
| ``action_repeat`` | int | ``1`` | control periods per step (Action repeat): a decision every ``action_repeat * control_period_s`` |
| ``slip_target_min_kmh`` | float | ``0.5`` | slip-target mode: the target of action -1, km/h, [0, 30] (0 lets the watchdog in: Action Space) |
| ``slip_target_max_kmh`` | float | ``8.0`` | slip-target mode: the target of action +1, km/h, above the minimum, at most 30 |
| ``slip_target_gain_per_kmh`` | float | ``0.2`` | slip-target mode: the inner loop's demand fraction per km/h of slip error, (0, 10] |
| ``slip_target_lead_s`` | float | ``0.1`` | slip-target mode: the inner loop's lead on the measured wheel deceleration, s, [0, 1] |
| ``slip_target_release`` | str | ``"working"`` | slip-target mode: when the inner loop's periodic release may begin: ``working``, only while the loop works (some axle asked for under the full demand in the last period, or a wheel's measured slip is beyond the estimator's working band), as the classical WSP; ``always``, whenever the reference's age allows (the loop before 2026-11-27; a policy file that does not name it loads with it) |
| ``slip_target_max_creep`` | float | ``0.2`` | slip-target mode: each target at most this fraction of the reference speed, or 2 km/h where that is more (a lower target is kept; a target fixed in km/h grows into a near-lock as the train slows), [0, 1]; 0: no cap (the loop before 2026-11-27's cap; a policy file that does not name it loads with 0) |
| ``slip_target_drift_correction`` | bool | ``False`` | slip-target mode, ``wheels+accel`` tier (an error without the accelerometer): the loop tracks the slip against the aided reference less the drift its last anchor showed and the estimator did not learn (``baselines/slip_target.py``; docs/training_log.md, "The slip-target loop's drift correction"); a policy file that does not name it loads with ``False`` |
| ``slip_target_gain_scale_floor`` | float | ``1.0`` | slip-target mode: the loop's gain is ``slip_target_gain_per_kmh`` times the pressure the axle holds over the demand, never below this share of it, (0, 1]; 1: a fixed gain (the loop before 2026-11-28; a policy file that does not name it loads with 1). With 0.25 and a gain of 0.8 per km/h low targets stop about 1 % shorter on leaves and oil, but the valves work harder on soap (73 % more air) and the score falls (docs/training_log.md, "The slip-target loop's gain scaled by the pressure held") |
| ``slip_target_onset_drift`` | bool | ``False`` | slip-target mode, with ``slip_target_drift_correction`` (an error without it): the loop reads the accelerometer's offset while every cylinder is still under its brake's threshold at the stop's start (the wheels' mean deceleration against the mean reading) and takes the drift it carries the aided reference above the train away until the first anchor whose jump it reads (docs/training_log.md, "The onset reading of the accelerometer's offset"); a policy file that does not name it loads with ``False`` |
| ``slip_target_scale_calibration`` | bool | ``False`` | slip-target mode, either tier: the loop reads each wheel-speed sensor's scale against the wheels' mean while every cylinder is still under its brake's threshold at the stop's start (every wheel rolls with the train) and divides it out of the wheels' readings and the estimator's reference (a BCU's wheel-diameter calibration; docs/training_log.md, "The wheel-scale calibration"); a policy file that does not name it loads with ``False`` |
| ``slip_target_onset_two_sided`` | bool | ``False`` | slip-target mode, with ``slip_target_onset_drift`` (an error without it): the onset reading corrects its other sense too, a reading of too much deceleration (a downhill's ``g sin(theta)``, a positive bias), which carries the aided reference below the train; every drift downward, this reading's or one read from an anchor's jump, raises the tracked reference only for the time no wheel has held the estimator's reference up (within 0.1 km/h of the fastest reading) since the last anchor (docs/training_log.md, "The onset reading's other sense"); a policy file that does not name it loads with ``False`` |
| ``slip_target_lock_guard`` | bool | ``False`` | slip-target mode, either tier: below 15 km/h, on a stop where a wheel has slipped beyond the estimator's working band and the reference has slowed at under 0.85 m/s^2 on average (a low-adhesion rail), every valve asks for at most 0.8 of the demand (from 6 s into a stop), so that a wheel meeting a contaminated patch at low speed locks for less time while its cylinder vents (``baselines/slip_target.py``, ``LOCK_GUARD_*``; thresholds chosen on the Régiolis; docs/training_log.md, "The lock guard, and a creep schedule for the Régiolis's leaves teacher"); a policy file that does not name it loads with ``False`` |
| ``stagger_reset_steps`` | int | ``0`` | vector class only (the single class takes only 0), a training option: ``reset`` advances each environment a random, seeded number of steps below this into a stop, driven by the classical WSP, so that stops do not all end together (``WSPBrakingVectorEnv``'s docstring); 0: off |
| ``memory_features`` | bool | False | append the memory features (Observation Space): per axle time in the current slide, time since the last release, sliding-energy estimate |
| ``memory_target_mean`` | bool | False | slip-target mode (an error in the others): append each valve's mean slip-target action over the stop so far (Observation Space); a policy file that does not name it loads with ``False`` |
| ``substep_s`` | float | ``0.001`` | the physics substep (linearly implicit; docs/physics.md) |
| ``max_time_s`` | float | ``300.0`` | truncation after ``ceil(max_time_s / control_period_s)`` steps (Episode End) |
| ``render_mode`` | str or None | None | ``"rgb_array"``: ``render()`` returns a frame, ``(480, 640, 3)`` uint8, of the last 10 s (wheel speeds against the train and the reference, slips, cylinder pressures against the demand; one figure reused, > 50 frames/s); ``"human"``: the same in a matplotlib window, updated at every step (with a non-interactive backend, e.g. ``MPLBACKEND=Agg`` or no display, drawn but not shown); ``wsp_env.envs.rendering`` |

## Version History

* v0: the first registered version: continuous and discrete valve actions, the residual mode
  on the frozen classical WSP (with ``residual_scale`` / ``residual_deadband``), the optional
  body accelerometer, privileged observations, distance-damage-lock-air reward with optional
  potential-based shaping and slide pricing; single and native vector entry points.
* v1 (2026-11-25; ``WSPBraking-v0``'s arguments changed with it, the benchmark's ids are
  ``-v1``): one sensor model for every controller (wheel speeds are readings, with optional
  resolution, noise and scale error; the accelerometer has noise and lag besides bias and
  gradient); one reference-speed estimator shared with the classical WSP (adaptive slope,
  anchors on free-rolling wheels both ways: it can no longer drift above the train
  uncorrected); the reference's age is observed (``obs_dim`` + 1); the safety watchdog acts on
  every controller; the benchmark ids fix vehicle, sensor tier, sensor errors, the scenario
  distribution (gradients +-25 per mille, every rail, load, pads, speeds 40 km/h to the
  maximum), reward, watchdog and timing.
* v1, later the same day (no new version: no scenario, observation or reward changed):
  truncation is counted, after exactly ``ceil(max_time_s / control_period_s)`` steps (it came
  one step later where the simulated time's float sum fell short of ``max_time_s``: 15,001
  steps at 300 s); the made environment's ``spec.max_episode_steps`` is that limit; the
  ``human`` render mode, and frames of the last 10 s on one reused figure; ``action_repeat``
  (default 1: unchanged); the ``slip_target`` action mode and ``memory_features`` (off by
  default: unchanged).
* v2 (2026-11-27; the benchmark's ids are ``-v2``, ``-v1`` stays registered and reproduces
  every earlier result): the safety watchdog's minimum-deceleration override gives way once
  every axle has read locked under its full demand for 0.2 s (``WatchdogConfig.
  give_way_locked_s``; ``-v1`` sets it to 0). Before, every axle sliding together at a rail's
  limit could trip the supervision (on the wheels alone that looks like grip) and its full
  demand then locked every axle to standstill: on a leaves stop at -18 per mille one policy's
  train ran 16.5 km in the 600 s limit with the override standing, 4.6 km with it giving way. Only stops where that override tripped change; ``info["metrics"]
  ["watchdog"]`` gains ``gave_way``. ``WSPBraking-v0``'s default watchdog changed with it.
* v3 (2026-11-27, later; the benchmark's ids are ``-v3``, ``-v1`` and ``-v2`` stay registered
  and reproduce every earlier result): two changes to the shared reference-speed estimator
  (``EstimatorConfig``; ``-v1`` and ``-v2`` set both to 0). Its spin-up test reads each
  wheel's acceleration filtered over 0.1 s (``free_roll_filter_s``): on one 20 ms reading a
  wheel spinning up slowly on leaves passed as free-rolling now and then, the reference was
  set to it far below the train, and nothing lifted it again (the classical WSP's longest lock
  on the development stops was 578.6 s). With the accelerometer, it learns the sensor's offset
  (bias and gradient) at each free-roll anchor (``accel_offset_gain``): the aided reference
  had run above the train by the offset's integral between anchors. The observation's layout
  is unchanged (the accelerometer entry is the raw reading); the state arrays gain columns, so
  an environment checkpoint from before is refused. ``WSPBraking-v0``'s default estimator
  changed with it.
* v3, 2026-11-27 (no new version: the benchmark's ids fix nothing of the slip-target loop, a
  policy chooses it as it chooses ``slip_target_lead_s``): the slip-target loop's periodic
  release begins only while the loop works (``slip_target_release="working"``, the new
  default; ``"always"`` is the loop before). The loop asks for under the demand while the
  cylinders fill at a stop's onset, the estimator then counts the reference's age, and on a
  stop where no wheel slides nothing re-anchors it: the ungated loop released one axle after
  another every 3 s of a train whose wheels all gripped (dry, 80 km/h, 3 km/h: 221.0 m against
  207.8 m). A policy file that does not name the gate was written before it and loads with
  ``"always"``; files written since name it.
* v3, 2026-11-27, later (no new version, as above): the slip-target loop caps each target
  at 20 % of the reference speed, never below 2 km/h (``slip_target_max_creep=0.2``, the new
  default; 0 is the loop before): a target fixed in km/h became a creep near locking as the
  train slowed (an 8 km/h target at 10 km/h), and on the UIC-Z1's development stops an 8 km/h
  target's longest lock was 13.5 s. A policy file that does not name the cap was written
  before it and loads with 0; files written since name it.
* v3, 2026-11-28 (no new version, as above; off by default, so no stop moves): the
  slip-target loop may correct the aided reference's drift from its anchors
  (``slip_target_drift_correction=True``, ``wheels+accel`` only). A policy file that does not
  name it loads with ``False``.
* v3, 2026-11-28, later (no new version, as above; off by default): the slip-target loop's gain
  may be scaled by the pressure held (``slip_target_gain_scale_floor`` below 1). A policy
  file that does not name it loads with 1, a fixed gain.
* v3, 2026-11-28, later still (no new version; only the drift-corrected loop changes): with
  ``slip_target_drift_correction`` the loop holds its reference deceleration (the lead term's)
  through every anchor it reads, where before an anchor right after another read as a fall.
  The few model files made with the correction before it load with the mended loop (constant
  targets on the development stops moved by at most −0.0004 in score, paired).
* v3, 2026-11-28, last (no new version; off by default): the drift-corrected loop may read the
  accelerometer's offset at the stop's onset (``slip_target_onset_drift``). A policy file that
  does not name it loads with ``False``.
* v3, 2026-12-06 (no new version; off by default): the slip-target loop may calibrate the
  wheel-speed sensors' scales at the stop's onset (``slip_target_scale_calibration``). A
  policy file that does not name it loads with ``False``.
* v3, 2026-12-07 (no new version; off by default): the onset reading may correct both senses
  of the accelerometer's offset (``slip_target_onset_two_sided``). A policy file that does not
  name it loads with ``False``.
* v3, 2026-12-07 (no new version; off by default, the observation unchanged without it): the
  stop's mean slip target may be observed (``memory_target_mean``, slip-target mode). A policy
  file that does not name it loads with ``False``.
* v3, 2026-12-07, later (no new version; only with ``slip_target_onset_two_sided``): the
  tracked reference's drop when a wheel holds the estimator's reference again is no longer
  read as the reference's deceleration by the loop's lead term (figures of the option moved by
  decimetres a stop; docs/training_log.md, "The onset reading's other sense").
* v3, 2026-12-08 (no new version; off by default): the slip-target loop may cap its requests at
  low speed on a low-adhesion stop (``slip_target_lock_guard``). A policy file that does not
  name it loads with ``False``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from wsp_env.baselines.slip_target import (
    DEFAULT_DRIFT_CORRECTION,
    DEFAULT_GAIN_PER_KMH,
    DEFAULT_GAIN_SCALE_FLOOR,
    DEFAULT_LOCK_GUARD,
    DEFAULT_MAX_CREEP,
    DEFAULT_ONSET_DRIFT,
    DEFAULT_ONSET_TWO_SIDED,
    DEFAULT_RELEASE,
    DEFAULT_SCALE_CALIBRATION,
)
from wsp_env.core import kernel as K
from wsp_env.core.braking import TERM_NAMES, BrakingCore, RewardConfig, ScenarioConfig
from wsp_env.core.config import RailConfig, VehicleConfig
from wsp_env.core.sensors import EstimatorConfig, SensorConfig, WatchdogConfig
from wsp_env.envs.rendering import FrameRenderer, RenderHistory


def make_core(n_envs: int, **kwargs: Any) -> BrakingCore:
    """A :class:`BrakingCore` of ``n_envs`` environments with ``WSPBrakingEnv``'s arguments; with
    ``action_mode="residual"`` the frozen classical WSP of the sensor tier
    (``configs/wsp/classical.yaml``, with ``accelerometer`` ``classical_accel.yaml``) is the
    controller the residual acts on; with ``action_mode="slip_target"`` the slip-target inner
    loop (``baselines.slip_target.SlipTargetLoop``, with ``slip_target_gain_per_kmh``,
    ``slip_target_lead_s``, ``slip_target_release``, ``slip_target_max_creep``,
    ``slip_target_drift_correction``, ``slip_target_gain_scale_floor``,
    ``slip_target_onset_drift``, ``slip_target_scale_calibration``,
    ``slip_target_onset_two_sided`` and ``slip_target_lock_guard``, on the same tier's
    classical thresholds) tracks the targets."""
    from wsp_env.baselines.slip_target import (
        SlipTargetLoop,
        check_drift_correction,
        check_gain_scale_floor,
        check_lock_guard,
        check_loop_args,
        check_max_creep,
        check_onset_drift,
        check_onset_two_sided,
        check_release,
        check_scale_calibration,
    )

    # the loop's own arguments: checked in every mode (as residual_scale is), used in one
    gain, lead = check_loop_args(
        kwargs.pop("slip_target_gain_per_kmh", DEFAULT_GAIN_PER_KMH),
        kwargs.pop("slip_target_lead_s", 0.1),
    )
    release = check_release(kwargs.pop("slip_target_release", DEFAULT_RELEASE))
    max_creep = check_max_creep(kwargs.pop("slip_target_max_creep", DEFAULT_MAX_CREEP))
    drift = check_drift_correction(
        kwargs.pop("slip_target_drift_correction", DEFAULT_DRIFT_CORRECTION)
    )
    floor = check_gain_scale_floor(
        kwargs.pop("slip_target_gain_scale_floor", DEFAULT_GAIN_SCALE_FLOOR)
    )
    onset = check_onset_drift(kwargs.pop("slip_target_onset_drift", DEFAULT_ONSET_DRIFT), drift)
    calibrate = check_scale_calibration(
        kwargs.pop("slip_target_scale_calibration", DEFAULT_SCALE_CALIBRATION)
    )
    two_sided = check_onset_two_sided(
        kwargs.pop("slip_target_onset_two_sided", DEFAULT_ONSET_TWO_SIDED), onset
    )
    guard = check_lock_guard(kwargs.pop("slip_target_lock_guard", DEFAULT_LOCK_GUARD))
    mode = kwargs.get("action_mode")
    if mode in ("residual", "slip_target"):
        from wsp_env.baselines.classical import ClassicalWSP, accelerometer_tier, load_wsp_config

        tier = accelerometer_tier(bool(kwargs.get("accelerometer")))
        if mode == "residual":
            kwargs.setdefault("residual_base", ClassicalWSP(load_wsp_config(tier=tier)))
        else:
            loop = SlipTargetLoop(
                load_wsp_config(tier=tier),
                gain_per_kmh=gain,
                lead_s=lead,
                release=release,
                max_creep=max_creep,
                drift_correction=drift,
                gain_scale_floor=floor,
                onset_drift=onset,
                scale_calibration=calibrate,
                onset_two_sided=two_sided,
                lock_guard=guard,
            )
            kwargs.setdefault("slip_target_loop", loop)
    return BrakingCore(n_envs, **kwargs)


def episode_step_limit(max_time_s: float, control_period_s: float) -> int:
    """The steps after which a stop is truncated: ``max_time_s / control_period_s``, rounded up
    (counted, so that it does not depend on how the simulated time's float sum rounds)."""
    return math.ceil(round(max_time_s / control_period_s, 9))


ACTION_REPEAT_MAX = 50
STAGGER_RESET_MAX = 100_000


def _check_int(value: Any, name: str, low: int, high: int) -> int:
    """``value`` as an int in ``low``-``high``, or a one-line ``ValueError`` naming ``name``."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int | np.integer)
        or not low <= value <= high
    ):
        raise ValueError(f"{name}: must be an integer {low}-{high}, got {value!r}")
    return int(value)


def check_action_repeat(action_repeat: Any) -> int:
    """``action_repeat`` as an int in 1-``ACTION_REPEAT_MAX``, or a one-line ``ValueError``."""
    return _check_int(action_repeat, "action_repeat", 1, ACTION_REPEAT_MAX)


def check_stagger_reset_steps(steps: Any) -> int:
    """``stagger_reset_steps`` as an int in 0-``STAGGER_RESET_MAX``, or a one-line
    ``ValueError``."""
    return _check_int(steps, "stagger_reset_steps", 0, STAGGER_RESET_MAX)


def _spec_with_limit(spec: EnvSpec | None, max_episode_steps: int) -> EnvSpec | None:
    """``spec`` (what ``gymnasium.make`` / ``make_vec`` set) with the environment's own step
    limit where it has none (no ``TimeLimit`` is involved: the environment truncates itself)."""
    if spec is None or spec.max_episode_steps is not None:
        return spec
    return dataclasses.replace(spec, max_episode_steps=max_episode_steps)


class WSPBrakingEnv(gym.Env):
    __doc__ = __doc__
    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["human", "rgb_array"], "render_fps": 50}
    _spec: EnvSpec | None = None

    def __init__(
        self,
        render_mode: str | None = None,
        vehicle: str | VehicleConfig = "uic_z1",
        action_mode: str = "continuous",
        residual_scale: float = 1.0,
        residual_deadband: float = 0.0,
        valve_group: str | None = None,
        privileged: bool = False,
        accelerometer: bool = False,
        accelerometer_bias_mps2: float | None = None,
        sensors: SensorConfig | dict | None = None,
        estimator: EstimatorConfig | dict | None = None,
        watchdog: WatchdogConfig | dict | None = None,
        reward: RewardConfig | dict | None = None,
        scenario: ScenarioConfig | dict | None = None,
        rails_config: str | None = None,
        extra_rails: dict[str, RailConfig] | None = None,
        control_period_s: float = 0.02,
        substep_s: float = 1e-3,
        max_time_s: float = 300.0,
        action_repeat: int = 1,
        slip_target_min_kmh: float = 0.5,
        slip_target_max_kmh: float = 8.0,
        slip_target_gain_per_kmh: float = DEFAULT_GAIN_PER_KMH,
        slip_target_lead_s: float = 0.1,
        slip_target_release: str = DEFAULT_RELEASE,
        slip_target_max_creep: float = DEFAULT_MAX_CREEP,
        slip_target_drift_correction: bool = DEFAULT_DRIFT_CORRECTION,
        slip_target_gain_scale_floor: float = DEFAULT_GAIN_SCALE_FLOOR,
        slip_target_onset_drift: bool = DEFAULT_ONSET_DRIFT,
        slip_target_scale_calibration: bool = DEFAULT_SCALE_CALIBRATION,
        slip_target_onset_two_sided: bool = DEFAULT_ONSET_TWO_SIDED,
        slip_target_lock_guard: bool = DEFAULT_LOCK_GUARD,
        memory_features: bool = False,
        memory_target_mean: bool = False,
        stagger_reset_steps: int = 0,
    ) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode: {render_mode!r} (supported: human, rgb_array)")
        self.action_repeat = check_action_repeat(action_repeat)
        # the vector class's option, accepted here only as 0 (off), so a configuration that
        # sets it for a single environment (gymnasium.make, make_vec's sync and async modes)
        # is told so in one line
        if check_stagger_reset_steps(stagger_reset_steps) > 0:
            raise ValueError(
                f"stagger_reset_steps: a vector-environment option (WSPBrakingVectorEnv; "
                f'gymnasium.make_vec(..., vectorization_mode="vector_entry_point")): one '
                f"environment has no batch to stagger, got {stagger_reset_steps!r}"
            )
        self.render_mode = render_mode
        self.core = make_core(
            1, vehicle=vehicle, action_mode=action_mode, residual_scale=residual_scale,
            residual_deadband=residual_deadband, valve_group=valve_group, privileged=privileged,
            accelerometer=accelerometer, accelerometer_bias_mps2=accelerometer_bias_mps2,
            sensors=sensors, estimator=estimator, watchdog=watchdog, reward=reward, scenario=scenario, rails_config=rails_config, extra_rails=extra_rails,
            control_period_s=control_period_s, substep_s=substep_s, max_time_s=max_time_s,
            slip_target_min_kmh=slip_target_min_kmh, slip_target_max_kmh=slip_target_max_kmh,
            slip_target_gain_per_kmh=slip_target_gain_per_kmh,
            slip_target_lead_s=slip_target_lead_s, slip_target_release=slip_target_release,
            slip_target_max_creep=slip_target_max_creep,
            slip_target_drift_correction=slip_target_drift_correction,
            slip_target_gain_scale_floor=slip_target_gain_scale_floor,
            slip_target_onset_drift=slip_target_onset_drift,
            slip_target_scale_calibration=slip_target_scale_calibration,
            slip_target_onset_two_sided=slip_target_onset_two_sided,
            slip_target_lock_guard=slip_target_lock_guard,
            memory_features=memory_features, memory_target_mean=memory_target_mean,
        )  # fmt: skip
        self.action_space = self.core.action_space()
        self.observation_space = self.core.observation_space()
        # the stop's limit in control periods, and in steps of action_repeat periods
        self.period_limit = episode_step_limit(max_time_s, control_period_s)
        self.max_episode_steps = math.ceil(self.period_limit / self.action_repeat)
        self.elapsed_steps = 0
        self.elapsed_periods = 0
        # rendering: the recent history a frame shows (kept only with a render_mode: nothing
        # otherwise) and the figure it is drawn on (``wsp_env.envs.rendering``)
        self.render_history: RenderHistory | None = None
        self.renderer: FrameRenderer | None = None
        if render_mode is not None:
            self.render_history = RenderHistory(self.core)
            self.renderer = FrameRenderer(
                self.core, self.render_history, human=render_mode == "human"
            )

    @property
    def spec(self) -> EnvSpec | None:
        """The spec ``gymnasium.make`` set, its ``max_episode_steps`` this environment's own
        limit (``max_episode_steps``: ``max_time_s / control_period_s``) unless a ``TimeLimit``
        gave one."""
        return self._spec

    @spec.setter
    def spec(self, spec: EnvSpec | None) -> None:
        self._spec = _spec_with_limit(spec, self.max_episode_steps)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.core.rngs[0] = self.np_random
        info = self.core.reset_env(0, options)
        self.elapsed_steps = 0
        self.elapsed_periods = 0
        if self.render_history is not None:
            self.render_history.clear(0)
            self.render_history.record()
            if self.render_mode == "human":
                self.renderer.draw(0)
        return self.core.obs[0].copy(), info

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        core = self.core
        a = core.check_actions(np.reshape(action, (1, -1)) if np.ndim(action) == 1 else action)
        terms = None
        clipped = 0
        terminated = truncated = False
        for _ in range(self.action_repeat):  # the action held for action_repeat periods
            core.step(a)
            period = core.terms[0]
            terms = period.copy() if terms is None else terms + period
            core.episode_return[0] += float(period.sum())
            core.episode_terms[0] += period
            clipped += int(core.flags[0, K.F_CLIPPED])
            self.elapsed_periods += 1
            terminated = bool(core.flags[0, K.F_TERMINATED])
            truncated = not terminated and (
                self.elapsed_periods >= self.period_limit or bool(core.flags[0, K.F_TRUNCATED])
            )
            if self.render_history is not None:
                self.render_history.record()
            if terminated or truncated:
                break
        self.elapsed_steps += 1
        reward = float(terms.sum())
        info: dict[str, Any] = {
            "reward_terms": dict(zip(TERM_NAMES, terms.tolist(), strict=True)),
            "action_clipped": clipped,
        }
        if terminated or truncated:
            info["metrics"] = core.episode_info(0)
        if self.render_mode == "human":
            self.renderer.draw(0)
        return core.obs[0].copy(), reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        """``rgb_array``: the current frame, ``(480, 640, 3)`` uint8; ``human``: draws it into
        the window (each step does too) and returns None; no ``render_mode``: None."""
        if self.renderer is None:
            return None
        if self.render_mode == "rgb_array":
            return self.renderer.frame(0)
        self.renderer.draw(0)
        return None

    def close(self) -> None:
        """Close the rendering figure, if one was made."""
        if self.renderer is not None:
            self.renderer.close()


class WSPBrakingVectorEnv(VectorEnv):
    """``num_envs`` environments stepped by one compiled call; same-step autoreset. Arguments
    as ``WSPBrakingEnv`` (module docstring) plus ``num_envs`` and ``max_episode_steps``: a step
    limit (what ``gymnasium.make_vec`` passes on); without ``max_time_s`` it sets
    ``max_time_s = max_episode_steps * control_period_s``, with both the earlier truncates.
    ``render_mode``: ``"rgb_array"`` only (one frame per environment, drawn in turn on one
    figure).

    ``stagger_reset_steps=K`` (0, off, by default; at most ``STAGGER_RESET_MAX``): a training
    option. Environments reset together would end their stops together, and a learning curve
    of the episodes that ended is then length-biased (short stops first). With ``K > 0``
    every ``reset`` then advances environment ``i`` ``k_i`` steps (``k_i action_repeat``
    control periods) into a stop, ``k_i`` uniform in ``0 .. K-1``, drawn from ``reset``'s seed
    (reproducible with one; its own generator, so each environment's scenarios are still drawn
    from its seed): the batch is stepped ``max(k)`` times and environment ``i``'s stop starts
    anew (its next scenario, ``options`` as given) ``max(k) - k_i`` steps in, stops that end in
    between autoresetting as in any step. The warm-up is driven period by period by the
    classical WSP of the sensor tier (``continuous``; ``discrete``: its vent / hold / fill;
    ``residual``: the zero residual, which is it; ``slip_target``: the zero action, the middle
    target, run by the inner loop), exactly the stop that controller gives from the start, so
    no stop starts from a state a controller would never leave; the residual's classical WSP
    and the slip-target loop advance once per period in it, as in any step. The returned
    observation and ``info["scenario"]`` are where each environment stands; ``episode_steps``
    counts its steps into the stop, and its return so far is in the core's
    ``episode_return`` (``SB3VecEnv`` leaves it out of its first episode's statistics). It
    costs ``max(k)`` batched steps per ``reset`` (a stop is 500-4,500 steps: ``K`` about
    2,000 spreads them)."""

    metadata: ClassVar[dict[str, Any]] = {
        "render_modes": ["rgb_array"],
        "render_fps": 50,
        "autoreset_mode": AutoresetMode.SAME_STEP,
    }
    _spec: EnvSpec | None = None

    def __init__(
        self,
        num_envs: int = 1,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        vehicle: str | VehicleConfig = "uic_z1",
        action_mode: str = "continuous",
        residual_scale: float = 1.0,
        residual_deadband: float = 0.0,
        valve_group: str | None = None,
        privileged: bool = False,
        accelerometer: bool = False,
        accelerometer_bias_mps2: float | None = None,
        sensors: SensorConfig | dict | None = None,
        estimator: EstimatorConfig | dict | None = None,
        watchdog: WatchdogConfig | dict | None = None,
        reward: RewardConfig | dict | None = None,
        scenario: ScenarioConfig | dict | None = None,
        rails_config: str | None = None,
        extra_rails: dict[str, RailConfig] | None = None,
        control_period_s: float = 0.02,
        substep_s: float = 1e-3,
        max_time_s: float | None = None,
        action_repeat: int = 1,
        slip_target_min_kmh: float = 0.5,
        slip_target_max_kmh: float = 8.0,
        slip_target_gain_per_kmh: float = DEFAULT_GAIN_PER_KMH,
        slip_target_lead_s: float = 0.1,
        slip_target_release: str = DEFAULT_RELEASE,
        slip_target_max_creep: float = DEFAULT_MAX_CREEP,
        slip_target_drift_correction: bool = DEFAULT_DRIFT_CORRECTION,
        slip_target_gain_scale_floor: float = DEFAULT_GAIN_SCALE_FLOOR,
        slip_target_onset_drift: bool = DEFAULT_ONSET_DRIFT,
        slip_target_scale_calibration: bool = DEFAULT_SCALE_CALIBRATION,
        slip_target_onset_two_sided: bool = DEFAULT_ONSET_TWO_SIDED,
        slip_target_lock_guard: bool = DEFAULT_LOCK_GUARD,
        memory_features: bool = False,
        memory_target_mean: bool = False,
        stagger_reset_steps: int = 0,
    ) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode: {render_mode!r} (supported: rgb_array)")
        self.action_repeat = check_action_repeat(action_repeat)
        self.stagger_reset_steps = check_stagger_reset_steps(stagger_reset_steps)
        if max_episode_steps is not None and (
            isinstance(max_episode_steps, bool)
            or not isinstance(max_episode_steps, int | np.integer)
            or max_episode_steps < 1
        ):
            raise ValueError(
                f"max_episode_steps: must be a positive integer, got {max_episode_steps!r}"
            )
        if max_time_s is None:
            steps = max_episode_steps
            max_time_s = 300.0 if steps is None else steps * self.action_repeat * control_period_s
        self.core = make_core(
            num_envs, vehicle=vehicle, action_mode=action_mode, residual_scale=residual_scale,
            residual_deadband=residual_deadband, valve_group=valve_group, privileged=privileged,
            accelerometer=accelerometer, accelerometer_bias_mps2=accelerometer_bias_mps2,
            sensors=sensors, estimator=estimator, watchdog=watchdog, reward=reward, scenario=scenario, rails_config=rails_config, extra_rails=extra_rails,
            control_period_s=control_period_s, substep_s=substep_s, max_time_s=max_time_s,
            slip_target_min_kmh=slip_target_min_kmh, slip_target_max_kmh=slip_target_max_kmh,
            slip_target_gain_per_kmh=slip_target_gain_per_kmh,
            slip_target_lead_s=slip_target_lead_s, slip_target_release=slip_target_release,
            slip_target_max_creep=slip_target_max_creep,
            slip_target_drift_correction=slip_target_drift_correction,
            slip_target_gain_scale_floor=slip_target_gain_scale_floor,
            slip_target_onset_drift=slip_target_onset_drift,
            slip_target_scale_calibration=slip_target_scale_calibration,
            slip_target_onset_two_sided=slip_target_onset_two_sided,
            slip_target_lock_guard=slip_target_lock_guard,
            memory_features=memory_features, memory_target_mean=memory_target_mean,
        )  # fmt: skip
        self.num_envs = num_envs
        self.render_mode = render_mode
        self.single_action_space = self.core.action_space()
        self.single_observation_space = self.core.observation_space()
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        # the stop's limit in control periods and in steps (of action_repeat periods)
        self.period_limit = episode_step_limit(max_time_s, control_period_s)
        limit = math.ceil(self.period_limit / self.action_repeat)
        if max_episode_steps is not None:
            limit = min(limit, int(max_episode_steps))
            self.period_limit = min(self.period_limit, limit * self.action_repeat)
        self.max_episode_steps = limit
        self.episode_steps = np.zeros(num_envs, dtype=np.int64)  # steps of each env's stop
        self.episode_periods = np.zeros(num_envs, dtype=np.int64)  # its control periods
        self.render_history: RenderHistory | None = None
        self.renderer: FrameRenderer | None = None
        if render_mode is not None:
            self.render_history = RenderHistory(self.core)
            self.renderer = FrameRenderer(self.core, self.render_history)

    @property
    def spec(self) -> EnvSpec | None:
        """The spec ``gymnasium.make_vec`` set, its ``max_episode_steps`` this environment's
        step limit (``max_episode_steps``) where the registration gives none."""
        return self._spec

    @spec.setter
    def spec(self, spec: EnvSpec | None) -> None:
        self._spec = _spec_with_limit(spec, self.max_episode_steps)

    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | list[dict[str, Any] | None] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start every environment anew: ``seed`` an int (env ``i`` gets ``seed + i``) or one
        per environment; ``options`` one dict for all, or a list with one per environment."""
        if isinstance(seed, int):
            seeds: list[int | None] = [seed + i for i in range(self.num_envs)]
        elif seed is None:
            seeds = [None] * self.num_envs
        else:
            if len(seed) != self.num_envs:
                raise ValueError(f"seed: {len(seed)} seeds for {self.num_envs} environments")
            seeds = list(seed)
        if isinstance(options, list | tuple):
            if len(options) != self.num_envs:
                raise ValueError(f"options: {len(options)} dicts for {self.num_envs} environments")
            each = list(options)
        else:
            each = [options] * self.num_envs
        for i, s in enumerate(seeds):
            self.core.rngs[i] = seeding.np_random(s)[0]
        scenarios = [self.core.reset_env(i, each[i])["scenario"] for i in range(self.num_envs)]
        self.episode_steps[:] = 0
        self.episode_periods[:] = 0
        if self.render_history is not None:
            self.render_history.clear(slice(None))
            self.render_history.record()
        if self.stagger_reset_steps > 0:
            known = seeds if all(s is not None for s in seeds) else None
            self._stagger(np.random.default_rng(known), each)
            scenarios = [self.core.describe(i) for i in range(self.num_envs)]
        return self.core.obs.copy(), {"scenario": np.array(scenarios, dtype=object)}

    def _stagger(self, rng: np.random.Generator, options: list[dict[str, Any] | None]) -> None:
        """``stagger_reset_steps``: advance environment ``i`` ``k_i`` steps into a stop
        (class docstring), driven period by period by the tier's classical WSP."""
        from wsp_env.baselines.classical import ClassicalWSP

        core, n = self.core, self.num_envs
        offsets = rng.integers(0, self.stagger_reset_steps, size=n)
        total = int(offsets.max())
        start_at = total - offsets  # the warm-up step at which environment i starts anew
        driver = None
        if core.action_mode in ("continuous", "discrete"):
            driver = ClassicalWSP()  # the core's tier's frozen thresholds, taken at bind
            driver.bind(core)
            driver.reset(np.arange(n))
        for t in range(1, total + 1):
            self._warm_step(driver, np.flatnonzero(start_at == t), options)

    def _warm_step(
        self, driver: Any, fresh: np.ndarray, options: list[dict[str, Any] | None]
    ) -> None:
        """One step of the staggered warm-up: ``action_repeat`` control periods, each driven by
        ``driver`` (the classical WSP, on every period's observation, as its timers assume; in
        the residual and slip-target modes the zero action: the classical WSP itself, the
        middle target), a stop that ends within them held where it ended (``freeze``) and
        started anew at the step's end, as ``step`` does, with nothing recorded of it; then
        environments ``fresh`` start their stop (``options``). Every reset comes before anything
        reads the observation, as an autoreset does, so the residual's base or the slip-target
        loop advances exactly once in each period (``BrakingCore.obs``)."""
        core, n = self.core, self.num_envs
        zeros = np.zeros((n, core.n_valves))
        done = np.zeros(n, dtype=bool)
        for _ in range(self.action_repeat):
            if driver is None:
                a = zeros
            else:
                a = driver.act(core.obs).astype(np.float64)
                if core.action_mode == "discrete":  # vent -1, apply +1, anything between a hold
                    a = np.where(a <= -1.0, 0.0, np.where(a >= 1.0, 2.0, 1.0))
            core.step(a)
            live = ~done
            period = np.where(live[:, None], core.terms, 0.0)
            core.episode_return += period.sum(axis=1)
            core.episode_terms += period
            self.episode_periods += live
            end = live & (
                core.flags[:, K.F_TERMINATED].astype(bool)
                | core.flags[:, K.F_TRUNCATED].astype(bool)
                | (self.episode_periods >= self.period_limit)
            )
            for e in np.flatnonzero(end):
                core.freeze(int(e))
            done |= end
            if done.all():
                break
        self.episode_steps += 1
        done[fresh] = False  # their stop starts anew below, with its options
        for e in np.flatnonzero(done):
            core.reset_env(int(e), None)
        for e in fresh:
            core.reset_env(int(e), options[e])
        self._started_anew(np.union1d(np.flatnonzero(done), fresh), driver)
        if self.render_history is not None:
            self.render_history.record()

    def _started_anew(self, envs: np.ndarray, driver: Any) -> None:
        """Environments ``envs`` were just reset within the warm-up: their counts, the driver's
        state and their frames start anew."""
        if not envs.size:
            return
        self.episode_steps[envs] = 0
        self.episode_periods[envs] = 0
        if driver is not None:
            driver.reset(envs)
        if self.render_history is not None:
            self.render_history.clear(envs)

    def step(
        self, actions: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        core = self.core
        a = core.check_actions(actions)
        if self.action_repeat == 1:
            core.step(a)
            terms = core.terms  # read before the next step: no copy
            core.episode_return += terms.sum(axis=1)
            core.episode_terms += terms
            self.episode_periods += 1
            terminated = core.flags[:, K.F_TERMINATED].astype(bool)
            truncated = core.flags[:, K.F_TRUNCATED].astype(bool)
            truncated |= self.episode_periods >= self.period_limit
            truncated &= ~terminated
            clipped = core.flags[:, K.F_CLIPPED].copy()
            final_obs = final_info = None
        else:
            terms, terminated, truncated, clipped, final_obs, final_info = self._repeat(a)
        rewards = terms.sum(axis=1)
        self.episode_steps += 1
        info: dict[str, Any] = {
            "reward_terms": {n: terms[:, i].copy() for i, n in enumerate(TERM_NAMES)},
            "action_clipped": clipped,
        }
        ended = np.flatnonzero(terminated | truncated)
        if ended.size:
            if final_obs is None:
                final_obs = np.zeros((self.num_envs, core.obs_dim), dtype=np.float32)
                final_info = np.full(self.num_envs, None, dtype=object)
                for e in ended:  # only the environments that just ended
                    final_obs[e], final_info[e] = self._final(int(e))
            mask = np.zeros(self.num_envs, dtype=bool)
            mask[ended] = True
            for e in ended:
                core.reset_env(int(e), None)
            self.episode_steps[ended] = 0
            self.episode_periods[ended] = 0
            info.update(
                final_obs=final_obs, _final_obs=mask, final_info=final_info, _final_info=mask.copy()
            )
            if self.render_history is not None:
                self.render_history.clear(ended)
        if self.render_history is not None:
            self.render_history.record()
        return core.obs.copy(), rewards, terminated, truncated, info

    def _final(self, e: int) -> tuple[np.ndarray, dict[str, Any]]:
        core = self.core
        return core.final_obs(e), {"metrics": core.episode_info(e), "scenario": core.describe(e)}

    def _repeat(self, a: np.ndarray) -> tuple[np.ndarray, ...]:
        """``action_repeat`` control periods with the action held; a stop that ends within
        them is recorded where it ended and held there (``freeze``) for the rest of the step."""
        core, n = self.core, self.num_envs
        terms = np.zeros((n, K.N_TERMS))
        done = np.zeros(n, dtype=bool)
        terminated = np.zeros(n, dtype=bool)
        truncated = np.zeros(n, dtype=bool)
        clipped = np.zeros(n, dtype=core.flags.dtype)
        final_obs = np.zeros((n, core.obs_dim), dtype=np.float32)
        final_info = np.full(n, None, dtype=object)
        for _ in range(self.action_repeat):
            core.step(a)
            live = ~done
            period = np.where(live[:, None], core.terms, 0.0)
            terms += period
            core.episode_return += period.sum(axis=1)
            core.episode_terms += period
            clipped += np.where(live, core.flags[:, K.F_CLIPPED], 0)
            self.episode_periods += live
            term = live & core.flags[:, K.F_TERMINATED].astype(bool)
            trunc = (
                live
                & ~term
                & (
                    core.flags[:, K.F_TRUNCATED].astype(bool)
                    | (self.episode_periods >= self.period_limit)
                )
            )
            for e in np.flatnonzero(term | trunc):
                final_obs[e], final_info[e] = self._final(int(e))
                core.freeze(int(e))  # held where it ended until the step's end
            terminated |= term
            truncated |= trunc
            done |= term | trunc
            if done.all():
                break
        return terms, terminated, truncated, clipped, final_obs, final_info

    def render(self) -> tuple[np.ndarray, ...] | None:
        """``rgb_array``: every environment's frame (``WSPBrakingEnv.render``); else None."""
        if self.renderer is None:
            return None
        return tuple(self.renderer.frame(e) for e in range(self.num_envs))

    def close_extras(self, **kwargs: Any) -> None:
        """Close the rendering figure, if one was made."""
        if self.renderer is not None:
            self.renderer.close()
