/* Small dense linear algebra for n = OPFMU_N_STATES (see linalg.h). */
#include <math.h>

#include "linalg.h"

#define N OPFMU_N_STATES

double dot(const double a[N], const double b[N])
{
    double sum = a[0] * b[0];
    for (int i = 1; i < N; ++i) sum += a[i] * b[i];
    return sum;
}

int lu_factor(Matrix A, int perm[N])
{
    for (int i = 0; i < N; ++i) perm[i] = i;
    for (int c = 0; c < N; ++c) {
        int pivot = c;
        for (int r = c + 1; r < N; ++r)
            if (fabs(A[r][c]) > fabs(A[pivot][c])) pivot = r;
        if (!(fabs(A[pivot][c]) >= 1e-14)) return 0;
        if (pivot != c) {
            for (int k = 0; k < N; ++k) {
                double swap = A[c][k];
                A[c][k] = A[pivot][k];
                A[pivot][k] = swap;
            }
            int swap = perm[c];
            perm[c] = perm[pivot];
            perm[pivot] = swap;
        }
        for (int r = c + 1; r < N; ++r) {
            A[r][c] /= A[c][c];
            for (int k = c + 1; k < N; ++k) A[r][k] -= A[r][c] * A[c][k];
        }
    }
    return 1;
}

void lu_solve(const Matrix F, const int perm[N], const double b[N], double x[N])
{
    for (int i = 0; i < N; ++i) {
        x[i] = b[perm[i]];
        for (int k = 0; k < i; ++k) x[i] -= F[i][k] * x[k];
    }
    for (int i = N - 1; i >= 0; --i) {
        for (int k = i + 1; k < N; ++k) x[i] -= F[i][k] * x[k];
        x[i] /= F[i][i];
    }
}
