/* kronlag: forward dynamics with multipliers, the augmented system solved by a null-space method
 * (see kronlag.numeric.solve_augmented for the algorithm, and tolerances.py for the rank policy). */

/* x <- (I - tau v v^T) x for a reflector v of the given length, zero before its first entry: the loops run
 * over the whole length, a constant of the model (unrolled and vectorized; the zeros add nothing). */
static inline void kronlag_reflect(const double *v, int length, double tau, double *x)
{
    double w = 0.0;
    for (int i = 0; i < length; ++i) w += v[i] * x[i];
    w *= tau;
    for (int i = 0; i < length; ++i) x[i] -= w * v[i];
}

/* Solve [[M, G^T], [G, 0]] [qdd; nu] = [h; c] with G = [Phi_q; A] (K x m), rank-revealing.
 * terms: the output of kronlag_dynamics (the blocks of codegen.LAYOUTS["dynamics"]).
 * max_rank caps the numerical rank at the generic rank of G, which an integrator knows from its
 * start: off the constraint manifold (an integrator's state between projections) the rows of
 * redundant constraints are no longer exactly dependent, and counting them as independent would
 * solve a nearly singular system (accelerations of order drift / rounding).
 * count right-hand sides share the factorization: the first [h; c], the others [forcing_e; 0] with
 * forcing (count - 1 vectors of m) -- the response to a generalized force (joint friction); the
 * solutions go to qdd (count x m) and nu (count x (K + 1)).
 * Returns 0, or 1 when M is not positive definite on the null space of G. */
static int kronlag_solve_many(const double *terms, const double *qd, double alpha, double beta, int max_rank,
                              int count, const double *forcing, double *qdd, double *nu, int *rank)
{
    enum { m = KRONLAG_M, r = KRONLAG_R, s = KRONLAG_S, k = KRONLAG_K };
    const double *M = terms + KRONLAG_DYNAMICS_M, *h = terms + KRONLAG_DYNAMICS_H, *Phi = terms + KRONLAG_DYNAMICS_PHI;
    const double *Phi_q = terms + KRONLAG_DYNAMICS_PHI_Q, *Phi_t = terms + KRONLAG_DYNAMICS_PHI_T;
    const double *gamma = terms + KRONLAG_DYNAMICS_GAMMA;
    const double *A = terms + KRONLAG_DYNAMICS_A, *b = terms + KRONLAG_DYNAMICS_B;
    const double *gamma_nh = terms + KRONLAG_DYNAMICS_GAMMA_NH;
    double X[m * (k + 1)], tau[k + 1], c[k + 1], B[m * m];
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
    /* B = Q^T M Q with Q = H_0 ... H_{rho-1}; Z = Q[:, rho:] spans the null space of G. */
    memcpy(B, M, sizeof B);
    for (int j = 0; j < rho; ++j) house_reflect_symmetric(X, m, k, j, tau[j], B);
    /* R1^T = W T (second QR, K x rho), so that G = P R1^T Q1^T. */
    double W[(k + 1) * (k + 1)], wtau[k + 1];
    for (int i = 0; i < k; ++i)
        for (int j = 0; j < rho; ++j) W[i * k + j] = i >= j ? X[j * k + i] : 0.0;
    house_qr(W, k, rho, k, NULL, wtau);
    /* Z^T M Z = B22 by Cholesky, in place (fails if singular); B21 and the rows 0..rho-1 are kept. */
    int n = m - rho;
    double *B22 = B + rho * m + rho;
    if (cholesky_upper(B22, n, m)) return 1;
    /* The reflectors of X and W as contiguous vectors (v[j] = 1, zero above), read by every right-hand side. */
    double V[(k + 1) * m + 1], U[(k + 1) * (k + 1) + 1];
    for (int j = 0; j < rho; ++j) {
        for (int i = 0; i < m; ++i) V[j * m + i] = i < j ? 0.0 : i == j ? 1.0 : X[i * k + j];
        for (int i = 0; i < k; ++i) U[j * k + i] = i < j ? 0.0 : i == j ? 1.0 : W[i * k + j];
    }
    for (int e = 0; e < count; ++e) {
        double y[m], qt[m + 1], a[k + 1];
        /* y = Q^T h; constraint part y1 = Q1^T qdd: T y1 = W^T P^T c (least squares when redundant
         * rows are inconsistent); the responses (e > 0) have c = 0: no constraint part. */
        memcpy(y, e == 0 ? h : forcing + (e - 1) * m, sizeof y);
        for (int j = 0; j < rho; ++j) kronlag_reflect(V + j * m, m, tau[j], y);
        for (int i = 0; i < rho; ++i) qt[i] = 0.0;
        if (e == 0) {
            double cp[k + 1];
            for (int i = 0; i < k; ++i) cp[i] = c[perm[i]];
            for (int j = 0; j < rho; ++j) kronlag_reflect(U + j * k, k, wtau[j], cp);
            for (int i = rho - 1; i >= 0; --i) {
                double sum = cp[i];
                for (int j = i + 1; j < rho; ++j) sum -= W[i * k + j] * qt[j];
                qt[i] = sum / W[i * k + i];
            }
        }
        /* Null-space part y2: (Z^T M Z) y2 = Z^T h - Z^T M Q1 y1. */
        double *z = qt + rho;
        for (int i = 0; i < n; ++i) {
            double sum = y[rho + i];
            for (int j = 0; j < rho && e == 0; ++j) sum -= B[(rho + i) * m + j] * qt[j];
            z[i] = sum;
        }
        cholesky_solve(B22, n, m, z);
        /* Multipliers, minimum norm: R1 P^T nu = Q1^T (h - M qdd) = y1 - B[:rho, :] qt,
         * R1 = T^T W^T, so P^T nu = W T^{-T} (Q1^T (h - M qdd)). */
        for (int i = 0; i < rho; ++i) {
            double sum = y[i];
            for (int j = e == 0 ? 0 : rho; j < m; ++j) sum -= B[i * m + j] * qt[j];
            for (int j = 0; j < i; ++j) sum -= W[j * k + i] * a[j];
            a[i] = sum / W[i * k + i];
        }
        for (int i = rho; i < k; ++i) a[i] = 0.0;
        for (int j = rho - 1; j >= 0; --j) kronlag_reflect(U + j * k, k, wtau[j], a);
        for (int i = 0; i < k; ++i) nu[e * (k + 1) + perm[i]] = a[i];
        /* qdd = Q qt */
        for (int j = rho - 1; j >= 0; --j) kronlag_reflect(V + j * m, m, tau[j], qt);
        memcpy(qdd + e * m, qt, m * sizeof *qt);
    }
    return 0;
}

