# The signatures of loop_rules.py's rules when Cython compiles it (an augmenting .pxd): C functions on the state
# S. The compiled loop (_core.c) includes the generated _loop_rules.c and calls the public ones by these names.
from libc.math cimport NAN, fabs, hypot, isfinite, isnan, pow

from biped_sim.engine._loop_state cimport *
from biped_sim.engine.loop_kernels cimport (feet_t, guard_t, k_copy, k_dense, k_energy, k_foot_kinematics,
                                            k_foot_positions, k_impact_map, k_rhs, k_step, k_ulp, rhs_t)

cdef public void rk_begin(double *S, rhs_t fun, void *ctx) noexcept nogil
cdef public double rk_carried_step(double h, double max_step) noexcept nogil
cdef public int rk_step(double *S, rhs_t fun, void *ctx) noexcept nogil
cdef public void rk_dense(double *S, rhs_t fun, void *ctx) noexcept nogil
cdef public double rk_dense_at(double *S, Py_ssize_t i, double tt) noexcept nogil
cdef public void rk_dense_state(double *S, double tt) noexcept nogil
cdef public double ev_height_at(double *S, int leg, double tt) noexcept nogil
cdef double ev_height_guard(double *S, void *ctx, double tt) noexcept nogil
cdef double ev_power_coefficient(double *S, Py_ssize_t r, Py_ssize_t p, Py_ssize_t w, double hi) noexcept nogil
cdef void ev_dip_coefficients(double *S, int leg) noexcept nogil
cdef int ev_dip_search(double *S, guard_t g, void *ctx, double h0, double h1) noexcept nogil
cdef public int ev_may_dip(double *S, rhs_t fun, void *ctx, int leg, double h0, double h1) noexcept nogil
cdef public bint ev_may_sink_in_step(double h0, double h1, double ground_tol) noexcept nogil
cdef double ev_height_below_guard(double *S, void *ctx, double tt) noexcept nogil
cdef public int ev_resting_foot_dips(double *S, rhs_t fun, void *ctx, int leg, double h0, double h1) noexcept nogil
cdef int ev_locate_crossing(double *S, guard_t g, void *ctx, double ta, double tb) noexcept nogil
cdef public int ev_locate_height_crossing(double *S, rhs_t fun, void *ctx, int leg, double ta, double tb) noexcept nogil
cdef public bint ev_triggered(double w0, double w1) noexcept nogil
cdef public double ev_across(double tan_s, double x, double y) noexcept nogil
cdef public void ev_foot_states(double *p, Py_ssize_t i, double tan_s, double *ft, Py_ssize_t j) noexcept nogil
cdef public void ev_foot_point(double *p, int leg, double *point) noexcept nogil
cdef public double ev_normal(double sin_s, double cos_s, double fx, double fy) noexcept nogil
cdef public double ev_tangential(double sin_s, double cos_s, double fx, double fy) noexcept nogil
cdef public double ev_slip_margin(double mu, double normal, double tangential) noexcept nogil
cdef public double ev_normal_force(double *S, double fx, double fy) noexcept nogil
cdef public double ev_tangential_force(double *S, double fx, double fy) noexcept nogil
cdef public double ev_cone_margin(double *S, double fx, double fy) noexcept nogil
cdef public double ev_ground_y(double tan_s, double x, double height) noexcept nogil
cdef public bint ev_arms(bint free, double height, double arm_height) noexcept nogil
cdef public bint ev_disarmed_by_reset(int leg, bint both, int stance_before, int stance_after) noexcept nogil
cdef public double ev_pin_drift(double *foot, double *pin, double tan_s) noexcept nogil
cdef public double ev_pin_drift_rate(double *foot) noexcept nogil
cdef public void ev_project_onto_pin(double *q, double *dq, double *foot, double *pin, double tan_s) noexcept nogil
cdef public bint ev_finite_state(double *q, double *dq, Py_ssize_t n) noexcept nogil
cdef public bint ev_violated(double value, double tol) noexcept nogil
cdef public bint ev_provisional(long appended, long every) noexcept nogil
cdef public bint ev_swinging_through(double dx, double dheight) noexcept nogil
cdef public bint ev_starts_scuff(bint forward, double front_tol, double x, double dx, double dheight,
                                 double x_stance) noexcept nogil
