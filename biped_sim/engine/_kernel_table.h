/* A described robot's six kernels as C entry points on double arrays (biped_sim/engine/model_kernels.py):
 * the table its compiled twin exports as the capsule KERNEL_TABLE, for C code that runs the robot without
 * a Python call (the compiled hybrid loop). The twin's Python functions k_stance ... k_energy call these
 * same entry points, so both give the same bits. Each twin's runtime (_kernels_runtime.h) includes it, and
 * so does C code that reads a table.
 *
 * Sizes: q, dq, ddq, dq_plus have n entries, u has actuators entries, F an (x, y) pair; p is
 * [x1, y1, x2, y2, ...] (2 a contact point), pv the positions then the velocities (4 a contact point), tv is
 * (T, V). contact is a contact point's 0-based index. Each returns KERNEL_OK, or why it has no answer (the
 * outputs are then unspecified). The functions touch no Python object and keep no state. */
#ifndef BIPED_SIM_KERNEL_TABLE_H
#define BIPED_SIM_KERNEL_TABLE_H

/* bumps when the struct below changes: a reader refuses a table of another version */
#define KERNEL_TABLE_VERSION 1
/* the capsule's name (PyCapsule_GetPointer checks it) */
#define KERNEL_TABLE_CAPSULE "biped_sim.engine.model_kernels.KernelTable"

enum { KERNEL_OK = 0, KERNEL_NOT_POSITIVE_DEFINITE = 1, KERNEL_SINGULAR_CONTACT = 2 };

typedef struct {
    int version;       /* KERNEL_TABLE_VERSION */
    int n;             /* the coordinates N */
    int contacts;      /* the contact points */
    int actuators;     /* the actuators M */
    /* [D -J_c^T; J_c 0] [ddq; F] = [B u - (C dq + G); -Jdot_c dq] */
    int (*stance)(const double *q, const double *dq, const double *u, int contact, double *ddq, double *F);
    /* D ddq = B u - (C dq + G) */
    int (*flight)(const double *q, const double *dq, const double *u, double *ddq);
    /* [D -J_c^T; J_c 0] [dq+; F] = [D dq-; 0] */
    int (*impact)(const double *q, const double *dq_minus, int contact, double *dq_plus, double *F);
    int (*foot_positions)(const double *q, double *p);
    int (*foot_kinematics)(const double *q, const double *dq, double *pv);
    int (*energy)(const double *q, const double *dq, double *tv);
} KernelTable;

#endif