#ifdef KRONLAG_FRICTION
int kronlag_forward_dynamics_turned(double t, const double *q, const double *qd, const double *p, double alpha,
                                    double beta, int max_rank, const double *turned, double *qdd, double *lam,
                                    double *mu);

/* Joint friction: kronlag.numeric.friction is the reference of this code (the same records, from the
 * kernel kronlag_friction, and the same steps). |v - (v.u) u| for 3-vectors. */
static double kronlag_perpendicular(const double *v, const double *u)
{
    double along = v[0] * u[0] + v[1] * u[1] + v[2] * u[2], sum = 0.0;
    for (int i = 0; i < 3; ++i) { double x = v[i] - along * u[i]; sum += x * x; }
    return sqrt(sum);
}

/* One joint's wrench W lambda_J (6: force, couple) at the multipliers lam (the joint's own rows only:
 * a planar pin has 2 of the 6). */
static void kronlag_friction_wrench(const double *record, const double *lam, double *wrench)
{
    const double *W = record + KRONLAG_M, *rows = W + 36;
    for (int i = 0; i < 6; ++i) wrench[i] = 0.0;
    for (int j = 0; j < 6; ++j) {
        if (rows[j] < 0.0) continue;
        double own = lam[(int)rows[j]];
        for (int i = 0; i < 6; ++i) wrench[i] += W[i * 6 + j] * own;
    }
}

/* The fields after J_rate (m), W (36) and the rows (6): u_force (3), u_couple (3), then RECORD_FIELDS:
 * static, kinetic, viscous, stribeck_velocity, radius, 1/arm, preload, smoothing_velocity, mode,
 * hold_row (the modes of kronlag.model.friction: 0 smooth, +-1 sliding that way, 2 sign(v), 3 held,
 * 4 locked to a held joint). */
