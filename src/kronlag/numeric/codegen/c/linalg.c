/* kronlag: dense linear algebra shared by the solvers and the integrators (generated code only
 * includes this file; no allocation, variable-length arrays of the model's dimensions). */

/* With KRONLAG_WIDE_LOOPS (kronlag's own build of the solver part, at -O3), the O(m^2) and O(m^3)
 * loops of the augmented solve are compiled twice with GCC on x86-64 glibc, for the baseline and
 * for AVX2, and the loader picks the one the CPU runs (an ifunc): the library stays portable (a
 * cached one too) and runs four doubles per instruction where it can. */
#if defined(KRONLAG_WIDE_LOOPS) && defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) \
    && defined(__GLIBC__)
#define KRONLAG_WIDE __attribute__((target_clones("avx2", "default"), noinline))
#else
#define KRONLAG_WIDE
#endif

/* Householder QR of the rows x cols matrix a (row-major, leading dimension lda), in place:
 * R in the upper triangle, reflector j (v_j[j] = 1) below the diagonal of column j, tau[j].
 * With perm != NULL, column pivoting by the largest remaining norm (a P = Q R). */
static void house_qr(double *a, int rows, int cols, int lda, int *perm, double *tau)
{
    int steps = rows < cols ? rows : cols;
    if (perm)
        for (int j = 0; j < cols; ++j) perm[j] = j;
    for (int j = 0; j < steps; ++j) {
        if (perm) {
            int best = j; double best_norm = -1.0;
            for (int c = j; c < cols; ++c) {
                double norm = 0.0;
                for (int i = j; i < rows; ++i) norm += a[i * lda + c] * a[i * lda + c];
                if (norm > best_norm) { best_norm = norm; best = c; }
            }
            if (best != j) {
                for (int i = 0; i < rows; ++i) {
                    double swap = a[i * lda + j]; a[i * lda + j] = a[i * lda + best]; a[i * lda + best] = swap;
                }
                int swap = perm[j]; perm[j] = perm[best]; perm[best] = swap;
            }
        }
        double alpha = a[j * lda + j], xnorm = 0.0;
        for (int i = j + 1; i < rows; ++i) xnorm += a[i * lda + j] * a[i * lda + j];
        if (xnorm == 0.0) { tau[j] = 0.0; continue; }
        double beta = -copysign(sqrt(alpha * alpha + xnorm), alpha);
        tau[j] = (beta - alpha) / beta;
        for (int i = j + 1; i < rows; ++i) a[i * lda + j] /= alpha - beta;
        a[j * lda + j] = beta;
        for (int c = j + 1; c < cols; ++c) {
            double w = a[j * lda + c];
            for (int i = j + 1; i < rows; ++i) w += a[i * lda + j] * a[i * lda + c];
            w *= tau[j];
            a[j * lda + c] -= w;
            for (int i = j + 1; i < rows; ++i) a[i * lda + c] -= w * a[i * lda + j];
        }
    }
}

/* x <- H_j x for the reflector stored in column j of a (rows x ., leading dimension lda). */
static void house_apply(const double *a, int rows, int lda, int j, double tau, double *x, int stride)
{
    if (tau == 0.0) return;
    double w = x[j * stride];
    for (int i = j + 1; i < rows; ++i) w += a[i * lda + j] * x[i * stride];
    w *= tau;
    x[j * stride] -= w;
    for (int i = j + 1; i < rows; ++i) x[i * stride] -= w * a[i * lda + j];
}

/* B <- H_j B H_j for the symmetric m x m matrix B (row-major) and the reflector stored in column j
 * of a (m x ., leading dimension lda): H B H = B - v w^T - w v^T with u = B v,
 * w = tau u - (tau^2 v^T u / 2) v.  Every loop runs along rows (vectorizable), unlike m calls
 * of house_apply on the columns of B. */
