/* The kernel table of the Loop whose state S is (_core.c defines it after its Loop: the state is a member of the
 * Loop), for the compiled rules' kernel glue (loop_kernels.pxd): a described robot's kernels (model_kernels.py,
 * _kernel_table.h), where S[LS_MODEL_KERNELS] != 0. */
#ifndef BIPED_SIM_LOOP_TABLE_H
#define BIPED_SIM_LOOP_TABLE_H
#include "_kernel_table.h"
static const KernelTable *loop_table(double *S);
#endif