#define KRONLAG_FRICTION_FIELDS(record) ((record) + KRONLAG_M + 48)
enum { KRONLAG_MODE_SMOOTH = 0, KRONLAG_MODE_SIGN = 2, KRONLAG_MODE_HELD = 3, KRONLAG_MODE_LOCKED = 4 };

/* The records of kronlag_friction at (t, q, qd) with the direction of a joint sliding (mode +-1) turned
 * where turned[j] < 0 (any other value: as compiled): the directions a compiled run turned at kinematic
 * dead points (cvode.c), without a model per set of directions; turned NULL: all as compiled. */
static void kronlag_friction_turned(double t, const double *q, const double *qd, const double *p,
                                    const double *turned, double *records)
{
    kronlag_friction(t, q, qd, p, records);
    for (int j = 0; turned && j < KRONLAG_FRICTION; ++j) {
        double *c = KRONLAG_FRICTION_FIELDS(records + j * KRONLAG_FRICTION_RECORD);
        if ((c[8] == 1.0 || c[8] == -1.0) && turned[j] < 0.0) c[8] = -c[8];
    }
}

/* The law's sign(v) by the record's mode. */
static double kronlag_friction_direction(const double *c, double rate)
{
    int mode = (int)c[8];
    if (mode == KRONLAG_MODE_SMOOTH) return tanh(rate / c[7]);
    if (mode == KRONLAG_MODE_SIGN) return (rate > 0.0) - (rate < 0.0);
    return mode == 1 || mode == -1 ? (double)mode : 0.0; /* held or locked: no force of the law */
}

/* r mu(v): the factor of the normal load in one joint's friction force at the rate v. */
static double kronlag_friction_coefficient(const double *record, double rate)
{
    const double *c = KRONLAG_FRICTION_FIELDS(record);
    double mu = c[1];
    if (c[3] > 0.0) { double x = rate / c[3]; mu += (c[0] - c[1]) * exp(-x * x); }
    return c[4] * mu * kronlag_friction_direction(c, rate);
}

/* The normal load N from the joint's wrench (friction_force in kronlag.numeric.friction). */
static double kronlag_friction_load(const double *record, const double *wrench)
{
    const double *u_force = record + KRONLAG_M + 42, *u_couple = u_force + 3, *c = KRONLAG_FRICTION_FIELDS(record);
    return kronlag_perpendicular(wrench, u_force) + c[5] * kronlag_perpendicular(wrench + 3, u_couple) + c[6];
}

/* Solve the n x n system A x = b in place (x in b) by Gaussian elimination with partial pivoting;
 * 1 if A is singular. */
static int kronlag_small_solve(double *A, double *b, int n)
{
    for (int c = 0; c < n; ++c) {
        int pivot = c;
        for (int i = c + 1; i < n; ++i) if (fabs(A[i * n + c]) > fabs(A[pivot * n + c])) pivot = i;
        if (A[pivot * n + c] == 0.0) return 1;
        if (pivot != c) {
            for (int j = 0; j < n; ++j) { double x = A[c * n + j]; A[c * n + j] = A[pivot * n + j]; A[pivot * n + j] = x; }
            double x = b[c]; b[c] = b[pivot]; b[pivot] = x;
        }
        for (int i = c + 1; i < n; ++i) {
            double factor = A[i * n + c] / A[c * n + c];
            for (int j = c; j < n; ++j) A[i * n + j] -= factor * A[c * n + j];
            b[i] -= factor * b[c];
        }
    }
    for (int i = n - 1; i >= 0; --i) {
        for (int j = i + 1; j < n; ++j) b[i] -= A[i * n + j] * b[j];
        b[i] /= A[i * n + i];
    }
    return 0;
}

/* The solve with the friction of the joints: the solution is linear in h, so the responses to a
 * unit friction force of each joint (the forcing -J_j, right-hand sides sharing the factorization)
 * give the solution for any friction forces f, and f = phi(lambda(f)) is found by Newton steps
 * to KRONLAG_FRICTION_RTOL (the error left bounded from the last two steps' contraction, as
 * kronlag.numeric.friction._converged: 2.2 steps a call on the four-bar instead of 3.15).  A joint whose force is zero whatever the load (held by its stick row:
 * r mu and c count nothing; or r mu(v) = 0 and no viscous term) needs no response: only the others
 * are unknowns (a linkage at rest in all its pins costs one right-hand side, as without friction).
 * The steps start from f = 0 at every call, so that the solution is a function of (t, q, qd, p) alone:
 * not of the calls before it, which may be another model's sharing this library (with_parameters, a
 * segment's trial holds).  (Measured on the four-bar, starting from the last call's forces saved 0.15
 * of 3.15 steps a call, and let a step from a stale start decide where a wedged trial converged.)
 * Returns 0, 1 (singular) or 2 (the friction forces did not converge). */

