"""The dynamics of the robot 'rabbit', generated from its description by biped_sim.config.codegen.

Do not edit: regenerate (make generate for a shipped model). Coordinates: base_x, base_y, hip_1, hip_2, knee_1, knee_2, torso_pitch.
"""
# ruff: noqa
from math import cos, sin

NAME = 'rabbit'
DIGEST = 'eeabe40500182351'
GENERATOR_VERSION = 2
COORDINATES = ('base_x', 'base_y', 'hip_1', 'hip_2', 'knee_1', 'knee_2', 'torso_pitch')
CONTACTS = ('foot_1', 'foot_2')
ACTUATED = ('hip_1', 'hip_2', 'knee_1', 'knee_2')
B = [[0, 0, 0, 0], [0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [0, 0, 0, 0]]
RELABELING = (0, 1, 3, 2, 5, 4, 6)
CONTACT_MIRROR = (1, 0)
TOTAL_MASS = 32.0
LINKS = ('femur_1', 'femur_2', 'tibia_1', 'tibia_2', 'torso')


def mass_matrix(q):
    """D(q), 7x7 row-major."""
    q0, q1, q2, q3, q4, q5, q6, = q
    t0 = q2 + q6
    t1 = q4 + t0
    t2 = 0.4096*cos(t1)
    t3 = t2 + 2.3884*cos(t0)
    t4 = q3 + q6
    t5 = q5 + t4
    t6 = 0.4096*cos(t5)
    t7 = t6 + 2.3884*cos(t4)
    t8 = t3 + t7 + 2.4*cos(q6)
    t9 = 0.4096*sin(t1)
    t10 = t9 + 2.3884*sin(t0)
    t11 = -t10
    t12 = 0.4096*sin(t5)
    t13 = t12 + 2.3884*sin(t4)
    t14 = -t13
    t15 = -t9
    t16 = -t12
    t17 = -t10 - t13 - 2.4*sin(q6)
    t18 = cos(q4)
    t19 = 0.32768*t18 + 1.415098
    t20 = 0.16384*t18 + 0.2524288
    t21 = cos(q5)
    t22 = 0.32768*t21 + 1.415098
    t23 = 0.16384*t21 + 0.2524288
    return (32.0000000000000, 0, t3, t7, t2, t6, t8, 0, 32.0000000000000, t11, t14, t15, t16, t17, t3, t11, t19, 0, t20, 0, t19, t7, t14, 0, t22, 0, t23, t22, t2, t15, t20, 0, 0.252428800000000, 0, t20, t6, t16, 0, t23, 0, 0.252428800000000, t23, t8, t17, t19, t22, t20, t23, 0.32768*t18 + 0.32768*t21 + 4.640196,)


def coriolis_matrix(q, dq):
    """C(q, dq) from the Christoffel symbols of D."""
    q0, q1, q2, q3, q4, q5, q6, = q
    dq0, dq1, dq2, dq3, dq4, dq5, dq6, = dq
    t0 = q2 + q6
    t1 = q4 + t0
    t2 = 0.4096*sin(t1)
    t3 = t2 + 2.3884*sin(t0)
    t4 = dq2*t3 + dq4*t2
    t5 = q3 + q6
    t6 = q5 + t5
    t7 = 0.4096*sin(t6)
    t8 = t7 + 2.3884*sin(t5)
    t9 = dq3*t8 + dq5*t7
    t10 = dq2 + dq6
    t11 = dq4 + t10
    t12 = dq3 + dq6
    t13 = dq5 + t12
    t14 = 0.4096*cos(t1)
    t15 = t14 + 2.3884*cos(t0)
    t16 = dq2*t15 + dq4*t14
    t17 = 0.4096*cos(t6)
    t18 = t17 + 2.3884*cos(t5)
    t19 = dq3*t18 + dq5*t17
    t20 = sin(q4)
    t21 = dq4*t20
    t22 = -0.16384*t21
    t23 = 0.16384*dq2
    t24 = 0.16384*dq4
    t25 = 0.16384*dq6
    t26 = sin(q5)
    t27 = dq5*t26
    t28 = -0.16384*t27
    t29 = 0.16384*dq3
    t30 = 0.16384*dq5
    t31 = 0.16384*dq6
    t32 = t23 + t31
    t33 = t29 + t31
    return (0, 0, -dq6*t3 - t4, -dq6*t8 - t9, -t11*t2, -t13*t7, -dq6*(t3 + t8 + 2.4*sin(q6)) - t4 - t9, 0, 0, -dq6*t15 - t16, -dq6*t18 - t19, -t11*t14, -t13*t17, -dq6*(t15 + t18 + 2.4*cos(q6)) - t16 - t19, 0, 0, t22, 0, -t20*(t23 + t24 + t25), 0, t22, 0, 0, 0, t28, 0, -t26*(t25 + t29 + t30), t28, 0, 0, 0.16384*t10*t20, 0, 0, 0, t20*t32, 0, 0, 0, 0.16384*t12*t26, 0, 0, t26*t33, 0, 0, t22, t28, -t20*(t24 + t32), -t26*(t30 + t33), -0.16384*t21 - 0.16384*t27,)


def gravity_vector(q):
    """G(q) = dV/dq."""
    q0, q1, q2, q3, q4, q5, q6, = q
    t0 = q2 + q6
    t1 = 4.018176*sin(q4 + t0)
    t2 = t1 + 23.430204*sin(t0)
    t3 = q3 + q6
    t4 = 4.018176*sin(q5 + t3)
    t5 = t4 + 23.430204*sin(t3)
    return (0, 313.920000000000, -t2, -t5, -t1, -t4, -t2 - t5 - 23.544*sin(q6),)


def bias_forces(q, dq):
    """C(q, dq) dq + G(q)."""
    q0, q1, q2, q3, q4, q5, q6, = q
    dq0, dq1, dq2, dq3, dq4, dq5, dq6, = dq
    t0 = dq2 + dq6
    t1 = dq4 + t0
    t2 = q2 + q6
    t3 = q4 + t2
    t4 = sin(t3)
    t5 = 0.4096*t4
    t6 = dq4*t5
    t7 = dq3 + dq6
    t8 = dq5 + t7
    t9 = q3 + q6
    t10 = q5 + t9
    t11 = sin(t10)
    t12 = 0.4096*t11
    t13 = dq5*t12
    t14 = sin(t2)
    t15 = 2.3884*t14 + t5
    t16 = dq2*t15 + t6
    t17 = sin(t9)
    t18 = t12 + 2.3884*t17
    t19 = dq3*t18 + t13
    t20 = sin(q6)
    t21 = 0.4096*cos(t3)
    t22 = dq4*t21
    t23 = 0.4096*cos(t10)
    t24 = dq5*t23
    t25 = t21 + 2.3884*cos(t2)
    t26 = dq2*t25 + t22
    t27 = t23 + 2.3884*cos(t9)
    t28 = dq3*t27 + t24
    t29 = 0.16384*dq2
    t30 = 0.16384*dq4
    t31 = 0.16384*dq6
    t32 = sin(q4)
    t33 = dq4*t32
    t34 = 4.018176*t4
    t35 = 23.430204*t14 + t29*t33 + t34
    t36 = 0.16384*dq3
    t37 = 0.16384*dq5
    t38 = sin(q5)
    t39 = dq5*t38
    t40 = 4.018176*t11
    t41 = 23.430204*t17 + t36*t39 + t40
    t42 = 0.16384*dq6
    t43 = t29 + t42
    t44 = t36 + t42
    return (-dq2*(dq6*t15 + t16) - dq3*(dq6*t18 + t19) - dq6*(dq6*(t15 + t18 + 2.4*t20) + t16 + t19) - t1*t6 - t13*t8, -dq2*(dq6*t25 + t26) - dq3*(dq6*t27 + t28) - dq6*(dq6*(t25 + t27 + 2.4*cos(q6)) + t26 + t28) - t1*t22 - t24*t8 + 313.92, -t31*t33 - t33*(t29 + t30 + t31) - t35, -t31*t39 - t39*(t31 + t36 + t37) - t41, dq6*t32*t43 + t0*t29*t32 - t34, dq6*t38*t44 + t36*t38*t7 - t40, -23.544*t20 - t33*(t30 + t43) - t35 - t39*(t37 + t44) - t41 - t42*(t33 + t39),)


def contact_positions(q):
    """p_c of every contact point, (x, y) each."""
    q0, q1, q2, q3, q4, q5, q6, = q
    t0 = q2 + q6
    t1 = q4 + t0
    t2 = q3 + q6
    t3 = q5 + t2
    return (q0 + 0.4*sin(t0) + 0.4*sin(t1), q1 + 0.4*cos(t0) + 0.4*cos(t1), q0 + 0.4*sin(t2) + 0.4*sin(t3), q1 + 0.4*cos(t2) + 0.4*cos(t3),)


def contact_jacobians(q):
    """J_c = dp_c/dq of every contact point, 2x7 row-major each."""
    q0, q1, q2, q3, q4, q5, q6, = q
    t0 = q2 + q6
    t1 = q4 + t0
    t2 = cos(t1)
    t3 = 0.4*t2 + 0.4*cos(t0)
    t4 = sin(t1)
    t5 = -0.4*t4 - 0.4*sin(t0)
    t6 = q3 + q6
    t7 = q5 + t6
    t8 = cos(t7)
    t9 = 0.4*t8 + 0.4*cos(t6)
    t10 = sin(t7)
    t11 = -0.4*t10 - 0.4*sin(t6)
    return (1, 0, t3, 0, 0.4*t2, 0, t3, 0, 1, t5, 0, -0.4*t4, 0, t5, 1, 0, 0, t9, 0, 0.4*t8, t9, 0, 1, 0, t11, 0, -0.4*t10, t11,)


def contact_jacobian_dots(q, dq):
    """dJ_c/dt of every contact point, 2x7 each."""
    q0, q1, q2, q3, q4, q5, q6, = q
    dq0, dq1, dq2, dq3, dq4, dq5, dq6, = dq
    t0 = q2 + q6
    t1 = q4 + t0
    t2 = sin(t1)
    t3 = t2 + sin(t0)
    t4 = -0.4*dq2*t3 - 0.4*dq4*t2 - 0.4*dq6*t3
    t5 = 0.4*dq2 + 0.4*dq4 + 0.4*dq6
    t6 = cos(t1)
    t7 = t6 + cos(t0)
    t8 = -0.4*dq2*t7 - 0.4*dq4*t6 - 0.4*dq6*t7
    t9 = q3 + q6
    t10 = q5 + t9
    t11 = sin(t10)
    t12 = t11 + sin(t9)
    t13 = -0.4*dq3*t12 - 0.4*dq5*t11 - 0.4*dq6*t12
    t14 = 0.4*dq3 + 0.4*dq5 + 0.4*dq6
    t15 = cos(t10)
    t16 = t15 + cos(t9)
    t17 = -0.4*dq3*t16 - 0.4*dq5*t15 - 0.4*dq6*t16
    return (0, 0, t4, 0, -t2*t5, 0, t4, 0, 0, t8, 0, -t5*t6, 0, t8, 0, 0, 0, t13, 0, -t11*t14, t13, 0, 0, 0, t17, 0, -t14*t15, t17,)


def contact_velocities(q, dq):
    """dp_c/dt of every contact point."""
    q0, q1, q2, q3, q4, q5, q6, = q
    dq0, dq1, dq2, dq3, dq4, dq5, dq6, = dq
    t0 = q2 + q6
    t1 = q4 + t0
    t2 = cos(t1)
    t3 = 0.4*dq4
    t4 = 0.4*t2 + 0.4*cos(t0)
    t5 = -dq1
    t6 = sin(t1)
    t7 = 0.4*t6 + 0.4*sin(t0)
    t8 = q3 + q6
    t9 = q5 + t8
    t10 = cos(t9)
    t11 = 0.4*dq5
    t12 = 0.4*t10 + 0.4*cos(t8)
    t13 = sin(t9)
    t14 = 0.4*t13 + 0.4*sin(t8)
    return (dq0 + dq2*t4 + dq6*t4 + t2*t3, -dq2*t7 - dq6*t7 - t3*t6 - t5, dq0 + dq3*t12 + dq6*t12 + t10*t11, -dq3*t14 - dq6*t14 - t11*t13 - t5,)


def mass_matrix_jacobian(q):
    """dD/dq_k for k = 0..6, each 7x7 row-major: [k, i, j], 343 values."""
    q0, q1, q2, q3, q4, q5, q6, = q
    t0 = q2 + q6
    t1 = q4 + t0
    t2 = 0.4096*sin(t1)
    t3 = t2 + 2.3884*sin(t0)
    t4 = -t3
    t5 = -t2
    t6 = 0.4096*cos(t1)
    t7 = t6 + 2.3884*cos(t0)
    t8 = -t7
    t9 = -t6
    t10 = q3 + q6
    t11 = q5 + t10
    t12 = 0.4096*sin(t11)
    t13 = t12 + 2.3884*sin(t10)
    t14 = -t13
    t15 = -t12
    t16 = 0.4096*cos(t11)
    t17 = t16 + 2.3884*cos(t10)
    t18 = -t17
    t19 = -t16
    t20 = sin(q4)
    t21 = -0.32768*t20
    t22 = -0.16384*t20
    t23 = sin(q5)
    t24 = -0.32768*t23
    t25 = -0.16384*t23
    t26 = -t13 - t3 - 2.4*sin(q6)
    t27 = -t17 - t7 - 2.4*cos(q6)
    return (0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t4, 0, t5, 0, t4, 0, 0, t8, 0, t9, 0, t8, t4, t8, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t5, t9, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t4, t8, 0, 0, 0, 0, 0, 0, 0, 0, t14, 0, t15, t14, 0, 0, 0, t18, 0, t19, t18, 0, 0, 0, 0, 0, 0, 0, t14, t18, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t15, t19, 0, 0, 0, 0, 0, t14, t18, 0, 0, 0, 0, 0, 0, 0, t5, 0, t5, 0, t5, 0, 0, t9, 0, t9, 0, t9, t5, t9, t21, 0, t22, 0, t21, 0, 0, 0, 0, 0, 0, 0, t5, t9, t22, 0, 0, 0, t22, 0, 0, 0, 0, 0, 0, 0, t5, t9, t21, 0, t22, 0, -0.32768*t20, 0, 0, 0, t15, 0, t15, t15, 0, 0, 0, t19, 0, t19, t19, 0, 0, 0, 0, 0, 0, 0, t15, t19, 0, t24, 0, t25, t24, 0, 0, 0, 0, 0, 0, 0, t15, t19, 0, t25, 0, 0, t25, t15, t19, 0, t24, 0, t25, -0.32768*t23, 0, 0, t4, t14, t5, t15, t26, 0, 0, t8, t18, t9, t19, t27, t4, t8, 0, 0, 0, 0, 0, t14, t18, 0, 0, 0, 0, 0, t5, t9, 0, 0, 0, 0, 0, t15, t19, 0, 0, 0, 0, 0, t26, t27, 0, 0, 0, 0, 0,)


def bias_forces_jacobian(q, dq):
    """dh/dq (7x7), then dh/d dq (7x7), row-major, h = C dq + G."""
    q0, q1, q2, q3, q4, q5, q6, = q
    dq0, dq1, dq2, dq3, dq4, dq5, dq6, = dq
    t0 = q2 + q6
    t1 = cos(t0)
    t2 = q4 + t0
    t3 = cos(t2)
    t4 = 0.4096*t3
    t5 = 2.3884*t1 + t4
    t6 = dq6*t5
    t7 = dq2*t5
    t8 = dq4*t4
    t9 = t7 + t8
    t10 = t6 + t9
    t11 = dq2 + dq6
    t12 = dq4 + t11
    t13 = dq2*t10 + t12*t8
    t14 = q3 + q6
    t15 = cos(t14)
    t16 = q5 + t14
    t17 = cos(t16)
    t18 = 0.4096*t17
    t19 = 2.3884*t15 + t18
    t20 = dq6*t19
    t21 = dq3*t19
    t22 = dq5*t18
    t23 = t21 + t22
    t24 = t20 + t23
    t25 = dq3 + dq6
    t26 = dq5 + t25
    t27 = dq3*t24 + t22*t26
    t28 = t12*t12
    t29 = t26*t26
    t30 = cos(q6)
    t31 = t19 + t5
    t32 = sin(t2)
    t33 = 0.4096*t32
    t34 = t33 + 2.3884*sin(t0)
    t35 = dq6*t34
    t36 = dq2*t34
    t37 = dq4*t33
    t38 = t36 + t37
    t39 = t35 + t38
    t40 = dq2*t39 + t12*t37
    t41 = sin(t16)
    t42 = 0.4096*t41
    t43 = t42 + 2.3884*sin(t14)
    t44 = dq6*t43
    t45 = dq3*t43
    t46 = dq5*t42
    t47 = t45 + t46
    t48 = t44 + t47
    t49 = dq3*t48 + t26*t46
    t50 = sin(q6)
    t51 = t34 + t43
    t52 = 4.018176*t3
    t53 = 23.430204*t1 + t52
    t54 = -t53
    t55 = 0.16384*dq2
    t56 = 0.16384*dq4
    t57 = 0.16384*dq6
    t58 = cos(q4)
    t59 = dq4*t58
    t60 = t52 + t55*t59
    t61 = 4.018176*t17
    t62 = 23.430204*t15 + t61
    t63 = -t62
    t64 = 0.16384*dq3
    t65 = 0.16384*dq5
    t66 = cos(q5)
    t67 = dq5*t66
    t68 = t61 + t64*t67
    t69 = -t52
    t70 = 0.16384*dq6
    t71 = t55 + t70
    t72 = -t61
    t73 = t64 + t70
    t74 = 0.8192*t32
    t75 = dq4*t74 + 2*t36
    t76 = 0.8192*t41
    t77 = dq5*t76 + 2*t45
    t78 = 2*dq6
    t79 = 0.8192*t3
    t80 = dq4*t79 + 2*t7
    t81 = 0.8192*t17
    t82 = dq5*t81 + 2*t21
    t83 = sin(q4)
    t84 = dq4*t83
    t85 = -0.32768*t84
    t86 = 0.32768*dq2
    t87 = 0.32768*dq4
    t88 = 0.32768*dq6
    t89 = sin(q5)
    t90 = dq5*t89
    t91 = -0.32768*t90
    t92 = 0.32768*dq3
    t93 = 0.32768*dq5
    t94 = 0.32768*dq6
    t95 = t86 + t94
    t96 = t92 + t94
    return (0, 0, -dq6*t10 - t13, -dq6*t24 - t27, -t28*t4, -t18*t29, -dq6*(dq6*(2.4*t30 + t31) + t23 + t9) - t13 - t27, 0, 0, dq6*t39 + t40, dq6*t48 + t49, t28*t33, t29*t42, dq6*(dq6*(2.4*t50 + t51) + t38 + t47) + t40 + t49, 0, 0, t54, 0, -t57*t59 - t59*(t55 + t56 + t57) - t60, 0, t54, 0, 0, 0, t63, 0, -t57*t67 - t67*(t57 + t64 + t65) - t68, t63, 0, 0, t69, 0, dq6*t58*t71 + t11*t55*t58 + t69, 0, t69, 0, 0, 0, t72, 0, dq6*t66*t73 + t25*t64*t66 + t72, t72, 0, 0, t54, t63, -t59*t70 - t59*(t56 + t71) - t60, -t67*t70 - t67*(t65 + t73) - t68, -23.544*t30 - t53 - t62, 0, 0, -2*t35 - t75, -2*t44 - t77, -t12*t74, -t26*t76, -t75 - t77 - t78*(2.4*t50 + t51), 0, 0, -2*t6 - t80, -2*t20 - t82, -t12*t79, -t26*t81, -t78*(2.4*t30 + t31) - t80 - t82, 0, 0, t85, 0, -t83*(t86 + t87 + t88), 0, t85, 0, 0, 0, t91, 0, -t89*(t88 + t92 + t93), t91, 0, 0, 0.32768*t11*t83, 0, 0, 0, t83*t95, 0, 0, 0, 0.32768*t25*t89, 0, 0, t89*t96, 0, 0, t85, t91, -t83*(t87 + t95), -t89*(t93 + t96), -0.32768*t84 - 0.32768*t90,)


def contact_jacobian_jacobians(q):
    """dJ_c/dq_k of every contact point: for each contact, for k = 0..6, 2x7 row-major ([c, k, a, j], 98 values a contact)."""
    q0, q1, q2, q3, q4, q5, q6, = q
    t0 = q2 + q6
    t1 = q4 + t0
    t2 = sin(t1)
    t3 = -0.4*t2 - 0.4*sin(t0)
    t4 = -0.4*t2
    t5 = cos(t1)
    t6 = -0.4*t5 - 0.4*cos(t0)
    t7 = -0.4*t5
    t8 = q3 + q6
    t9 = q5 + t8
    t10 = sin(t9)
    t11 = -0.4*t10 - 0.4*sin(t8)
    t12 = -0.4*t10
    t13 = cos(t9)
    t14 = -0.4*t13 - 0.4*cos(t8)
    t15 = -0.4*t13
    return (0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t3, 0, t4, 0, t3, 0, 0, t6, 0, t7, 0, t6, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t4, 0, t4, 0, t4, 0, 0, t7, 0, t7, 0, t7, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t3, 0, t4, 0, t3, 0, 0, t6, 0, t7, 0, t6, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t11, 0, t12, t11, 0, 0, 0, t14, 0, t15, t14, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, t12, 0, t12, t12, 0, 0, 0, t15, 0, t15, t15, 0, 0, 0, t11, 0, t12, t11, 0, 0, 0, t14, 0, t15, t14,)


def contact_bias_jacobians(q, dq):
    """Jdot_c dq (2), d(Jdot_c dq)/dq (2x7), d(Jdot_c dq)/d dq (2x7) of every contact point, row-major (30 values a contact)."""
    q0, q1, q2, q3, q4, q5, q6, = q
    dq0, dq1, dq2, dq3, dq4, dq5, dq6, = dq
    t0 = dq2 + dq4 + dq6
    t1 = q2 + q6
    t2 = q4 + t1
    t3 = sin(t2)
    t4 = dq4*t3
    t5 = t3 + sin(t1)
    t6 = dq2*t5 + dq6*t5 + t4
    t7 = 0.4*dq2*t6 + 0.4*dq6*t6 + 0.4*t0*t4
    t8 = cos(t2)
    t9 = dq4*t8
    t10 = t8 + cos(t1)
    t11 = dq2*t10 + dq6*t10 + t9
    t12 = -0.4*dq2*t11 - 0.4*dq6*t11 - 0.4*t0*t9
    t13 = 0.4*t0*t0
    t14 = -0.8*t6
    t15 = 0.8*t0
    t16 = -0.8*t11
    t17 = dq3 + dq5 + dq6
    t18 = q3 + q6
    t19 = q5 + t18
    t20 = sin(t19)
    t21 = dq5*t20
    t22 = t20 + sin(t18)
    t23 = dq3*t22 + dq6*t22 + t21
    t24 = 0.4*dq3*t23 + 0.4*dq6*t23 + 0.4*t17*t21
    t25 = cos(t19)
    t26 = dq5*t25
    t27 = t25 + cos(t18)
    t28 = dq3*t27 + dq6*t27 + t26
    t29 = -0.4*dq3*t28 - 0.4*dq6*t28 - 0.4*t17*t26
    t30 = 0.4*t17*t17
    t31 = -0.8*t23
    t32 = 0.8*t17
    t33 = -0.8*t28
    return (-t7, t12, 0, 0, t12, 0, -t13*t8, 0, t12, 0, 0, t7, 0, t13*t3, 0, t7, 0, 0, t14, 0, -t15*t3, 0, t14, 0, 0, t16, 0, -t15*t8, 0, t16, -t24, t29, 0, 0, 0, t29, 0, -t25*t30, t29, 0, 0, 0, t24, 0, t20*t30, t24, 0, 0, 0, t31, 0, -t20*t32, t31, 0, 0, 0, t33, 0, -t25*t32, t33,)


def energy(q, dq):
    """(T, V): kinetic and potential energy."""
    q0, q1, q2, q3, q4, q5, q6, = q
    dq0, dq1, dq2, dq3, dq4, dq5, dq6, = dq
    t0 = dq2 + dq6
    t1 = dq3 + dq6
    t2 = cos(q6)
    t3 = 0.2*dq6
    t4 = q2 + q6
    t5 = cos(t4)
    t6 = 0.163*t5
    t7 = q3 + q6
    t8 = cos(t7)
    t9 = 0.163*t8
    t10 = -dq1
    t11 = sin(t4)
    t12 = 0.163*t11
    t13 = sin(t7)
    t14 = 0.163*t13
    t15 = q4 + t4
    t16 = cos(t15)
    t17 = 0.128*t16
    t18 = t17 + 0.4*t5
    t19 = q5 + t7
    t20 = cos(t19)
    t21 = 0.128*t20
    t22 = t21 + 0.4*t8
    t23 = 0.128*sin(t15)
    t24 = 0.4*t11 + t23
    t25 = 0.128*sin(t19)
    t26 = 0.4*t13 + t25
    return (0.665*dq6*dq6 + 0.235*t0*t0 + 0.235*t1*t1 + 6*(dq0 + t2*t3)**2 + 6*(dq1 - t3*sin(q6))**2 + 0.1*(dq4 + t0)**2 + 0.1*(dq5 + t1)**2 + 3.4*(dq0 + dq2*t6 + dq6*t6)**2 + 3.4*(dq0 + dq3*t9 + dq6*t9)**2 + 3.4*(dq2*t12 + dq6*t12 + t10)**2 + 3.4*(dq3*t14 + dq6*t14 + t10)**2 + 1.6*(dq0 + dq2*t18 + dq4*t17 + dq6*t18)**2 + 1.6*(dq0 + dq3*t22 + dq5*t21 + dq6*t22)**2 + 1.6*(dq2*t24 + dq4*t23 + dq6*t24 + t10)**2 + 1.6*(dq3*t26 + dq5*t25 + dq6*t26 + t10)**2, 313.92*q1 + 4.018176*t16 + 23.544*t2 + 4.018176*t20 + 23.430204*t5 + 23.430204*t8,)


def com_position(q):
    """The centre of mass of the whole robot."""
    q0, q1, q2, q3, q4, q5, q6, = q
    t0 = q2 + q6
    t1 = q3 + q6
    t2 = q4 + t0
    t3 = q5 + t1
    return (1.0*q0 + 0.075*sin(q6) + 0.0746375*sin(t0) + 0.0746375*sin(t1) + 0.0128*sin(t2) + 0.0128*sin(t3), 1.0*q1 + 0.075*cos(q6) + 0.0746375*cos(t0) + 0.0746375*cos(t1) + 0.0128*cos(t2) + 0.0128*cos(t3),)


def segments(q):
    """Each link's joint and tip, (x, y) each: the drawing."""
    q0, q1, q2, q3, q4, q5, q6, = q
    t0 = q2 + q6
    t1 = q0 + 0.4*sin(t0)
    t2 = q1 + 0.4*cos(t0)
    t3 = q3 + q6
    t4 = q0 + 0.4*sin(t3)
    t5 = q1 + 0.4*cos(t3)
    t6 = q4 + t0
    t7 = q5 + t3
    return (q0, q1, t1, t2, q0, q1, t4, t5, t1, t2, t1 + 0.4*sin(t6), t2 + 0.4*cos(t6), t4, t5, t4 + 0.4*sin(t7), t5 + 0.4*cos(t7), q0, q1, q0 + 0.625*sin(q6), q1 + 0.625*cos(q6),)
