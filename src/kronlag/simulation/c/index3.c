/* kronlag compiled index-3 integrator: augmented Lagrangian formulation with mass-orthogonal
 * projections of velocities and accelerations (ALI3-P: Bayo & Ledesma, Nonlinear Dyn. 9 (1996)
 * 113-130; Cuadrado, Cardenal, Morer & Bayo, Multibody Syst. Dyn. 4 (2000) 55-73), trapezoidal
 * rule, with local error control.
 *
 * Appended to the C source of a kronlag NumericModel together with the "tangent" and
 * "potential_energy" kernels (kronlag.simulation.Index3Solver); reads the block offsets
 * KRONLAG_DYNAMICS_* and KRONLAG_TANGENT_* and the policy macros of tolerances.py.
 *
 * Step from t to t + h (q0, v0, a0, lam0 known).  The trapezoidal rule ties the new velocities
 * and accelerations to the new positions q:
 *     v = 2/h (q - q0) - v0,     a = 4/h^2 (q - q0) - 4/h v0 - a0,
 * and q solves the equations of motion with the constraint forces of an augmented Lagrangian,
 *     M a + C v + g - f_Q + Phi_q^T (lam* + alpha Phi) = 0,
 * by Newton's method with the exact tangent matrix generated symbolically,
 *     J = M + h/2 D + h^2/4 (K + alpha Phi_q^T Phi_q),   K = de/dq, D = de/dqd,
 * and the multiplier update lam* <- lam* + alpha Phi after every iteration (the constraints
 * are met exactly at convergence; lam = lam* + alpha Phi).  J stays positive definite where
 * Phi_q loses rank (singular configurations, redundant constraints), so no rank decision is
 * needed in the step.  Then the velocities and accelerations are projected onto
 * Phi_q v = 0 and Phi_q a = gamma in the metric of J (mass-orthogonal):
 *     J v <- J v - h^2/4 alpha Phi_q^T Phi_q v,
 *     J a <- J a - h^2/4 alpha Phi_q^T (Phi_q a - gamma(q, v)).
 * alpha = KL3_KAPPA * 4/h^2 * max diag M / max |Phi_q row|^2 makes the penalty KL3_KAPPA times
 * the inertia in J whatever the step size and the units.
 *
 * Error control: the local error of the trapezoidal rule in q is -h^3/12 q''' ~ -h^2/12 (a - a0);
 * its weighted RMS norm with weights 1 / (atol + rtol |q|) must be <= 1. */

#define KL3_MAX_NEWTON 20
#define KL3_NEWTON_TOL 1e-3    /* weighted RMS of the last Newton correction, error-norm units */
#define KL3_ROUNDING 1e-13     /* a Newton correction below this (1 + |q|) is at rounding level */
#define KL3_WEAK 1e-8          /* ... and below this near a singular configuration */
#define KL3_KAPPA 1e8
#define KL3_SAFETY 0.9
#define KL3_GROWTH 4.0
#define KL3_SHRINK 0.2
#define KL3_FIRST_STEP 1e-3   /* of the time span */
#define KL3_MAX_RETRIES 60   /* consecutive rejected attempts of one step */
#define KL3_TOO_MUCH_WORK (-1)
#define KL3_STEP_TOO_SMALL (-2)
#define KL3_NEWTON_FAILED (-3)
#define KL3_START_FAILED (-6)
#define KL3_HANDBACK 1
#define KL3_OUTPUTS_FULL (-7)

enum { KL3_M = KRONLAG_M, KL3_R = KRONLAG_R };

typedef struct {
    const double *p;
    double *pext;   /* [p (P), a (m), nu (r)]: the inputs of the tangent kernel */
    int n_parameters;
    double rtol, atol, mass_scale, constraint_scale;
    double terms[KRONLAG_DYNAMICS_SIZE + 1], tangent[KRONLAG_TANGENT_SIZE + 1];
    double J[KL3_M * KL3_M];
    int pivots[KL3_M];
    long newton_iterations, jacobians;
} kl3_state;

static double kl3_norm(const double *e, const double *q0, const double *q1, const kl3_state *s)
{
    double sum = 0.0;
    for (int i = 0; i < KL3_M; ++i) {
        double w = s->atol + s->rtol * fmax(fabs(q0[i]), fabs(q1[i]));
        sum += (e[i] / w) * (e[i] / w);
    }
    return sqrt(sum / KL3_M);
}

