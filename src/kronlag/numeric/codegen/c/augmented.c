/* kronlag: forward dynamics with multipliers, the augmented system solved by a null-space method
 * (see kronlag.numeric.solve_augmented for the algorithm, and tolerances.py for the rank policy). */

/* Solve [[M, G^T], [G, 0]] [qdd; nu] = [h; c] with G = [Phi_q; A] (K x m), rank-revealing.
 * terms: the output of kronlag_dynamics (the blocks of codegen.LAYOUTS["dynamics"]).
 * max_rank caps the numerical rank at the generic rank of G, which an integrator knows from its
 * start: off the constraint manifold (an integrator's state between projections) the rows of
 * redundant constraints are no longer exactly dependent, and counting them as independent would
 * solve a nearly singular system (accelerations of order drift / rounding).
 * Returns 0, or 1 when M is not positive definite on the null space of G. */
static int kronlag_solve(const double *terms, const double *qd, double alpha, double beta, int max_rank,
                         double *qdd, double *nu, int *rank)
{
    enum { m = KRONLAG_M, r = KRONLAG_R, s = KRONLAG_S, k = KRONLAG_K };
    const double *M = terms + KRONLAG_DYNAMICS_M, *h = terms + KRONLAG_DYNAMICS_H, *Phi = terms + KRONLAG_DYNAMICS_PHI;
    const double *Phi_q = terms + KRONLAG_DYNAMICS_PHI_Q, *Phi_t = terms + KRONLAG_DYNAMICS_PHI_T;
    const double *gamma = terms + KRONLAG_DYNAMICS_GAMMA;
    const double *A = terms + KRONLAG_DYNAMICS_A, *b = terms + KRONLAG_DYNAMICS_B;
    const double *gamma_nh = terms + KRONLAG_DYNAMICS_GAMMA_NH;
    double X[m * (k + 1)], tau[k + 1], c[k + 1], B[m * m], y[m];
    int perm[k + 1];
    /* X = G^T (m x k), c = [gamma - 2 alpha (Phi_q qd + Phi_t) - beta^2 Phi; gamma_nh - alpha (A qd + b)] */
    for (int j = 0; j < k; ++j) {
        const double *row = j < r ? Phi_q + j * m : A + (j - r) * m;
        double velocity = 0.0;
        for (int i = 0; i < m; ++i) { X[i * k + j] = row[i]; velocity += row[i] * qd[i]; }
        c[j] = j < r ? gamma[j] - 2.0 * alpha * (velocity + Phi_t[j]) - beta * beta * Phi[j]
                     : gamma_nh[j - r] - alpha * (velocity + b[j - r]);
    }
    house_qr(X, m, k, k, perm, tau);
    int steps = m < k ? m : k;
    double magnitudes[k + 1];
    for (int j = 0; j < steps; ++j) magnitudes[j] = fabs(X[j * k + j]);
    int rho = rank_of(magnitudes, steps);
    if (rho > max_rank) rho = max_rank;
    *rank = rho;
    /* B = Q^T M Q, y = Q^T h with Q = H_0 ... H_{rho-1}; Z = Q[:, rho:] spans the null space of G. */
    memcpy(B, M, sizeof B);
    memcpy(y, h, sizeof y);
    for (int j = 0; j < rho; ++j) {
        house_reflect_symmetric(X, m, k, j, tau[j], B);
        house_apply(X, m, k, j, tau[j], y, 1);
    }
    /* R1^T = W T (second QR, K x rho), so that G = P R1^T Q1^T. Constraint part y1 = Q1^T qdd:
     * T y1 = W^T P^T c (least squares when redundant rows are inconsistent). */
    double W[(k + 1) * (k + 1)], wtau[k + 1], cp[k + 1];
    for (int i = 0; i < k; ++i) {
        cp[i] = c[perm[i]];
        for (int j = 0; j < rho; ++j) W[i * k + j] = i >= j ? X[j * k + i] : 0.0;
    }
    house_qr(W, k, rho, k, NULL, wtau);
    for (int j = 0; j < rho; ++j) house_apply(W, k, k, j, wtau[j], cp, 1);
    double qt[m];
    for (int i = rho - 1; i >= 0; --i) {
        double sum = cp[i];
        for (int j = i + 1; j < rho; ++j) sum -= W[i * k + j] * qt[j];
        qt[i] = sum / W[i * k + i];
    }
    /* Null-space part y2: (Z^T M Z) y2 = Z^T h - Z^T M Q1 y1, Cholesky (fails if singular). */
    int n = m - rho;
    double *B22 = B + rho * m + rho, *z = qt + rho;
    for (int i = 0; i < n; ++i) {
        double sum = y[rho + i];
        for (int j = 0; j < rho; ++j) sum -= B[(rho + i) * m + j] * qt[j];
        z[i] = sum;
    }
    /* the multipliers below need the rows 0..rho-1 of B only: B22 may be factorized in place */
    if (cholesky_upper(B22, n, m)) return 1;
    cholesky_solve(B22, n, m, z);
    /* Multipliers, minimum norm: R1 P^T nu = Q1^T (h - M qdd) = y1 - B[:rho, :] qt,
     * R1 = T^T W^T, so P^T nu = W T^{-T} (Q1^T (h - M qdd)). */
    double a[k + 1];
    for (int i = 0; i < rho; ++i) {
        double sum = y[i];
        for (int j = 0; j < m; ++j) sum -= B[i * m + j] * qt[j];
        for (int j = 0; j < i; ++j) sum -= W[j * k + i] * a[j];
        a[i] = sum / W[i * k + i];
    }
    for (int i = rho; i < k; ++i) a[i] = 0.0;
    for (int j = rho - 1; j >= 0; --j) house_apply(W, k, k, j, wtau[j], a, 1);
    for (int i = 0; i < k; ++i) nu[perm[i]] = a[i];
    /* qdd = Q qt */
    for (int j = rho - 1; j >= 0; --j) house_apply(X, m, k, j, tau[j], qt, 1);
    memcpy(qdd, qt, sizeof qt);
    return 0;
}