static int kronlag_friction_solve(double t, const double *q, const double *qd, const double *p, const double *terms,
                                  double alpha, double beta, int max_rank, const double *turned, double *qdd,
                                  double *nu, int *rank)
{
    enum { m = KRONLAG_M, k = KRONLAG_K, nf = KRONLAG_FRICTION, size = KRONLAG_FRICTION_RECORD };
    double records[nf * size + 1], forcing[nf * m], accelerations[(nf + 1) * m], multipliers[(nf + 1) * (k + 1)];
    double rates[nf], forces[nf], factor[nf], viscous[nf];
    int active[nf], na = 0;  /* the joints whose force can be nonzero: the unknowns */
    kronlag_friction_turned(t, q, qd, p, turned, records);
    for (int j = 0; j < nf; ++j) {
        const double *record = records + j * size;
        rates[j] = 0.0;
        for (int i = 0; i < m; ++i) rates[j] += record[i] * qd[i];
        factor[j] = kronlag_friction_coefficient(record, rates[j]);
        int mode = (int)KRONLAG_FRICTION_FIELDS(record)[8];
        viscous[j] = mode == KRONLAG_MODE_HELD || mode == KRONLAG_MODE_LOCKED ? 0.0
                     : KRONLAG_FRICTION_FIELDS(record)[2] * rates[j];
        if (factor[j] == 0.0 && viscous[j] == 0.0) continue;
        forces[na] = 0.0;
        active[na++] = j;
    }
    /* The responses: to each unknown's forcing -J_j, or, when the joints' rates read fewer coordinates
     * than there are unknowns (the support of their J_j: a planar linkage's pins read its few angles), to
     * the unit forcings -e_i of those coordinates, combined as sum_i J_j[i] (response to -e_i): fewer
     * right-hand sides, the same solution (linear in the forcing; no rank decision, exact zeros only). */
    int support[m], ns = 0;
    for (int i = 0; i < m; ++i)
        for (int c = 0; c < na; ++c)
            if (records[active[c] * size + i] != 0.0) { support[ns++] = i; break; }
    int by_coordinate = ns < na, count = by_coordinate ? ns : na;
    for (int e = 0; e < count; ++e)
        for (int i = 0; i < m; ++i)
            forcing[e * m + i] = by_coordinate ? -(double)(i == support[e]) : -records[active[e] * size + i];
    int status = kronlag_solve_many(terms, qd, alpha, beta, max_rank, count + 1, forcing, accelerations, multipliers,
                                    rank);
    if (status) return status;
    const double *dqdd = accelerations + m, *dnu = multipliers + (k + 1);
    double combined_qdd[nf * m + 1], combined_nu[nf * (k + 1) + 1];
    if (by_coordinate) {
        for (int c = 0; c < na; ++c) {
            const double *J = records + active[c] * size;
            for (int i = 0; i < m; ++i) combined_qdd[c * m + i] = 0.0;
            for (int i = 0; i < k + 1; ++i) combined_nu[c * (k + 1) + i] = 0.0;
            for (int e = 0; e < ns; ++e) {
                double weight = J[support[e]];
                for (int i = 0; i < m; ++i) combined_qdd[c * m + i] += weight * dqdd[e * m + i];
                for (int i = 0; i < k + 1; ++i) combined_nu[c * (k + 1) + i] += weight * dnu[e * (k + 1) + i];
            }
        }
        dqdd = combined_qdd;
        dnu = combined_nu;
    }
    /* per unknown c (joint active[c]): its wrench without friction and per unit friction force of the
     * unknown d (linear in f), so that each step is a few flops a joint */
    double wrench[nf][6], response[nf][nf][6];
    for (int c = 0; c < na; ++c) {
        const double *record = records + active[c] * size;
        kronlag_friction_wrench(record, multipliers, wrench[c]);
        for (int d = 0; d < na; ++d) kronlag_friction_wrench(record, dnu + d * (k + 1), response[c][d]);
    }
    /* Newton steps on g(f) = f - r mu N(f) - c v = 0 (N(f) piecewise linear in f: its derivative is the
     * unit direction of the force and couple parts times their responses), from f = 0 */
    int converged = 0;
    double previous = 0.0;  /* the last step's largest change */
    for (int step = 0; step < KRONLAG_FRICTION_MAX_ITERATIONS && !converged; ++step) {
        double jacobian[nf * nf + 1], residual[nf + 1];
        for (int c = 0; c < na; ++c) {
            int j = active[c];
            const double *record = records + j * size, *u_force = record + m + 42, *u_couple = u_force + 3;
            double total[6], direction[6];
            for (int a = 0; a < 6; ++a) {
                total[a] = wrench[c][a];
                for (int d = 0; d < na; ++d) total[a] += forces[d] * response[c][d][a];
            }
            residual[c] = forces[c] - factor[j] * kronlag_friction_load(record, total) - viscous[j];
            /* d|p|/dw = p / |p| with p = w - (w.u) u (p is perpendicular to u), zero where p = 0 */
            for (int part = 0; part < 2; ++part) {
                const double *w = total + 3 * part, *u = part ? u_couple : u_force;
                double along = w[0] * u[0] + w[1] * u[1] + w[2] * u[2];
                double weight = part ? KRONLAG_FRICTION_FIELDS(record)[5] : 1.0, norm = 0.0;
                double *e = direction + 3 * part;
                for (int a = 0; a < 3; ++a) { e[a] = w[a] - along * u[a]; norm += e[a] * e[a]; }
                norm = sqrt(norm);
                for (int a = 0; a < 3; ++a) e[a] = norm > 0.0 ? weight * e[a] / norm : 0.0;
            }
            for (int d = 0; d < na; ++d) {
                double slope = 0.0;
                for (int a = 0; a < 6; ++a) slope += direction[a] * response[c][d][a];
                jacobian[c * na + d] = (c == d) - factor[j] * slope;
            }
        }
        if (kronlag_small_solve(jacobian, residual, na)) return 2;
        double change = 0.0, largest = 0.0;
        for (int c = 0; c < na; ++c) {
            forces[c] -= residual[c];
            change = fmax(change, fabs(residual[c]));
            largest = fmax(largest, fabs(forces[c]));
        }
        /* the error left after this step, bounded from the contraction theta of the last two steps
         * (theta / (1 - theta) times this step's change, valid for linear convergence and an upper
         * bound for Newton's quadratic one): a step less than confirming what the last one found */
        double theta = previous > 0.0 ? change / previous : 1.0;
        converged = change <= KRONLAG_FRICTION_RTOL * largest
                    || (theta < 1.0 && theta / (1.0 - theta) * change <= KRONLAG_FRICTION_RTOL * largest);
        previous = change;
    }
    if (!converged) return 2;
    for (int i = 0; i < m; ++i) {
        qdd[i] = accelerations[i];
        for (int c = 0; c < na; ++c) qdd[i] += forces[c] * dqdd[c * m + i];
    }
    for (int i = 0; i < k; ++i) {
        nu[i] = multipliers[i];
        for (int c = 0; c < na; ++c) nu[i] += forces[c] * dnu[c * (k + 1) + i];
    }
    return 0;
}