/* x = J^-1 (c Phi_q^T r) with the current factors: the penalty projection of a constraint
 * residual r (r entries). */
static void kl3_project(kl3_state *s, const double *Phi_q, const double *r, double c, double *x)
{
    for (int i = 0; i < KL3_M; ++i) {
        double sum = 0.0;
        for (int k = 0; k < KL3_R; ++k) sum += Phi_q[k * KL3_M + i] * r[k];
        x[i] = c * sum;
    }
    lu_solve(s->J, KL3_M, s->pivots, x);
}

/* One step of size h from (t, q0, v0, a0, lam0) to (q1, v1, a1, lam1).
 * Returns 0 or KL3_NEWTON_FAILED; *error: the local error norm. */
static int kl3_step(kl3_state *s, double t, double h, const double *q0, const double *v0, const double *a0,
                    const double *lam0, double *q1, double *v1, double *a1, double *lam1, double *error)
{
    enum { m = KL3_M, r = KL3_R };
    double lamstar[r + 1], nu[r + 1], F[m], residual[r + 1], x[m];
    const double *M = s->terms + KRONLAG_DYNAMICS_M, *hvec = s->terms + KRONLAG_DYNAMICS_H;
    const double *Phi = s->terms + KRONLAG_DYNAMICS_PHI, *Phi_q = s->terms + KRONLAG_DYNAMICS_PHI_Q;
    const double *gamma = s->terms + KRONLAG_DYNAMICS_GAMMA;
    const double *K = s->tangent + KRONLAG_TANGENT_K, *D = s->tangent + KRONLAG_TANGENT_D;
    double alpha = KL3_KAPPA * 4.0 / (h * h) * s->mass_scale / s->constraint_scale;
    double c = h * h / 4.0, t1 = t + h;
    double *a = s->pext + s->n_parameters, *pnu = a + m;
    for (int i = 0; i < m; ++i) q1[i] = q0[i] + h * v0[i] + 0.5 * h * h * a0[i];
    for (int k = 0; k < r; ++k) lamstar[k] = lam0[k];
    int converged = 0;
    for (int iteration = 0; ; ++iteration) {
        for (int i = 0; i < m; ++i) {
            v1[i] = 2.0 / h * (q1[i] - q0[i]) - v0[i];
            a[i] = 4.0 / (h * h) * (q1[i] - q0[i]) - 4.0 / h * v0[i] - a0[i];
        }
        kronlag_dynamics(t1, q1, v1, s->p, s->terms);
        for (int k = 0; k < r; ++k) {
            if (iteration > 0) lamstar[k] += alpha * Phi[k];
            nu[k] = lamstar[k] + alpha * Phi[k];
        }
        for (int i = 0; i < m; ++i) if (!isfinite(a[i]) || !isfinite(v1[i])) return KL3_NEWTON_FAILED;
        if (converged) break;
        if (iteration == KL3_MAX_NEWTON) return KL3_NEWTON_FAILED;
        for (int i = 0; i < m; ++i) {
            double sum = -hvec[i];
            for (int j = 0; j < m; ++j) sum += M[i * m + j] * a[j];
            for (int k = 0; k < r; ++k) sum += Phi_q[k * m + i] * nu[k];
            F[i] = -c * sum;
        }
        /* K gets the curvature term of lam* only: that of the penalty, alpha Phi_qq Phi, is left
         * out (Gauss-Newton), as it makes J indefinite while Phi is far from zero */
        memcpy(pnu, lamstar, r * sizeof(double));
        kronlag_tangent(t1, q1, v1, s->pext, s->tangent);
        for (int i = 0; i < m; ++i)
            for (int j = 0; j < m; ++j) {
                double penalty = 0.0;
                for (int k = 0; k < r; ++k) penalty += Phi_q[k * m + i] * Phi_q[k * m + j];
                s->J[i * m + j] = M[i * m + j] + 0.5 * h * D[i * m + j] + c * (K[i * m + j] + alpha * penalty);
            }
        ++s->jacobians;
        ++s->newton_iterations;
        if (lu_factor(s->J, m, s->pivots)) return KL3_NEWTON_FAILED;
        lu_solve(s->J, m, s->pivots, F);
        for (int i = 0; i < m; ++i) q1[i] += F[i];
        /* converged: the correction is small against the error tolerances, or at rounding level */
        double largest = 0.0, correction = 0.0;
        for (int i = 0; i < m; ++i) { largest = fmax(largest, fabs(q1[i])); correction = fmax(correction, fabs(F[i])); }
        /* Near a singular configuration the position in the weakly constrained direction is
         * determined only to ~ eps / sigma_min^2 and the multiplier update converges slowly there:
         * after KL3_MAX_NEWTON iterations a correction below the local error tolerance, or below
         * KL3_WEAK (1 + |q|), is accepted. */
        double size = kl3_norm(F, q0, q1, s);
        converged = size <= KL3_NEWTON_TOL || correction <= KL3_ROUNDING * (1.0 + largest)
                    || (iteration + 1 == KL3_MAX_NEWTON && (size <= 1.0 || correction <= KL3_WEAK * (1.0 + largest)));
    }
    memcpy(lam1, nu, r * sizeof(double));
    memcpy(a1, a, m * sizeof(double));
    /* velocity projection onto Phi_q v + Phi_t = 0 (the terms are those of the converged q1, v1) */
    for (int k = 0; k < r; ++k) {
        double sum = s->terms[KRONLAG_DYNAMICS_PHI_T + k];
        for (int i = 0; i < m; ++i) sum += Phi_q[k * m + i] * v1[i];
        residual[k] = sum;
    }
    kl3_project(s, Phi_q, residual, c * alpha, x);
    for (int i = 0; i < m; ++i) v1[i] -= x[i];
    /* acceleration projection with gamma at the projected velocities */
    kronlag_dynamics(t1, q1, v1, s->p, s->terms);
    for (int k = 0; k < r; ++k) {
        double sum = -gamma[k];
        for (int i = 0; i < m; ++i) sum += Phi_q[k * m + i] * a1[i];
        residual[k] = sum;
    }
    kl3_project(s, Phi_q, residual, c * alpha, x);
    /* local error in q: -h^3/12 q''' ~ -h^2/12 (a1 - a0) */
    for (int i = 0; i < m; ++i) {
        a1[i] -= x[i];
        F[i] = h * h / 12.0 * (a1[i] - a0[i]);
    }
    *error = kl3_norm(F, q0, q1, s);
    return 0;
}

