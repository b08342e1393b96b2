"""The dynamics of the robot 'three_link', generated from its description by biped_sim.config.codegen.

Do not edit: regenerate (make generate for a shipped model). Coordinates: base_x, base_y, hip_1, hip_2, torso_pitch.
"""
# ruff: noqa
from math import cos, sin

NAME = 'three_link'
DIGEST = '024519ae3864388f'
GENERATOR_VERSION = 2
COORDINATES = ('base_x', 'base_y', 'hip_1', 'hip_2', 'torso_pitch')
CONTACTS = ('foot_1', 'foot_2')
ACTUATED = ('hip_1', 'hip_2')
B = [[0, 0], [0, 0], [1, 0], [0, 1], [0, 0]]
RELABELING = (0, 1, 3, 2, 4)
CONTACT_MIRROR = (1, 0)
TOTAL_MASS = 20.0
LINKS = ('leg_1', 'leg_2', 'torso')


def mass_matrix(q):
    """D(q), 5x5 row-major."""
    q0, q1, q2, q3, q4, = q
    t0 = q2 + q4
    t1 = cos(t0)
    t2 = 2.5*t1
    t3 = q3 + q4
    t4 = cos(t3)
    t5 = 2.5*t4
    t6 = 2.5*t1 + 2.5*t4 + 2.5*cos(q4)
    t7 = sin(t0)
    t8 = -2.5*t7
    t9 = sin(t3)
    t10 = -2.5*t9
    t11 = -2.5*t7 - 2.5*t9 - 2.5*sin(q4)
    return (20, 0, t2, t5, t6, 0, 20, t8, t10, t11, t2, t8, 1.75000000000000, 0, 1.75000000000000, t5, t10, 0, 1.75000000000000, 1.75000000000000, t6, t11, 1.75000000000000, 1.75000000000000, 5.12500000000000,)


def coriolis_matrix(q, dq):
    """C(q, dq) from the Christoffel symbols of D."""
    q0, q1, q2, q3, q4, = q
    dq0, dq1, dq2, dq3, dq4, = dq
    t0 = q2 + q4
    t1 = sin(t0)
    t2 = 2.5*dq2 + 2.5*dq4
    t3 = q3 + q4
    t4 = sin(t3)
    t5 = 2.5*dq3 + 2.5*dq4
    t6 = cos(t0)
    t7 = cos(t3)
    return (0, 0, -t1*t2, -t4*t5, -2.5*dq2*t1 - 2.5*dq3*t4 - 2.5*dq4*(t1 + t4 + sin(q4)), 0, 0, -t2*t6, -t5*t7, -2.5*dq2*t6 - 2.5*dq3*t7 - 2.5*dq4*(t6 + t7 + cos(q4)), 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,)


def gravity_vector(q):
    """G(q) = dV/dq."""
    q0, q1, q2, q3, q4, = q
    t0 = sin(q2 + q4)
    t1 = sin(q3 + q4)
    return (0, 196.200000000000, -24.525*t0, -24.525*t1, -24.525*t0 - 24.525*t1 - 24.525*sin(q4),)


def bias_forces(q, dq):
    """C(q, dq) dq + G(q)."""
    q0, q1, q2, q3, q4, = q
    dq0, dq1, dq2, dq3, dq4, = dq
    t0 = dq2 + dq4
    t1 = q2 + q4
    t2 = sin(t1)
    t3 = dq2*t2
    t4 = dq3 + dq4
    t5 = q3 + q4
    t6 = sin(t5)
    t7 = dq3*t6
    t8 = t2 + t6 + sin(q4)
    t9 = cos(t1)
    t10 = dq2*t9
    t11 = cos(t5)
    t12 = dq3*t11
    return (-2.5*dq4*(dq4*t8 + t3 + t7) - 2.5*t0*t3 - 2.5*t4*t7, -2.5*dq4*(dq4*(t11 + t9 + cos(q4)) + t10 + t12) - 2.5*t0*t10 - 2.5*t12*t4 + 196.2, -24.525*t2, -24.525*t6, -24.525*t8,)


def contact_positions(q):
    """p_c of every contact point, (x, y) each."""
    q0, q1, q2, q3, q4, = q
    t0 = q2 + q4
    t1 = q3 + q4
    return (q0 + sin(t0), q1 + cos(t0), q0 + sin(t1), q1 + cos(t1),)