/* Exact stiction (kronlag.simulation.stiction): what a run watches per joint with friction, each
 * positive while nothing happens -- d v for a joint sliding in the direction d, r mu_s N - |f| for a
 * held one (f = nu[hold_row], nu = [lam; mu] from the forward dynamics without Baumgarte terms), 1
 * otherwise (stiction_values in kronlag.numeric.friction).  lam and mu: the multipliers at the state,
 * or NULL: then solved here only when a joint is held (sliding ones need the rates alone, and the
 * root function is called at every step); turned: as for kronlag_friction_turned.  Returns 0, or the
 * forward dynamics' failure. */
static int kronlag_stiction_values(double t, const double *q, const double *qd, const double *p, const double *turned,
                                   const double *lam, const double *mu, double *out)
{
    enum { m = KRONLAG_M, r = KRONLAG_R, s = KRONLAG_S, k = KRONLAG_K, nf = KRONLAG_FRICTION,
           size = KRONLAG_FRICTION_RECORD };
    double records[nf * size + 1], nu[k + 1], wrench[6], own_lam[r + 1], own_mu[s + 1], qdd[m + 1];
    kronlag_friction_turned(t, q, qd, p, turned, records);
    int held = 0;
    for (int j = 0; j < nf; ++j) held |= (int)KRONLAG_FRICTION_FIELDS(records + j * size)[8] == KRONLAG_MODE_HELD;
    if (held && !lam) {
        int status = kronlag_forward_dynamics_turned(t, q, qd, p, 0.0, 0.0, k, turned, qdd, own_lam, own_mu);
        if (status) return status;
        lam = own_lam;
        mu = own_mu;
    }
    for (int i = 0; i < k && held; ++i) nu[i] = i < r ? lam[i] : mu[i - r];
    for (int j = 0; j < nf; ++j) {
        const double *record = records + j * size, *c = KRONLAG_FRICTION_FIELDS(record);
        int mode = (int)c[8];
        out[j] = 1.0;
        if (mode == 1 || mode == -1) {
            double rate = 0.0;
            for (int i = 0; i < m; ++i) rate += record[i] * qd[i];
            out[j] = mode * rate;
        } else if (mode == KRONLAG_MODE_HELD) {
            kronlag_friction_wrench(record, nu, wrench);
            out[j] = c[4] * c[0] * kronlag_friction_load(record, wrench) - fabs(nu[(int)c[9]]);
        }
    }
    return 0;
}
#define KRONLAG_STICTION_WATCHED KRONLAG_FRICTION
#else
#define KRONLAG_STICTION_WATCHED 0
#endif