#ifdef KRONLAG_FRICTION
/* Joint friction: kronlag.numeric.friction is the reference of this code (the same records, from the
 * kernel kronlag_friction, and the same steps). |v - (v.u) u| for 3-vectors. */
static double kronlag_perpendicular(const double *v, const double *u)
{
    double along = v[0] * u[0] + v[1] * u[1] + v[2] * u[2], sum = 0.0;
    for (int i = 0; i < 3; ++i) { double x = v[i] - along * u[i]; sum += x * x; }
    return sqrt(sum);
}

/* One joint's friction force (torque) at the multipliers lam and its rate (friction_force in Python). */
static double kronlag_friction_force(const double *record, const double *lam, double rate)
{
    const double *W = record + KRONLAG_M, *rows = W + 36, *u_force = rows + 6, *u_couple = u_force + 3;
    const double *c = u_couple + 3; /* RECORD_FIELDS: static, kinetic, viscous, stribeck, radius, 1/arm, preload, eps */
    double own[6], wrench[6];
    for (int j = 0; j < 6; ++j) own[j] = rows[j] >= 0.0 ? lam[(int)rows[j]] : 0.0;
    for (int i = 0; i < 6; ++i) {
        wrench[i] = 0.0;
        for (int j = 0; j < 6; ++j) wrench[i] += W[i * 6 + j] * own[j];
    }
    double load = kronlag_perpendicular(wrench, u_force) + c[5] * kronlag_perpendicular(wrench + 3, u_couple) + c[6];
    double mu = c[1];
    if (c[3] > 0.0) { double x = rate / c[3]; mu += (c[0] - c[1]) * exp(-x * x); }
    mu *= tanh(rate / c[7]);
    return c[4] * mu * load + c[2] * rate;
}

/* kronlag_solve with the friction of the joints: the solution is linear in h, so one more solve per joint
 * gives the change a unit friction force causes, and the friction forces f = phi(lambda(f)) are found
 * by fixed-point steps to KRONLAG_FRICTION_RTOL.  terms' h is changed and restored.
 * Returns 0, 1 (singular) or 2 (the friction forces did not converge). */
