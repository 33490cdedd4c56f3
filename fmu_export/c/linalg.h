/* Small dense linear algebra: LU factors of an n x n matrix (row-major), and the same for vectors and
   matrices of the state size n = OPFMU_N_STATES. */
#ifndef OPFMU_LINALG_H
#define OPFMU_LINALG_H

#include "model.h"

typedef double Matrix[OPFMU_N_STATES][OPFMU_N_STATES];

/* a . b, summed in index order */
OPFMU_INTERNAL double dot(const double a[OPFMU_N_STATES], const double b[OPFMU_N_STATES]);

/* LU factors of the n x n matrix A (row-major, A[i * n + j]) in place (partial pivoting; row i of the
   factors is row perm[i] of A); 0 if a pivot is below 1e-14 in magnitude (singular for this purpose) */
OPFMU_INTERNAL int lu_factor_n(double *A, int n, int *perm);

/* x = A^-1 b from the factors F of lu_factor_n (x and b distinct) */
OPFMU_INTERNAL void lu_solve_n(const double *F, int n, const int *perm, const double *b, double *x);

/* LU factors of A in place (partial pivoting; row i of the factors is row perm[i] of A); 0 if a
   pivot is below 1e-14 in magnitude (singular for this purpose) */
OPFMU_INTERNAL int lu_factor(Matrix A, int perm[OPFMU_N_STATES]);

/* x = A^-1 b from the factors F of lu_factor (x and b distinct) */
OPFMU_INTERNAL void lu_solve(const Matrix F, const int perm[OPFMU_N_STATES], const double b[OPFMU_N_STATES],
                             double x[OPFMU_N_STATES]);

#endif