KRONLAG_WIDE static void house_reflect_symmetric(const double *a, int m, int lda, int j, double tau, double *B)
{
    if (tau == 0.0) return;
    double v[m], u[m];
    for (int i = 0; i < m; ++i) { v[i] = i > j ? a[i * lda + j] : 0.0; u[i] = 0.0; }
    v[j] = 1.0;
    for (int l = j; l < m; ++l)                     /* u = B v = sum_l v_l B[l, :] (B symmetric) */
        for (int i = 0; i < m; ++i) u[i] += v[l] * B[l * m + i];
    double s = 0.0;
    for (int i = j; i < m; ++i) s += v[i] * u[i];
    double half = 0.5 * tau * tau * s;
    for (int i = 0; i < m; ++i) u[i] = tau * u[i] - half * v[i];
    for (int row = 0; row < m; ++row) {
        double vr = v[row], ur = u[row];
        for (int i = 0; i < m; ++i) B[row * m + i] -= vr * u[i] + ur * v[i];
    }
}

/* Cholesky factorization A = U^T U of the n x n symmetric matrix A (upper triangle read; row-major,
 * leading dimension lda), U written over the upper triangle, right-looking (row updates,
 * vectorizable).  Returns 1, a singular configuration, when a pivot is not above
 * KRONLAG_CHOLESKY_RTOL times the largest diagonal entry of A, else 0. */
KRONLAG_WIDE static int cholesky_upper(double *A, int n, int lda)
{
    double largest = 0.0;
    for (int i = 0; i < n; ++i) if (A[i * lda + i] > largest) largest = A[i * lda + i];
    double pivot_row[n + 1];  /* a copy the compiler knows apart from A: the updates vectorize */
    for (int p = 0; p < n; ++p) {
        double *row = A + p * lda;
        if (!(row[p] > KRONLAG_CHOLESKY_RTOL * largest)) return 1;
        double pivot = sqrt(row[p]), inverse = 1.0 / pivot;
        row[p] = pivot;
        for (int c = p + 1; c < n; ++c) pivot_row[c] = row[c] *= inverse;
        for (int i = p + 1; i < n; ++i) {
            double factor = pivot_row[i], *target = A + i * lda;
            for (int c = i; c < n; ++c) target[c] -= factor * pivot_row[c];
        }
    }
    return 0;
}

/* x <- (U^T U)^-1 x with the factor of cholesky_upper. */
KRONLAG_WIDE static void cholesky_solve(const double *U, int n, int lda, double *x)
{
    for (int i = 0; i < n; ++i) {                     /* U^T y = x, by columns of U^T */
        x[i] /= U[i * lda + i];
        for (int c = i + 1; c < n; ++c) x[c] -= U[i * lda + c] * x[i];
    }
    for (int i = n - 1; i >= 0; --i) {                /* U x = y */
        double sum = x[i];
        for (int c = i + 1; c < n; ++c) sum -= U[i * lda + c] * x[c];
        x[i] = sum / U[i * lda + i];
    }
}

/* LU factorization with partial pivoting of the n x n row-major matrix a, in place.
 * Returns 0, or 1 if a pivot is exactly zero (the matrix is singular). */
static int lu_factor(double *a, int n, int *piv)
{
    for (int j = 0; j < n; ++j) {
        int best = j;
        for (int i = j + 1; i < n; ++i) if (fabs(a[i * n + j]) > fabs(a[best * n + j])) best = i;
        piv[j] = best;
        if (a[best * n + j] == 0.0) return 1;
        if (best != j)
            for (int c = 0; c < n; ++c) { double swap = a[j * n + c]; a[j * n + c] = a[best * n + c]; a[best * n + c] = swap; }
        double inverse = 1.0 / a[j * n + j];
        for (int i = j + 1; i < n; ++i) {
            double factor = a[i * n + j] *= inverse;
            if (factor != 0.0)
                for (int c = j + 1; c < n; ++c) a[i * n + c] -= factor * a[j * n + c];
        }
    }
    return 0;
}

/* x <- a^-1 x with the factors of lu_factor. */
static void lu_solve(const double *a, int n, const int *piv, double *x)
{
    /* the factorization swapped whole rows (the multipliers with them): all swaps first */
    for (int j = 0; j < n; ++j)
        if (piv[j] != j) { double swap = x[j]; x[j] = x[piv[j]]; x[piv[j]] = swap; }
    for (int j = 0; j < n; ++j)
        for (int i = j + 1; i < n; ++i) x[i] -= a[i * n + j] * x[j];
    for (int i = n - 1; i >= 0; --i) {
        double sum = x[i];
        for (int c = i + 1; c < n; ++c) sum -= a[i * n + c] * x[c];
        x[i] = sum / a[i * n + i];
    }
}