/* Outputs at the state (t, q, v, a) (current: s->terms already hold its kernel values): y = [q, v],
 * qdd, the multipliers, kinetic and potential
 * energy, Phi (r) and Phi_q v + Phi_t (r).  The multipliers are the least-squares solution of
 * Phi_q^T lam = f_Q - C v - g - M a (the iteration's lam* + alpha Phi carries the rounding of
 * Phi times alpha). */
static void kl3_output(kl3_state *s, int row, int current, double t, const double *q, const double *v,
                       const double *a, double *t_out, double *y_out, double *qdd_out, double *lam_out,
                       double *energies, double *phi_out, double *velocity_out)
{
    enum { m = KL3_M, r = KL3_R };
    double potential, forces[m], lam[r + 1];
    if (!current) kronlag_dynamics(t, q, v, s->p, s->terms);  /* else s->terms are those of (t, q, v) */
    for (int i = 0; i < m; ++i) {
        double sum = s->terms[KRONLAG_DYNAMICS_H + i];
        for (int j = 0; j < m; ++j) sum -= s->terms[KRONLAG_DYNAMICS_M + i * m + j] * a[j];
        forces[i] = sum;
    }
    if (r > 0) least_squares_transpose(s->terms + KRONLAG_DYNAMICS_PHI_Q, r, m, forces, lam);
    kronlag_potential_energy(t, q, v, s->p, &potential);
    const double *M = s->terms + KRONLAG_DYNAMICS_M, *Phi = s->terms + KRONLAG_DYNAMICS_PHI;
    const double *Phi_q = s->terms + KRONLAG_DYNAMICS_PHI_Q;
    t_out[row] = t;
    memcpy(y_out + row * 2 * m, q, m * sizeof(double));
    memcpy(y_out + row * 2 * m + m, v, m * sizeof(double));
    memcpy(qdd_out + row * m, a, m * sizeof(double));
    memcpy(lam_out + row * r, lam, r * sizeof(double));
    memcpy(phi_out + row * r, Phi, r * sizeof(double));
    double kinetic = 0.0;
    for (int i = 0; i < m; ++i)
        for (int j = 0; j < m; ++j) kinetic += v[i] * M[i * m + j] * v[j];
    energies[2 * row] = 0.5 * kinetic;
    energies[2 * row + 1] = potential;
    for (int k = 0; k < r; ++k) {
        double sum = s->terms[KRONLAG_DYNAMICS_PHI_T + k];
        for (int i = 0; i < m; ++i) sum += Phi_q[k * m + i] * v[i];
        velocity_out[row * r + k] = sum;
    }
}

