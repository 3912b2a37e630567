"""Column layout of the batched parameter, state and accumulator arrays.

The compiled kernel (``integrator.py``) works on a handful of dense float64 arrays so that one
call advances every environment, with no Python objects in the hot path:

* ``env_par``   (n_envs, N_EP)            per-run scalars (mass, demand, adhesion law, ...)
* ``axle_par``  (n_envs, n_axles, N_AP)   per-axle constants (radius, inertia, brake gain, ...)
* ``sections``  (n_envs, MAX_SECTIONS, 3) contaminated stretches ``[start_m, end_m, level]``
* ``env_state`` (n_envs, N_ES), ``axle_state`` (n_envs, n_axles, N_AS)
* ``field``     (n_envs, n_cells) remaining contamination of the rail under the train (ring buffer)
* ``env_acc`` (n_envs, N_EA), ``axle_acc`` (n_envs, n_axles, N_AA): integrals for the metrics.

Units: SI throughout (m, s, kg, N, rad/s, J); pressures in bar (gauge), air in free-air litres.
"""

# ---- per-environment parameters --------------------------------------------------------------
EP_MASS = 0  # kg, whole train (wheelsets included)
EP_GRADE_ACC = 1  # m/s^2, g*sin(gradient); > 0 uphill (helps braking)
EP_DAVIS_A = 2  # N
EP_DAVIS_B = 3  # N s/m
EP_DAVIS_C = 4  # N s^2/m^2
EP_P_MAX = 5  # bar, demand pressure at full application
EP_DEMAND_DELAY = 6  # s, dead time before the demand rises
EP_DEMAND_RISE = 7  # s, 0 -> p_max ramp time
EP_FILL_DECAY = 8  # exp(-dt/tau_fill) for the substep dt
EP_FILL_RATE = 9  # bar/s, maximum filling rate
EP_VENT_DECAY = 10  # exp(-dt/tau_vent)
EP_VENT_RATE = 11  # bar/s, maximum venting rate
EP_VALVE_DEAD = 12  # s, WSP valve dead time (<= control period)
EP_PAD_SCALE = 13  # actual / nominal pad friction
EP_PAD_SLOPE = 14  # 1/(m/s): relative change of pad friction per m/s above EP_PAD_VREF
EP_PAD_VREF = 15  # m/s
EP_LAW = 16  # adhesion law id (adhesion.LAW_*)
EP_MU_CLEAN = 17  # friction level of the rail without contaminant
EP_MU_CONT = 18  # friction level under full contamination (level 1)
EP_LP0 = 19  # law parameters p0..p3 (see adhesion.creep_law)
EP_LP1 = 20
EP_LP2 = 21
EP_LP3 = 22
EP_REC_GAIN = 23  # mu_rec / mu_level (seed 002 Table 5: 0.10 / 0.08 = 1.25)
EP_W_LIM = 24  # recovery onset (unit set by EP_REC_BASIS)
EP_W_MAX = 25  # full recovery
EP_REC_BASIS = 26  # adhesion.REC_BASIS_*
EP_RF_B0 = 27  # recovery filter (seed 002 Eqs. 11, 13): b0, b1, b2, a1, a2
EP_RF_B1 = 28
EP_RF_B2 = 29
EP_RF_A1 = 30
EP_RF_A2 = 31
EP_E_CLEAN = 32  # J/m: sliding energy per metre of rail that removes 1 - 1/e of the contaminant
EP_PASS_REMOVAL = 33  # fraction removed by one rolling wheelset passage (no sliding)
EP_CELL_DX = 34  # m, length of one rail cell of the contamination field
EP_C_BACKGROUND = 35  # contamination level outside every section
EP_INJ_LEVEL = 36  # level laid at the leading axle while injecting (seed 000 soap tests)
EP_INJ_UNTIL = 37  # s, injection stops at this time (-1: no injection)
EP_N_SECTIONS = 38  # number of used rows of ``sections``
EP_V_EPS = 39  # m/s, creepage regularisation speed
EP_EXTRA_BRAKE_N = 40  # N at full demand: a brake force not through the wheels (track brake, ...)
EP_SLIDE_THRESH = 41  # m/s: a wheel slides (metrics: time and longest spell) when V - v_i
EP_SLIDE_REL = 42  # exceeds max(EP_SLIDE_THRESH, EP_SLIDE_REL V)
EP_STIFF_FACTOR = 43  # creep stiffness of the contaminated contact / Kalker's (rail.py)
# 1.0: the wheel torques are given from outside (AS_EXT_TORQUE: the roller rig's estimated
# torques, a traction drive) instead of the pneumatic brakes; 0.0: the brakes (default)
EP_EXT_TORQUE = 44
N_EP = 45