/* Number of magnitudes above KRONLAG_RANK_RTOL times the first (the largest). */
static int rank_of(const double *magnitudes, int n)
{
    int rank = 0;
    while (rank < n && magnitudes[rank] > KRONLAG_RANK_RTOL * magnitudes[0]) ++rank;
    return rank;
}

/* Column-pivoted Householder QR of G^T (G: rows x m, row-major) into X (m x rows), tau, perm, and
 * the magnitudes |diag R| (rows; 0 past min(m, rows)), decreasing: the rank-revealing factorization
 * of the rank policy (tolerances.py).  Returns the rank (rank_of). */
static int pivoted_qr_transpose(const double *G, int rows, int m, double *X, double *tau, int *perm,
                                double *magnitudes)
{
    for (int i = 0; i < m; ++i)
        for (int j = 0; j < rows; ++j) X[i * rows + j] = G[j * m + i];
    house_qr(X, m, rows, rows, perm, tau);
    int steps = m < rows ? m : rows;
    for (int j = 0; j < rows; ++j) magnitudes[j] = j < steps ? fabs(X[j * rows + j]) : 0.0;
    return rank_of(magnitudes, steps);
}

/* |diag R| of the column-pivoted QR of G^T (G: rows x m) in decreasing order, and perm[i], the
 * constraint row behind magnitudes[i]. */
static void rank_magnitudes(const double *G, int rows, int m, double *magnitudes, int *perm)
{
    double X[m * (rows + 1)], tau[rows + 1];
    pivoted_qr_transpose(G, rows, m, X, tau, perm, magnitudes);
}

/* x <- x - dx, dx the least-norm solution of G dx = residual for the rows x m matrix G
 * (row-major), over its independent rows: redundant rows are dropped, and for a consistent
 * residual they are met as well.  Returns the rank. */
static int min_norm_correction(const double *G, int rows, int m, const double *residual, double *x)
{
    double X[m * (rows + 1)], tau[rows + 1], magnitudes[rows + 1], y[m];
    int perm[rows + 1];
    int rank = pivoted_qr_transpose(G, rows, m, X, tau, perm, magnitudes);
    /* P^T G = R^T Q^T: R1^T y1 = (P^T residual)[:rank] (forward substitution), y2 = 0, dx = Q y. */
    for (int i = 0; i < m; ++i) y[i] = 0.0;
    for (int i = 0; i < rank; ++i) {
        double sum = residual[perm[i]];
        for (int j = 0; j < i; ++j) sum -= X[j * rows + i] * y[j];
        y[i] = sum / X[i * rows + i];
    }
    for (int j = rank - 1; j >= 0; --j) house_apply(X, m, rows, j, tau[j], y, 1);
    for (int i = 0; i < m; ++i) x[i] -= y[i];
    return rank;
}

/* The least-squares solution lam (rows) of G^T lam = b for the rows x m matrix G (row-major), over
 * its independent rows (the others get 0): the multipliers that balance the forces b.  Returns the
 * rank. */
static int least_squares_transpose(const double *G, int rows, int m, const double *b, double *lam)
{
    double X[m * (rows + 1)], tau[rows + 1], magnitudes[rows + 1], y[m], solution[rows + 1];
    int perm[rows + 1];
    int rank = pivoted_qr_transpose(G, rows, m, X, tau, perm, magnitudes);
    memcpy(y, b, m * sizeof(double));
    for (int j = 0; j < rank; ++j) house_apply(X, m, rows, j, tau[j], y, 1);   /* y = Q^T b */
    for (int i = rank - 1; i >= 0; --i) {                                        /* R1 s = y1 */
        double sum = y[i];
        for (int j = i + 1; j < rank; ++j) sum -= X[i * rows + j] * solution[j];
        solution[i] = sum / X[i * rows + i];
    }
    for (int i = 0; i < rows; ++i) lam[perm[i]] = i < rank ? solution[i] : 0.0;
    return rank;
}