/* Integrate from t0 (y0 = [q0, v0] consistent, a0 and lam0 from forward dynamics) to t1.
 * Outputs at the n_eval times t_eval (dense output: cubic Hermite in q and v, linear in a and lam)
 * or, with n_eval == 0, at every step (at most max_rows rows): t_out, y_out (rows x 2m), qdd_out,
 * lam_out, energies (rows x 2: kinetic, potential), phi_out, velocity_out; *n_out rows.
 * stats = [steps, rejected steps, Newton iterations, Jacobians]; singular passages in events
 * (monitor.c), *n_events of them (more than max_events are counted, not stored).
 * With handback != 0 the integration also ends, with KL3_HANDBACK, at the first step whose
 * singular ratio exceeds KRONLAG_LEAVE_RTOL (the switching method continues from there).
 * Returns 0, KL3_HANDBACK or a negative KL3_* flag; *t_end, y_end (2m): where it ended. */
int kronlag_index3(const double *p, int n_parameters, double t0, double t1, const double *y0, const double *a0,
                   const double *lam0, int n_eval, const double *t_eval, double rtol, double atol, double h0,
                   double max_step, long max_steps, int max_rows, int handback, double *t_out, double *y_out,
                   double *qdd_out, double *lam_out, double *energies, double *phi_out, double *velocity_out,
                   int *n_out, long *stats, double *events, int max_events, int *n_events, double *t_end,
                   double *y_end, void (*progress)(double))
{
    enum { m = KL3_M, r = KL3_R };
    double pext[n_parameters + m + r + 1];
    kl3_state s;
    memset(&s, 0, sizeof s);
    memcpy(pext, p, n_parameters * sizeof(double));
    s.p = p; s.pext = pext; s.n_parameters = n_parameters; s.rtol = rtol; s.atol = atol;
    double q[m], v[m], a[m], lam[r + 1], qn[m], vn[m], an[m], lamn[r + 1];
    memcpy(q, y0, m * sizeof(double));
    memcpy(v, y0 + m, m * sizeof(double));
    memcpy(a, a0, m * sizeof(double));
    memcpy(lam, lam0, r * sizeof(double));
    kronlag_dynamics(t0, q, v, p, s.terms);
    s.mass_scale = 0.0;
    for (int i = 0; i < m; ++i) s.mass_scale = fmax(s.mass_scale, s.terms[KRONLAG_DYNAMICS_M + i * m + i]);
    s.constraint_scale = 0.0;
    for (int k = 0; k < r; ++k) {
        double sum = 0.0;
        for (int i = 0; i < m; ++i) {
            double entry = s.terms[KRONLAG_DYNAMICS_PHI_Q + k * m + i];
            sum += entry * entry;
        }
        s.constraint_scale = fmax(s.constraint_scale, sum);
    }
    if (!(s.constraint_scale > 0.0)) s.constraint_scale = 1.0;
    kl_monitor monitor;
    kl_monitor_start(&monitor, t0, q, s.terms + KRONLAG_DYNAMICS_PHI_Q, events, max_events);
    int rows = 0, flag = 0, next = 0, retry = 0;
    long steps = 0, rejected = 0;
    double t = t0;
    if (n_eval == 0) {
        kl3_output(&s, rows++, 0, t0, q, v, a, t_out, y_out, qdd_out, lam_out, energies, phi_out, velocity_out);
    } else {
        for (; next < n_eval && t_eval[next] <= t0; ++next)
            kl3_output(&s, rows++, 0, t_eval[next], q, v, a, t_out, y_out, qdd_out, lam_out, energies, phi_out,
                       velocity_out);
    }
    if (!(s.mass_scale > 0.0)) { flag = KL3_START_FAILED; goto done; }
    double h_min = 16.0 * 2.220446049250313e-16 * fmax(fabs(t0), fabs(t1));
    /* not a tiny first step: the accelerations a = 4/h^2 (q - q0) - ... of an index-3 method carry
     * the rounding of q amplified by 4/h^2; the error test shortens a step that is too long */
    double h = h0 > 0.0 ? h0 : KL3_FIRST_STEP * (t1 - t0);
    if (max_step > 0.0) h = fmin(h, max_step);
    while (t < t1) {
        if (steps >= max_steps) { flag = KL3_TOO_MUCH_WORK; break; }
        int last = t + h >= t1 - h_min;
        if (last) h = t1 - t;
        double error = 0.0;
        int result = kl3_step(&s, t, h, q, v, a, lam, qn, vn, an, lamn, &error);
        if (result == 0 && !(error <= 1.0)) result = 1;  /* error test failed (NaN included) */
        if (result != 0) {
            ++rejected;
            if (++retry > KL3_MAX_RETRIES) { flag = result == 1 ? KL3_STEP_TOO_SMALL : result; break; }
            h *= result == 1 ? fmax(KL3_SHRINK, KL3_SAFETY * pow(fmax(error, 1e-300), -1.0 / 3.0)) : 0.25;
            if (h < h_min) { flag = result == 1 ? KL3_STEP_TOO_SMALL : result; break; }
            continue;
        }
        retry = 0;
        double t_new = last ? t1 : t + h;
        /* the terms of the step's last evaluation are those of (qn, vn) */
        double ratio = kl_monitor_observe(&monitor, t_new, qn, s.terms + KRONLAG_DYNAMICS_PHI_Q);
        if (n_eval == 0) {
            if (rows == max_rows) { flag = KL3_OUTPUTS_FULL; break; }
            kl3_output(&s, rows++, 1, t_new, qn, vn, an, t_out, y_out, qdd_out, lam_out, energies, phi_out,
                       velocity_out);
        } else {
            for (; next < n_eval && t_eval[next] <= t_new; ++next) {
                double theta = (t_eval[next] - t) / h, qi[m], vi[m], ai[m];
                double h00 = (1 + 2 * theta) * (1 - theta) * (1 - theta), h10 = theta * (1 - theta) * (1 - theta);
                double h01 = theta * theta * (3 - 2 * theta), h11 = theta * theta * (theta - 1);
                for (int i = 0; i < m; ++i) {
                    qi[i] = h00 * q[i] + h10 * h * v[i] + h01 * qn[i] + h11 * h * vn[i];
                    vi[i] = h00 * v[i] + h10 * h * a[i] + h01 * vn[i] + h11 * h * an[i];
                    ai[i] = (1 - theta) * a[i] + theta * an[i];
                }
                kl3_output(&s, rows++, 0, t_eval[next], qi, vi, ai, t_out, y_out, qdd_out, lam_out, energies,
                           phi_out, velocity_out);
            }
        }
        t = t_new;
        memcpy(q, qn, sizeof q); memcpy(v, vn, sizeof v); memcpy(a, an, sizeof a); memcpy(lam, lamn, sizeof lam);
        ++steps;
        if (progress) progress(t);
        if (handback && ratio > KRONLAG_LEAVE_RTOL && t < t1) { flag = KL3_HANDBACK; break; }
        h *= fmin(KL3_GROWTH, KL3_SAFETY * pow(fmax(error, 1e-300), -1.0 / 3.0));
        if (max_step > 0.0) h = fmin(h, max_step);
    }
done:
    *n_out = rows;
    *n_events = monitor.count;
    *t_end = t;
    memcpy(y_end, q, m * sizeof(double));
    memcpy(y_end + m, v, m * sizeof(double));
    stats[0] = steps; stats[1] = rejected; stats[2] = s.newton_iterations; stats[3] = s.jacobians;
    return flag;
}