cdef public double ev_start_scuff(double *scuff, Py_ssize_t i, double t, double scuffs) noexcept nogil
cdef public void ev_scuff_under_way(double *S, int leg, double t, double depth) noexcept nogil
cdef public bint ev_passes_through(bint forward, double front_tol, double x, double dx, double dheight,
                                   double x_stance) noexcept nogil
cdef public void ev_keep_feet_end(double *S, double t, double *ft, Py_ssize_t i) noexcept nogil
cdef public void ev_keep_force_end(double *S, double t, double fx, double fy) noexcept nogil
cdef public void ev_forget_feet_end(double *S) noexcept nogil
cdef public void ev_forget_force_end(double *S) noexcept nogil
cdef public bint ev_feet_kept_at(double *S, double t) noexcept nogil
cdef public bint ev_force_kept_at(double *S, double t) noexcept nogil
cdef public bint ev_within_step(double t_old, double t, double tt) noexcept nogil
cdef public int ev_track_scuff(double *S, feet_t feet_at, void *ctx, int leg, int stance_leg, double t_end) noexcept nogil
cdef public bint ev_outside_cone(double mu, double n, double tg, double tol) noexcept nogil
cdef public bint ev_stays_down(double dheight, double tol) noexcept nogil
cdef public int ev_impulse_checks(bint has_mu, double mu, double n, double tg) noexcept nogil
cdef public int ev_impact(double *S, int leg, int old, bint has_mu) noexcept nogil
cdef public double ev_impact_loss(double *S) noexcept nogil
cdef public int ev_stance_start(bint slip_watched, double mu, double n, double tg) noexcept nogil
cdef public bint ev_impacts_close(long n_before, double t_before, double t, double interval) noexcept nogil
cdef public bint ev_over_budget(long n_events, long max_events) noexcept nogil
cdef public bint ev_event_loop(long n_events, double t_first, double t_last) noexcept nogil
cdef public bint ev_accumulating(double *times, Py_ssize_t n, double t) noexcept nogil
cdef public void ev_count_impact(double *S, double t) noexcept nogil
cdef public double ev_ring_oldest(double *S) noexcept nogil
cdef public void ev_count_mode_event(double *S, double t) noexcept nogil
cdef public long ev_period_index(double t, double period, long k) noexcept nogil
cdef public double ev_period_end(long j, double period, double t_final) noexcept nogil
cdef public bint ev_diverging(double *dq, Py_ssize_t n, double max_speed) noexcept nogil
cdef public double ev_energy_lost_after(double energy_lost, double loss) noexcept nogil
cdef public double ev_energy_residual(double energy, double e0, double work, double push_work,
                                      double energy_lost) noexcept nogil
cdef public double ev_running_max(double m, double v) noexcept nogil
cdef public void ev_sample_row(double *row, double t, double *q, double *dq, double leg, double *F, double *u,
                               double residual) noexcept nogil
cdef public void ev_sample_row_of(double *row, double t, double *q, double *dq, Py_ssize_t n, double leg, double *F,
                                  double *u, Py_ssize_t m, double residual) noexcept nogil
cdef public bint ev_finite_sum(double *u, Py_ssize_t m) noexcept nogil
cdef public double ev_actuated_power(double *u, double *dq, double *joints, Py_ssize_t m) noexcept nogil
cdef public bint ev_finite_torques(double u0, double u1) noexcept nogil
cdef public bint ev_next_period_runs(double t, double t_final, double t_stop, double period) noexcept nogil
cdef public double ev_motor_power(double *u, double dq1, double dq2) noexcept nogil
cdef public long ev_sample_slot(long n, bint provisional, bint last_only) noexcept nogil