/* The solve at a state: with the joints' friction when the model has any (their sliding directions
 * turned by turned, NULL: as compiled; kronlag_friction_turned). */
static int kronlag_solve_turned(double t, const double *q, const double *qd, const double *p, const double *terms,
                                double alpha, double beta, int max_rank, const double *turned, double *qdd, double *nu,
                                int *rank)
{
#ifdef KRONLAG_FRICTION
    return kronlag_friction_solve(t, q, qd, p, terms, alpha, beta, max_rank, turned, qdd, nu, rank);
#else
    (void)t; (void)q; (void)p; (void)turned;
    return kronlag_solve_many(terms, qd, alpha, beta, max_rank, 1, NULL, qdd, nu, rank);
#endif
}

/* The solve at a state with the directions as compiled. */
static int kronlag_solve_at(double t, const double *q, const double *qd, const double *p, const double *terms,
                            double alpha, double beta, int max_rank, double *qdd, double *nu, int *rank)
{
    return kronlag_solve_turned(t, q, qd, p, terms, alpha, beta, max_rank, NULL, qdd, nu, rank);
}

/* Forward dynamics with multipliers (Baumgarte alpha, beta), at most max_rank independent rows of
 * [Phi_q; A] (KRONLAG_K: the numerical rank alone decides), the sliding directions turned by turned
 * (kronlag_friction_turned); 0 on success, 1 if singular. */
int kronlag_forward_dynamics_turned(double t, const double *q, const double *qd, const double *p, double alpha,
                                    double beta, int max_rank, const double *turned, double *qdd, double *lam,
                                    double *mu)
{
    double terms[KRONLAG_DYNAMICS_SIZE + 1], nu[KRONLAG_K + 1];
    int rank;
    kronlag_dynamics(t, q, qd, p, terms);
    int status = kronlag_solve_turned(t, q, qd, p, terms, alpha, beta, max_rank, turned, qdd, nu, &rank);
    for (int j = 0; j < KRONLAG_R; ++j) lam[j] = nu[j];
    for (int j = 0; j < KRONLAG_S; ++j) mu[j] = nu[KRONLAG_R + j];
    return status;
}

/* kronlag_forward_dynamics_turned with the directions as compiled. */
int kronlag_forward_dynamics_ranked(double t, const double *q, const double *qd, const double *p,
                                    double alpha, double beta, int max_rank, double *qdd, double *lam, double *mu)
{
    return kronlag_forward_dynamics_turned(t, q, qd, p, alpha, beta, max_rank, NULL, qdd, lam, mu);
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
