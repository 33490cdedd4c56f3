/* Small dense linear algebra (see linalg.h). */
#include <math.h>

#include "linalg.h"

#define N OPFMU_N_STATES

double dot(const double a[N], const double b[N])
{
    double sum = a[0] * b[0];
    for (int i = 1; i < N; ++i) sum += a[i] * b[i];
    return sum;
}

int lu_factor_n(double *A, int n, int *perm)
{
    for (int i = 0; i < n; ++i) perm[i] = i;
    for (int c = 0; c < n; ++c) {
        int pivot = c;
        for (int r = c + 1; r < n; ++r)
            if (fabs(A[r * n + c]) > fabs(A[pivot * n + c])) pivot = r;
        if (!(fabs(A[pivot * n + c]) >= 1e-14)) return 0;
        if (pivot != c) {
            for (int k = 0; k < n; ++k) {
                double swap = A[c * n + k];
                A[c * n + k] = A[pivot * n + k];
                A[pivot * n + k] = swap;
            }
            int swap = perm[c];
            perm[c] = perm[pivot];
            perm[pivot] = swap;
        }
        for (int r = c + 1; r < n; ++r) {
            A[r * n + c] /= A[c * n + c];
            for (int k = c + 1; k < n; ++k) A[r * n + k] -= A[r * n + c] * A[c * n + k];
        }
    }
    return 1;
}

void lu_solve_n(const double *F, int n, const int *perm, const double *b, double *x)
{
    for (int i = 0; i < n; ++i) {
        x[i] = b[perm[i]];
        for (int k = 0; k < i; ++k) x[i] -= F[i * n + k] * x[k];
    }
    for (int i = n - 1; i >= 0; --i) {
        for (int k = i + 1; k < n; ++k) x[i] -= F[i * n + k] * x[k];
        x[i] /= F[i * n + i];
    }
}

int lu_factor(Matrix A, int perm[N]) { return lu_factor_n(&A[0][0], N, perm); }

void lu_solve(const Matrix F, const int perm[N], const double b[N], double x[N]) { lu_solve_n(&F[0][0], N, perm, b, x); }
