/* The hybrid loop's state (biped_sim/engine/loop_state.py, written by tools/generate_loop.py: do not
 * edit). LOOP_STATE_MEMBERS are the fields as doubles in the order of the offsets LS_*, so that a
 * union of double S[LOOP_STATE_SIZE] with a struct of these members reads the same memory both ways. */
#ifndef BIPED_SIM_LOOP_STATE_H
#define BIPED_SIM_LOOP_STATE_H

#define LOOP_STATE_SIZE 3397
#define LS_NMAX 25
#define LS_NQ_MAX 12
#define LS_MAX_DEPTH 30
#define LS_CHAIN_MAX 4
#define LS_CHAIN_WIDTH 8
#define LS_COEF_WIDTH 6
#define LS_EVENT_ROOM 32
#define LS_METHOD 0
#define LS_N_Y 1
#define LS_N_Q 2
#define LS_MODEL_KERNELS 3
#define LS_RTOL 4
#define LS_ATOL 5
#define LS_MAX_STEP 6
#define LS_GRAZE_TOL 7
#define LS_EVENT_TOL 8
#define LS_L_LEG 9
#define LS_CHAIN_LINKS 10
#define LS_CHAIN 12
#define LS_TAN_S 76
#define LS_SIN_S 77
#define LS_COS_S 78
#define LS_MU 79
#define LS_FIXED_BASE 80
#define LS_FRONT_TOL 81
#define LS_SCUFF_DEPTH 82
#define LS_FORWARD_RULE 83
#define LS_K_POS 84
#define LS_TO_POWER_BASIS 116
#define LS_MAX_SPEED 180
#define LS_GROUND_TOL 181
#define LS_FORCE_TOL 182
#define LS_ARM_HEIGHT 183
#define LS_HAS_MU 184
#define LS_STOP_ON_SLIP 185
#define LS_PROJECT 186
#define LS_CHECK_INVARIANTS 187
#define LS_IMPACT_PHASE 188
#define LS_FRONT_RULE 189
#define LS_COMPUTE_GRF 190
#define LS_ZENO_INTERVAL 191
#define LS_IMPULSE_TOL 192
#define LS_CONTACT_TOL 193
#define LS_MAX_EVENTS 194
#define LS_STANCE_LEG 195
#define LS_PIN 196
#define LS_U_HOLD 198
#define LS_T_NEXT 207
#define LS_REFUSED_U 208
#define LS_N_RECORDS 217
#define LS_WHY 218
#define LS_END_U 219
#define LS_END_F 228
#define LS_STEPS 230
#define LS_MAX_DRIFT 231
#define LS_MAX_RATE 232
#define LS_MAX_RESIDUAL 233
#define LS_WALL_TIME 234
#define LS_T 235
#define LS_T_BOUND 236
#define LS_H_ABS 237
#define LS_T_OLD 238
#define LS_H 239
#define LS_Y 240
#define LS_F 265
#define LS_Y_OLD 290
#define LS_STAGES 315
#define LS_NFEV 640
#define LS_NREJECTED 641
#define LS_NACCEPTED 642
#define LS_DENSE_READY 643
#define LS_DENSE 644
#define LS_FAIL_KIND 844
#define LS_FAIL_VALUE 845
#define LS_FAIL_T 846
#define LS_CALLBACK_FAILED 847
#define LS_GUARD_LEG 848
#define LS_SCUFF_TRIAL 849
#define LS_DEEPEST_TRIAL 852
#define LS_FEET 853
#define LS_E0 861
#define LS_PUSH_WORK 862
#define LS_ENERGY_LOST 863
#define LS_SIM_T 864
#define LS_SIM_WORK 865
#define LS_SIM_H 866
#define LS_SIM_U 867
#define LS_SIM_Q 876
#define LS_SIM_DQ 888
#define LS_SIM_STATE_UNMADE 900
#define LS_MODE_BEGUN 901
#define LS_CONTROL_PERIODS 902
#define LS_RUNNING 903
#define LS_INITIAL_SAMPLE_PENDING 904
#define LS_N_SAMPLES 905
#define LS_APPENDED 906
#define LS_PROVISIONAL 907
#define LS_EVERY 908
#define LS_LAST_ONLY 909
#define LS_LAST_IMPACT 910
#define LS_N_IMPACTS 911
#define LS_RECENT_IMPACTS 912
#define LS_N_RECENT 916
#define LS_MODE_EVENTS 917
#define LS_RING 918
#define LS_N_LATCHED 967
#define LS_ARMED 968
#define LS_SCUFFING 970
#define LS_SCUFF 972
#define LS_DEEPEST_SCUFF 978
#define LS_SCUFFS 979
#define LS_FEET_END_T 980
#define LS_FEET_END 981
#define LS_FORCE_END_T 989
#define LS_FORCE_END 990
#define LS_OUT 992
#define LS_RESULT 1368
#define LS_COEF 1370
#define LS_COEF_LINKS 1418
#define LS_COEF_LENGTH 1419
#define LS_DIP_D 1423
#define LS_QS 1435
#define LS_PS 1447
#define LS_STACK 1451
#define LS_K_IMPACT 1771
#define LS_K_ENERGY 1803
#define LS_K_FEET 1835
#define LS_Q_IMPACT 1867
#define LS_DQ_MINUS 1879
#define LS_DQ_PLUS 1891
#define LS_IMPULSE 1903
#define LS_TV 1905
#define LS_ENERGY_BEFORE 1907
#define LS_ENERGY_AFTER 1908
#define LS_KINEMATICS 1909
#define LS_FEET_AFTER 1917
#define LS_RECORDS 1925
#define IMPACT_OLD_FOOT_SINKS 1
#define IMPACT_PULLS 2
#define IMPACT_OUTSIDE_CONE 4
#define STANCE_HOLDS 0
#define STANCE_LIFTS_OFF 1
#define STANCE_SLIPS 2
#define ROW_T 0
#define ROW_Q 1
#define ROW_DQ 6
#define ROW_LEG 11
#define ROW_F 12
#define ROW_U 14
#define ROW_RESIDUAL 16
#define ROW_WIDTH 17
#define REC_KIND 0
#define REC_A 1
#define REC_B 2
#define REC_V 3
#define REC_WIDTH 46
#define REC_TD_T 0
#define REC_TD_Q 1
#define REC_TD_DQ_MINUS 13
#define REC_TD_DQ_PLUS 25
#define REC_TD_IMPULSE 37
#define REC_TD_LOSS 39
#define REC_TD_LOST 40
#define REC_TD_PIN 41
#define REC_SCUFF_SCUFF 0
#define REC_SCUFF_T_UP 3
#define REC_SCUFF_Q 4
#define REC_SCUFF_DQ 16