static int kronlag_friction_solve(double t, const double *q, const double *qd, const double *p, double *terms,
                                  double alpha, double beta, int max_rank, double *qdd, double *nu, int *rank)
{
    enum { m = KRONLAG_M, k = KRONLAG_K, nf = KRONLAG_FRICTION, size = KRONLAG_FRICTION_RECORD };
    double records[nf * size + 1], dqdd[nf][m], dnu[nf][k + 1], rates[nf], forces[nf], lam[k + 1], saved[m];
    int status = kronlag_solve(terms, qd, alpha, beta, max_rank, qdd, nu, rank);
    if (status) return status;
    kronlag_friction(t, q, qd, p, records);
    double *h = terms + KRONLAG_DYNAMICS_H;
    memcpy(saved, h, sizeof saved);
    for (int j = 0; j < nf && !status; ++j) {
        const double *J = records + j * size;
        int unused;
        rates[j] = 0.0;
        forces[j] = 0.0;
        for (int i = 0; i < m; ++i) { h[i] = saved[i] - J[i]; rates[j] += J[i] * qd[i]; }
        status = kronlag_solve(terms, qd, alpha, beta, max_rank, dqdd[j], dnu[j], &unused);
        for (int i = 0; i < m; ++i) dqdd[j][i] -= qdd[i];
        for (int i = 0; i < k; ++i) dnu[j][i] -= nu[i];
    }
    memcpy(h, saved, sizeof saved);
    if (status) return status;
    int converged = 0;
    for (int step = 0; step < KRONLAG_FRICTION_MAX_ITERATIONS && !converged; ++step) {
        for (int i = 0; i < k; ++i) {
            lam[i] = nu[i];
            for (int j = 0; j < nf; ++j) lam[i] += forces[j] * dnu[j][i];
        }
        double change = 0.0, largest = 0.0;
        for (int j = 0; j < nf; ++j) {
            double f = kronlag_friction_force(records + j * size, lam, rates[j]);
            change = fmax(change, fabs(f - forces[j]));
            largest = fmax(largest, fabs(f));
            forces[j] = f;
        }
        converged = change <= KRONLAG_FRICTION_RTOL * largest;
    }
    if (!converged) return 2;
    for (int j = 0; j < nf; ++j) {
        for (int i = 0; i < m; ++i) qdd[i] += forces[j] * dqdd[j][i];
        for (int i = 0; i < k; ++i) nu[i] += forces[j] * dnu[j][i];
    }
    return 0;
}
#endif

/* The solve at a state: with the joints' friction when the model has any. */
static int kronlag_solve_at(double t, const double *q, const double *qd, const double *p, double *terms,
                            double alpha, double beta, int max_rank, double *qdd, double *nu, int *rank)
{
#ifdef KRONLAG_FRICTION
    return kronlag_friction_solve(t, q, qd, p, terms, alpha, beta, max_rank, qdd, nu, rank);
#else
    (void)t; (void)q; (void)p;
    return kronlag_solve(terms, qd, alpha, beta, max_rank, qdd, nu, rank);
#endif
}

/* Forward dynamics with multipliers (Baumgarte alpha, beta), at most max_rank independent rows of
 * [Phi_q; A] (KRONLAG_K: the numerical rank alone decides); 0 on success, 1 if singular. */
int kronlag_forward_dynamics_ranked(double t, const double *q, const double *qd, const double *p,
                                    double alpha, double beta, int max_rank, double *qdd, double *lam, double *mu)
{
    double terms[KRONLAG_DYNAMICS_SIZE + 1], nu[KRONLAG_K + 1];
    int rank;
    kronlag_dynamics(t, q, qd, p, terms);
    int status = kronlag_solve_at(t, q, qd, p, terms, alpha, beta, max_rank, qdd, nu, &rank);
    for (int j = 0; j < KRONLAG_R; ++j) lam[j] = nu[j];
    for (int j = 0; j < KRONLAG_S; ++j) mu[j] = nu[KRONLAG_R + j];
    return status;
}

/* Forward dynamics with multipliers (Baumgarte alpha, beta); 0 on success, 1 if singular. */
int kronlag_forward_dynamics(double t, const double *q, const double *qd, const double *p,
                             double alpha, double beta, double *qdd, double *lam, double *mu)
{
    return kronlag_forward_dynamics_ranked(t, q, qd, p, alpha, beta, KRONLAG_K, qdd, lam, mu);
}

/* Entry point for Python: in = [t, alpha, beta, q (m), qd (m), p (P)], out = [qdd (m), lambda (r), mu (s)];
 * returns the rank of [Phi_q; A], -1 when the configuration is singular, -2 when the joints' friction
 * forces did not converge. */
int kronlag_forward_dynamics_packed(const double *in, double *out)
{
    double terms[KRONLAG_DYNAMICS_SIZE + 1];
    int rank;
    const double *q = in + 3, *qd = q + KRONLAG_M;
    kronlag_dynamics(in[0], q, qd, qd + KRONLAG_M, terms);
    int status = kronlag_solve_at(in[0], q, qd, qd + KRONLAG_M, terms, in[1], in[2], KRONLAG_K, out, out + KRONLAG_M,
                                  &rank);
    return status ? -status : rank;
}