def contact_jacobians(q):
    """J_c = dp_c/dq of every contact point, 2x5 row-major each."""
    q0, q1, q2, q3, q4, = q
    t0 = q2 + q4
    t1 = cos(t0)
    t2 = -sin(t0)
    t3 = q3 + q4
    t4 = cos(t3)
    t5 = -sin(t3)
    return (1, 0, t1, 0, t1, 0, 1, t2, 0, t2, 1, 0, 0, t4, t4, 0, 1, 0, t5, t5,)


def contact_jacobian_dots(q, dq):
    """dJ_c/dt of every contact point, 2x5 each."""
    q0, q1, q2, q3, q4, = q
    dq0, dq1, dq2, dq3, dq4, = dq
    t0 = dq2 + dq4
    t1 = q2 + q4
    t2 = -t0*sin(t1)
    t3 = -t0*cos(t1)
    t4 = dq3 + dq4
    t5 = q3 + q4
    t6 = -t4*sin(t5)
    t7 = -t4*cos(t5)
    return (0, 0, t2, 0, t2, 0, 0, t3, 0, t3, 0, 0, 0, t6, t6, 0, 0, 0, t7, t7,)


def contact_velocities(q, dq):
    """dp_c/dt of every contact point."""
    q0, q1, q2, q3, q4, = q
    dq0, dq1, dq2, dq3, dq4, = dq
    t0 = q2 + q4
    t1 = cos(t0)
    t2 = -dq1
    t3 = sin(t0)
    t4 = q3 + q4
    t5 = cos(t4)
    t6 = sin(t4)
    return (dq0 + dq2*t1 + dq4*t1, -dq2*t3 - dq4*t3 - t2, dq0 + dq3*t5 + dq4*t5, -dq3*t6 - dq4*t6 - t2,)


def mass_matrix_jacobian(q):
    """dD/dq_k for k = 0..4, each 5x5 row-major: [k, i, j], 125 values."""
    q0, q1, q2, q3, q4, = q
    t0 = q2 + q4
    t1 = sin(t0)
    t2 = -2.5*t1
    t3 = cos(t0)
    t4 = -2.5*t3
    t5 = q3 + q4
    t6 = sin(t5)
    t7 = -2.5*t6
    t8 = cos(t5)
    t9 = -2.5*t8
    t10 = -2.5*t1 - 2.5*t6 - 2.5*sin(q4)
    t11 = -2.5*t3 - 2.5*t8 - 2.5*cos(q4)
    return (0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t2, 0, t2, 0, 0, t4, 0, t4, t2, t4, 0, 0, 0, 0, 0, 0, 0, 0, t2, t4, 0, 0, 0, 0, 0, 0, t7, t7, 0, 0, 0, t9, t9, 0, 0, 0, 0, 0, t7, t9, 0, 0, 0, t7, t9, 0, 0, 0, 0, 0, t2, t7, t10, 0, 0, t4, t9, t11, t2, t4, 0, 0, 0, t7, t9, 0, 0, 0, t10, t11, 0, 0, 0,)


def bias_forces_jacobian(q, dq):
    """dh/dq (5x5), then dh/d dq (5x5), row-major, h = C dq + G."""
    q0, q1, q2, q3, q4, = q
    dq0, dq1, dq2, dq3, dq4, = dq
    t0 = q2 + q4
    t1 = cos(t0)
    t2 = dq2 + dq4
    t3 = 2.5*t2*t2
    t4 = q3 + q4
    t5 = cos(t4)
    t6 = dq3 + dq4
    t7 = 2.5*t6*t6
    t8 = dq2*t1
    t9 = dq3*t5
    t10 = t1 + t5 + cos(q4)
    t11 = dq4*t10 + t8 + t9
    t12 = sin(t0)
    t13 = sin(t4)
    t14 = dq2*t12
    t15 = dq3*t13
    t16 = dq4*(t12 + t13 + sin(q4)) + t14 + t15
    t17 = -24.525*t1
    t18 = -24.525*t5
    t19 = 5.0*t2
    t20 = 5.0*t6
    return (0, 0, -t1*t3, -t5*t7, -2.5*dq4*t11 - 2.5*t2*t8 - 2.5*t6*t9, 0, 0, t12*t3, t13*t7, 2.5*dq4*t16 + 2.5*t14*t2 + 2.5*t15*t6, 0, 0, t17, 0, t17, 0, 0, 0, t18, t18, 0, 0, t17, t18, -24.525*t10, 0, 0, -t12*t19, -t13*t20, -5.0*t16, 0, 0, -t1*t19, -t20*t5, -5.0*t11, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,)