/* Outcome, Record and Reason (loop_state.py) */
#define OUTCOME_DONE 0
#define OUTCOME_EVENT 1
#define OUTCOME_NEED_ROOM 2
#define OUTCOME_FAILED 3
#define OUTCOME_RAISED 4
#define OUTCOME_TORQUE_CHANGE 5
#define OUTCOME_DECLINED 6
#define OUTCOME_PYTHON_STEPS 7
#define RECORD_SCUFF_ENDED 1
#define RECORD_TOUCHDOWN 2
#define WHY_DIVERGING 1
#define WHY_CROSSING_IN_PYTHON 2
#define WHY_TOUCHDOWN_WHILE_SCUFFING 3
#define WHY_LIFTOFF 4
#define WHY_SLIP 5
#define WHY_FOOT_PUSHED_IN 6
#define WHY_SCUFF_LEAVES_MODEL 7
#define WHY_NON_FINITE 8
#define WHY_FOOT_BELOW_GROUND 9
#define WHY_GROUND_PULLS 10
#define WHY_OUTSIDE_CONE 11
#define WHY_LAW_FAILED 12
#define WHY_CALLED_BACK_LAW 13
#define WHY_IMPACTS_CLOSE 14
#define WHY_MAX_EVENTS 15
#define WHY_EVENT_LOOP 16
#define WHY_OLD_FOOT_SINKS 18
#define WHY_IMPULSE_CHECK 19
#define WHY_OLD_FOOT_STAYS 20
#define WHY_STANCE_REFUSED 21
#define WHY_ACCUMULATING 22