# ---- per-axle parameters ---------------------------------------------------------------------
AP_RADIUS = 0  # m, rolling radius
AP_INERTIA = 1  # kg m^2, wheelset + discs
AP_N_STATIC = 2  # N, static axle load
AP_K_TRANSFER = 3  # N per m/s^2 of deceleration (load transfer, > 0 on leading axles)
AP_STIFF = 4  # N, Kalker longitudinal stiffness of the axle (both wheels) at static load
AP_BRAKE_GAIN = 5  # N m / bar above threshold
AP_P_THRESH = 6  # bar, pressure below which no torque (spring return)
AP_OFFSET = 7  # m, distance behind the leading axle
AP_MU_FACTOR = 8  # constant axle-position reduction R_i (seed 002 Fig. 8), 1 = none
AP_CYL_VOLUME_L = 9  # litres of cylinder + pipe volume vented by this axle's valve
N_AP = 10

MAX_SECTIONS = 16

# ---- per-environment state -------------------------------------------------------------------
ES_V = 0  # m/s train speed
ES_X = 1  # m, leading-axle position along the track
ES_T = 2  # s since brake application
ES_DECEL = 3  # m/s^2, deceleration of the last substep (load transfer input)
ES_STOPPED = 4  # 1.0 once at standstill
ES_T_STOP = 5  # s, interpolated standstill time
ES_HEAD = 6  # index of the foremost initialised rail cell (stored as float, exact integers)
N_ES = 7

# ---- per-axle state --------------------------------------------------------------------------
AS_OMEGA = 0  # rad/s
AS_P = 1  # bar, cylinder pressure
AS_CMD = 2  # valve command of the previous control period (for the dead time)
AS_MU = 3  # signed adhesion coefficient used in the last substep
AS_N = 4  # N, normal load (quasi-static load transfer, set once per control period)
AS_MU_LEVEL = 5  # friction level seen by the axle (contamination, R_i) in the last substep
AS_RF_S1 = 6  # recovery filter states (transposed direct form II)
AS_RF_S2 = 7
AS_KW = 8  # filtered removal fraction K_W
AS_CONT = 9  # contamination level under the axle in the last substep
AS_F = 10  # N, adhesion force of the last substep (linearised, as used by both equations)
AS_DOMEGA = 11  # rad/s, change of omega in the last substep
AS_TORQUE = 12  # N m, brake torque of the last substep
AS_CELL = 13  # index of the rail cell under the axle; AS_CONT is read once on entering it
AS_STIFF = 14  # Kalker stiffness / normal load at the current load (once per control period)
AS_VENTING = 15  # 1.0 while the valve vents (last substep)
AS_INV_STIFF = 16  # normal load / Kalker stiffness
AS_EXT_TORQUE = 17  # N m on the wheelset with EP_EXT_TORQUE: > 0 drives (traction), < 0 brakes
N_AS = 18

NO_CELL = -1.0e18  # AS_CELL before the first substep

# ---- accumulators ----------------------------------------------------------------------------
EA_RESIST_E = 0  # J, running-resistance work
EA_GRADE_E = 1  # J, work against gravity (potential energy gained)
EA_EXTRA_E = 2  # J, work of the extra (non-wheel) brake force
N_EA = 3

AA_SLIDE_INT = 0  # m, integral of (V - omega r) dt            (seed 002 Eq. 23)
AA_SLIDE_SQ_INT = 1  # m^2/s, integral of (V - omega r)^2 dt    (seed 002 Eq. 24)
AA_SLIDE_E = 2  # J, wheel-rail sliding work
AA_BRAKE_E = 3  # J, brake (pad-disc) work
AA_LOCK_CUR = 4  # s, current continuous lock
AA_LOCK_MAX = 5  # s, longest lock
AA_AIR_L = 6  # free-air litres vented
AA_ADH_INT = 7  # s, integral of |F|/N dt while braking
AA_BRAKE_T = 8  # s, time with brake torque applied
AA_VENT_CUR = 9  # s, current continuous vent
AA_VENT_MAX = 10  # s, longest continuous vent
AA_LEVEL_INT = 11  # s, integral of the friction level seen, dt (while braking)
AA_AVAIL_INT = 12  # s, integral of the most the curve can give (recovered level), dt (braking)
AA_MAX_SLIDE = 13  # m/s, largest sliding speed V - omega r
AA_SLIDE_T = 14  # s, time sliding (above the slide threshold, EP_SLIDE_THRESH / EP_SLIDE_REL)
AA_SLIDE_CUR = 15  # s, current continuous slide
AA_SLIDE_MAX = 16  # s, longest continuous slide
AA_VENT_T = 17  # s, total time the valve vents
AA_VALVE_CYCLES = 18  # number of vent onsets (apply/hold -> vent)
N_AA = 19

# Valve commands (one float per axle per control period): a value in [0, 1] asks for that
# fraction of the demand pressure; CMD_HOLD closes both valve seats (pressure held).
CMD_HOLD = -1.0