def contact_jacobian_jacobians(q):
    """dJ_c/dq_k of every contact point: for each contact, for k = 0..4, 2x5 row-major ([c, k, a, j], 50 values a contact)."""
    q0, q1, q2, q3, q4, = q
    t0 = q2 + q4
    t1 = -sin(t0)
    t2 = -cos(t0)
    t3 = q3 + q4
    t4 = -sin(t3)
    t5 = -cos(t3)
    return (0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t1, 0, t1, 0, 0, t2, 0, t2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t1, 0, t1, 0, 0, t2, 0, t2, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t4, t4, 0, 0, 0, t5, t5, 0, 0, 0, t4, t4, 0, 0, 0, t5, t5,)


def contact_bias_jacobians(q, dq):
    """Jdot_c dq (2), d(Jdot_c dq)/dq (2x5), d(Jdot_c dq)/d dq (2x5) of every contact point, row-major (22 values a contact)."""
    q0, q1, q2, q3, q4, = q
    dq0, dq1, dq2, dq3, dq4, = dq
    t0 = q2 + q4
    t1 = sin(t0)
    t2 = dq2 + dq4
    t3 = t2*t2
    t4 = t1*t3
    t5 = cos(t0)
    t6 = -t3*t5
    t7 = 2*t2
    t8 = -t1*t7
    t9 = -t5*t7
    t10 = q3 + q4
    t11 = sin(t10)
    t12 = dq3 + dq4
    t13 = t12*t12
    t14 = t11*t13
    t15 = cos(t10)
    t16 = -t13*t15
    t17 = 2*t12
    t18 = -t11*t17
    t19 = -t15*t17
    return (-t4, t6, 0, 0, t6, 0, t6, 0, 0, t4, 0, t4, 0, 0, t8, 0, t8, 0, 0, t9, 0, t9, -t14, t16, 0, 0, 0, t16, t16, 0, 0, 0, t14, t14, 0, 0, 0, t18, t18, 0, 0, 0, t19, t19,)


def energy(q, dq):
    """(T, V): kinetic and potential energy."""
    q0, q1, q2, q3, q4, = q
    dq0, dq1, dq2, dq3, dq4, = dq
    t0 = cos(q4)
    t1 = 0.25*dq4
    t2 = q2 + q4
    t3 = cos(t2)
    t4 = 0.5*t3
    t5 = q3 + q4
    t6 = cos(t5)
    t7 = 0.5*t6
    t8 = -dq1
    t9 = 0.5*sin(t2)
    t10 = 0.5*sin(t5)
    return ((1/2)*dq4*dq4 + 5*(dq0 + t0*t1)**2 + 5*(dq1 - t1*sin(q4))**2 + 0.25*(dq2 + dq4)**2 + 0.25*(dq3 + dq4)**2 + (5/2)*(dq0 + dq2*t4 + dq4*t4)**2 + (5/2)*(dq0 + dq3*t7 + dq4*t7)**2 + (5/2)*(dq2*t9 + dq4*t9 + t8)**2 + (5/2)*(dq3*t10 + dq4*t10 + t8)**2, 196.2*q1 + 24.525*t0 + 24.525*t3 + 24.525*t6,)


def com_position(q):
    """The centre of mass of the whole robot."""
    q0, q1, q2, q3, q4, = q
    t0 = q2 + q4
    t1 = q3 + q4
    return (q0 + 0.125*sin(q4) + 0.125*sin(t0) + 0.125*sin(t1), q1 + 0.125*cos(q4) + 0.125*cos(t0) + 0.125*cos(t1),)


def segments(q):
    """Each link's joint and tip, (x, y) each: the drawing."""
    q0, q1, q2, q3, q4, = q
    t0 = q2 + q4
    t1 = q3 + q4
    return (q0, q1, q0 + sin(t0), q1 + cos(t0), q0, q1, q0 + sin(t1), q1 + cos(t1), q0, q1, q0 + 0.5*sin(q4), q1 + 0.5*cos(q4),)