/* the right-hand side f(ctx, t, y) -> dy the generated steps take, and a guard's value at t: the
 * functions the rules take as arguments */
typedef int (*rhs_t)(void *ctx, double t, const double *y, double *dy);
typedef double (*guard_t)(double *S, void *ctx, double t);
/* the feet at t into S[LS_FEET] */
typedef void (*feet_t)(double *S, void *ctx, double t);

#define LOOP_STATE_MEMBERS \
    double method;  /* the Runge-Kutta pair: 0 dop853, 1 dopri5 (METHODS) */ \
    double n_y;  /* entries of y in use (at most NMAX): also the distance of a trial step's rows (out, stages) */ \
    double n_q;  /* the model's coordinates N, the entries of a field of q in use (at most NQ_MAX) */ \
    double model_kernels;  /* whose kernels the rules evaluate (loop_kernels): 0 the three-link's closed forms on the constants below, k > 0 the generated model registered as k (the Python loop only) */ \
    double rtol;  /* relative tolerance of the step control */ \
    double atol;  /* absolute tolerance of the step control */ \
    double max_step;  /* the largest step size (s) */ \
    double graze_tol;  /* the dip search's depth (m): a dip of the foot deeper than this is found */ \
    double event_tol;  /* brentq's xtol (s) */ \
    double l_leg;  /* the leg's length (m) */ \
    double chain_links[2];  /* per contact point, the links of its chain: those from the floating base's point to it that carry it a distance (a link's frame turns with its absolute angle) */ \
    double chain[2][4][8];  /* per contact point, a row per chain link from the base: its length l_k (m), the count of its absolute angle's terms, then each term as +-(the entry of y + 1), + for a joint turning about +y */ \
    double tan_s;  /* tan(slope) of the ground */ \
    double sin_s;  /* sin(slope): a force's normal and tangential components on the ground line */ \
    double cos_s;  /* cos(slope) */ \
    double mu;  /* the friction coefficient (0 without one: the slip witness is then not a row) */ \
    double fixed_base;  /* 1 when y is the fixed base's (q1, q2, q3, dq..., work): the dip bound's form */ \
    double front_tol;  /* touchdown_rule front: a swing foot within this of the stance foot counts as behind (m) */ \
    double scuff_depth;  /* the deepest a scuff may pass under the ground (m) */ \
    double forward_rule;  /* 1 under scuff_rule forward, 0 under behind */ \
    double k_pos[32];  /* the constants of the closed form foot_positions (BipedModel.k; room for any) */ \
    double to_power_basis[8][8];  /* dop853's dense row to its power-basis coefficients (integrators) */ \
    double max_speed;  /* a rate beyond this is a diverging state (Options.max_speed) */ \
    double ground_tol;  /* how far a free foot may be under the ground (m) */ \
    double force_tol;  /* how far the ground may pull or the force leave the cone (N) */ \
    double arm_height;  /* a foot's touchdown counts once it has been higher than this (m) */ \
    double has_mu;  /* 1 with a friction coefficient (the slip witness is a row) */ \
    double stop_on_slip;  /* 1: a slip stops the run (Options.stop_on_slip) */ \
    double project;  /* 1: the state is projected onto the pin after each step (project_constraints) */ \
    double check_invariants;  /* 1: the invariants are checked after each step and impact */ \
    double impact_phase;  /* 1 when the scene has impacts ("impact" in phases) */ \
    double front_rule;  /* 1 under touchdown_rule front */ \
    double compute_grf;  /* 1: the event's sample has its ground force */ \
    double zeno_interval;  /* impacts closer than this may accumulate (s) */ \
    double impulse_tol;  /* how far an impact's impulse may pull (N s) */ \
    double contact_tol;  /* an old stance foot slower than this after an impact stays down (m/s) */ \
    double max_events;  /* the run stops after this many mode events */ \
    double stance_leg;  /* the stance foot: 1 or 2, 0 in flight (the simulator's stance_leg) */ \
    double pin[2];  /* where the stance foot is pinned (m; the simulator's pin, not read in flight) */ \
    double u_hold[9];  /* the torque held while the torque law is held, one an actuator (N m) */ \
    double t_next;  /* period(), periods(): the end of the control period under way (s) */ \
    double refused_u[9];  /* periods() ending TORQUE_CHANGE: the command refused at its period's start, one an actuator (N m) */ \
    double n_records;  /* the touchdowns and ended scuffs applied in C whose Events the Python code makes (records, in order) */ \
    double why;  /* why the compiled loop handed the last step back (Reason) */ \
    double end_u[9];  /* the step handed back: the torque of its end, one an actuator (N m) */ \
    double end_F[2];  /* the step handed back: the stance force of its end (N) */ \
    double steps;  /* the quiet steps accepted in C */ \
    double max_drift;  /* the largest drift of the stance foot from the pin (m) */ \
    double max_rate;  /* the largest rate of that drift (m/s) */ \
    double max_residual;  /* the largest |energy balance residual| (J) */ \
    double wall_time;  /* the wall time of the control periods run whole in C (Loop.period, s) */ \
    double t;  /* time (s) at the end of the last step */ \
    double t_bound;  /* the end of the interval the stepper runs to (s) */ \
    double h_abs;  /* the step size the next step tries (s) */ \
    double t_old;  /* time at the start of the last step (s) */ \
    double h;  /* the last step's size (s) */ \
    double y[25];  /* the state at t */ \
    double f[25];  /* the right-hand side at (t, y) */ \
    double y_old[25];  /* the state at t_old */ \
    double stages[13][25];  /* the last step's stages k0..k12 */ \
    double nfev;  /* right-hand-side evaluations */ \
    double nrejected;  /* rejected steps */ \
    double naccepted;  /* accepted steps */ \
    double dense_ready;  /* 1 when dense holds the last step's dense output */ \
    double dense[200];  /* the last step's dense output, a row of DENSE_WIDTH per entry of y */ \
    double fail_kind;  /* why the last step failed: 1 the step size underflowed, 2 a non-finite state, 3 the torque law failed (callback_failed) */ \
    double fail_value;  /* the failure's step size (kind 1) or time (kind 2) */ \
    double fail_t;  /* the time the failing step started at */ \
    double callback_failed;  /* 1 once the torque law failed inside the right-hand side (the compiled loop) */ \
    double guard_leg;  /* the foot whose height the root finder and the dip search follow */ \
    double scuff_trial[3];  /* a scuff followed over a step: t_start, deepest, t_deepest (ev_track_scuff) */ \
    double deepest_trial;  /* the deepest of any scuff so far, with this step's (ev_track_scuff) */ \
    double feet[2][4];  /* the feet on the dense output: x, height across the slope, and their rates, a row a foot */ \
    double e0;  /* the energy at the run's start (J) */ \
    double push_work;  /* the kinetic energy pushes added (J) */ \
    double energy_lost;  /* the energy the impacts took out (J) */ \
    double sim_t;  /* the simulator's time: its last accepted state's (s) */ \
    double sim_work;  /* the hip motors' work up to sim_t (J) */ \
    double sim_h;  /* the step size the next stepper starts with (NaN: none yet, the initial one is computed) */ \
    double sim_u[9];  /* the torque held now, one an actuator (N m) */ \
    double sim_q[12];  /* q at sim_t, where a quiet period left it (sim_state_unmade) */ \
    double sim_dq[12];  /* dq at sim_t, alike */ \
    double sim_state_unmade;  /* 1 when sim_q and sim_dq are the simulator's state and its arrays not yet made */ \
    double mode_begun;  /* 1 while the compiled loop's mode was begun (Loop.begin) at the simulator's state: a write of the simulator's time, q or dq by the Python code, or its reset to flight, clears it, and the next period begins the mode again */ \
    double control_periods;  /* the control periods begun so far */ \
    double running;  /* 1 while the run's status is running */ \
    double initial_sample_pending;  /* 1 until the first advance redoes the t0 sample under its torque */ \
    double n_samples;  /* the Samples' rows in use */ \
    double appended;  /* the samples appended so far */ \
    double provisional;  /* 1 when the newest sample is overwritten by the next (ev_provisional) */ \
    double every;  /* keep every this many samples (0: only the events' and the last) */ \
    double last_only;  /* 1 when the Samples keep the last sample only (one row) */ \
    double last_impact;  /* the last impact's time (s): ImpactHistory, a touchdown the loop applies */ \
    double n_impacts;  /* the impacts so far */ \
    double recent_impacts[4];  /* the last (up to) 4 impact times, oldest first */ \
    double n_recent;  /* how many of recent_impacts are in use */ \
    double mode_events;  /* the events that changed the mode so far (max_events counts them) */ \
    double ring[49];  /* the times of the last 49 of them, event i at i % 49 (50 within 1e-9 s: an event loop) */ \
    double n_latched;  /* the guards the locator holds latched (off until positive again: only Python follows) */ \
    double armed[2];  /* 1 for a foot whose touchdown counts (it has been higher than arm_height): EventLocator */ \
    double scuffing[2];  /* 1 for a foot in a scuff (under the ground, passing through it) */ \
    double scuff[2][3];  /* a foot's scuff: t_start, deepest, t_deepest */ \
    double deepest_scuff;  /* the deepest dip of any scuff so far (m) */ \
    double scuffs;  /* the scuffs so far (crossings behind the stance foot that did not touch down) */ \
    double feet_end_t;  /* the time of feet_end (NaN: none kept): the last step's end, the next one's start */ \
    double feet_end[2][4];  /* the feet there (x, height, and their rates, a row a foot) */ \
    double force_end_t;  /* the time of force_end (NaN: none kept) */ \
    double force_end[2];  /* the stance force there (N) */ \
    double out[376];  /* a trial step: y_new, f_new, err, stages; between steps the dense state (dense_state) */ \
    double result[2];  /* a located root, or a dip's bracket */ \
    double coef[8][6];  /* the dip search's |power-basis coefficients|, a row a power: the base's x, its y, then the absolute angle of each link of the foot's chain (fixed base: the stance leg's angle, 0, the swing leg's) */ \
    double coef_links;  /* the chain links of coef's row (its columns from the third) */ \
    double coef_length[4];  /* their lengths l_k (m): from the link's joint to the next joint, or the foot */ \
    double dip_d[2][6];  /* the dip search's bounds of each column's first and second derivatives */ \
    double qs[12];  /* q on the dense output */ \
    double ps[4];  /* the feet's positions there */ \
    double stack[64][5];  /* the dip search's intervals: a, b, h(a), h(b), depth */ \
    double k_impact[32];  /* the constants of the closed form impact_map_1 (impact_map_2 takes the same) */ \
    double k_energy[32];  /* the constants of the closed form energy */ \
    double k_feet[32];  /* the constants of the closed form foot_kinematics */ \
    double q_impact[12];  /* q at the impact */ \
    double dq_minus[12];  /* dq before the impact */ \
    double dq_plus[12];  /* dq after the impact (the impact map writes it, and the impulse into the next field) */ \
    double impulse[2];  /* the ground's impulse on the landing foot (N s) */ \
    double tv[2];  /* T and V (the closed form energy) */ \
    double energy_before;  /* T + V before the impact (J) */ \
    double energy_after;  /* T + V after the impact (J) */ \
    double kinematics[8];  /* foot_kinematics after the impact: p_1, p_2, dp_1/dt, dp_2/dt */ \
    double feet_after[2][4];  /* the feet after the impact: x, height across the ground, their rates, a row a foot */ \
    double records[32][46];  /* the touchdowns and ended scuffs applied in C, a row a record (RECORD_ROW), the first n_records in use */

#endif
