/* kronlag compiled integrator: SUNDIALS CVODE (Adams-Moulton) on the Baumgarte index-1 ODE,
 * with the outputs projected onto the constraint manifold.
 *
 * Appended to the C source of a kronlag NumericModel (NumericModel.c_source) with its
 * "potential_energy" and "Phi_q" kernels and monitor.c (kronlag.simulation.CompiledSolver); reads
 * KRONLAG_M, KRONLAG_R, KRONLAG_S, the block offsets KRONLAG_DYNAMICS_* and the policy macros
 * of tolerances.py, and calls kronlag_forward_dynamics and kronlag_dynamics.
 *
 * State y = [q, qd] (2 m).  Right-hand side y' = [qd, qdd] with
 *   [[M, Phi_q^T, A^T], [Phi_q, 0, 0], [A, 0, 0]] [qdd; lam; mu]
 *     = [h; gamma - 2 alpha Phi_q qd - beta^2 Phi; gamma_nh - alpha (A qd + b)].
 * Projection (of every output; the integrator's own state is left alone, Baumgarte keeps its
 * drift small), least-norm corrections over the independent rows (min_norm_correction):
 *   q  <- q - Phi_q^+ Phi(q)                           (Gauss-Newton, until |Phi| <= atol / 100
 *                                                       or the steps reach rounding level)
 *   qd <- qd - B^+ (B qd + c),  B = [Phi_q; A], c = [0; b].
 * Singular configurations (monitor.c): the steps are limited so that the approach to one is seen;
 * there the integration stops with KL_APPROACH (an index-1 formulation cannot tell the branches
 * apart), and the switching method continues with ALI3-P.
 *
 * Adams-Moulton (orders 1-12, Newton iteration with a dense difference-quotient Jacobian) rather
 * than BDF: mechanisms are not stiff, and on the four-bar Adams needed fewer steps and gave ten
 * times smaller errors than BDF, with or without CVODE's BDF-only projection (CVodeSetProjFn).
 *
 * The scikit-sundae wheel ships the SUNDIALS 7 shared libraries but not their
 * headers, so the few declarations needed are written out below (SUNDIALS 7.x,
 * sunrealtype = double, sunindextype = int, no MPI: SUNComm = int); the symbols resolve at load
 * time against those libraries, which kronlag.simulation loads first with global visibility. */

typedef double sunrealtype;
typedef int sunindextype;
typedef int SUNComm;
typedef struct _generic_N_Vector *N_Vector;
typedef struct _generic_SUNMatrix *SUNMatrix;
typedef struct _generic_SUNLinearSolver *SUNLinearSolver;
typedef struct SUNContext_ *SUNContext;
typedef int (*CVRhsFn)(sunrealtype t, N_Vector y, N_Vector ydot, void *user_data);

extern int SUNDIALSGetVersionNumber(int *major, int *minor, int *patch, char *label, int len);
extern int SUNContext_Create(SUNComm comm, SUNContext *ctx);
extern int SUNContext_Free(SUNContext *ctx);
extern int SUNContext_ClearErrHandlers(SUNContext ctx);
extern N_Vector N_VNew_Serial(sunindextype length, SUNContext ctx);
extern sunrealtype *N_VGetArrayPointer(N_Vector v);
extern void N_VDestroy(N_Vector v);
extern SUNMatrix SUNDenseMatrix(sunindextype rows, sunindextype cols, SUNContext ctx);
extern void SUNMatDestroy(SUNMatrix A);
extern SUNLinearSolver SUNLinSol_Dense(N_Vector y, SUNMatrix A, SUNContext ctx);
extern int SUNLinSolFree(SUNLinearSolver S);
extern void *CVodeCreate(int lmm, SUNContext ctx);
extern int CVodeInit(void *mem, CVRhsFn f, sunrealtype t0, N_Vector y0);
extern int CVodeSStolerances(void *mem, sunrealtype rtol, sunrealtype atol);
extern int CVodeSetUserData(void *mem, void *data);
extern int CVodeSetMaxNumSteps(void *mem, long mxsteps);
extern int CVodeSetMaxStep(void *mem, sunrealtype hmax);
extern int CVodeSetStopTime(void *mem, sunrealtype tstop);
extern int CVodeSetMaxHnilWarns(void *mem, int mxhnil);
extern int CVodeSetLinearSolver(void *mem, SUNLinearSolver LS, SUNMatrix A);
extern int CVode(void *mem, sunrealtype tout, N_Vector yout, sunrealtype *tret, int itask);
extern int CVodeGetDky(void *mem, sunrealtype t, int k, N_Vector dky);
extern int CVodeGetNumSteps(void *mem, long *n);
extern int CVodeGetNumRhsEvals(void *mem, long *n);
extern int CVodeGetNumLinRhsEvals(void *mem, long *n);
extern int CVodeGetNumJacEvals(void *mem, long *n);
extern char *CVodeGetReturnFlagName(long flag);
extern void CVodeFree(void **mem);

enum { KL_M = KRONLAG_M, KL_R = KRONLAG_R, KL_S = KRONLAG_S, KL_N = 2 * KRONLAG_M,
       KL_K = KRONLAG_R + KRONLAG_S, KL_TERMS_ = KRONLAG_DYNAMICS_SIZE };
enum { CV_ADAMS = 1, CV_ONE_STEP = 2 };
enum { KL_PHI = KRONLAG_DYNAMICS_PHI, KL_PHI_Q = KRONLAG_DYNAMICS_PHI_Q, KL_PHI_T = KRONLAG_DYNAMICS_PHI_T,
       KL_A = KRONLAG_DYNAMICS_A, KL_B = KRONLAG_DYNAMICS_B };
#define KL_MAX_PROJECTION_ITERATIONS 8
#define KL_STALL 1e-15  /* Gauss-Newton steps below KL_STALL (1 + |q|) end the iteration */
#define KL_SETUP_FAILED (-1000)
#define KL_VERSION_MISMATCH (-1001)
#define KL_PROJECTION_FAILED (-1002)
#define KL_TOO_MUCH_WORK (-1)  /* CV_TOO_MUCH_WORK */
#define KL_APPROACH 2          /* stopped at the approach to a singular configuration */
#define KL_SINGULAR (-1003)
#define KL_OUTPUTS_FULL (-1004) /* every step is an output and there is no room for more */    /* the accelerations are not determined (M singular on the constraints' null space) */

typedef struct {
    const double *p;
    double alpha, beta, tol;
    int singular;                      /* the right-hand side met a singular configuration ... */
    double t_singular, y_singular[KL_N];  /* ... there */
} kl_data;

static int kl_rhs(sunrealtype t, N_Vector y, N_Vector ydot, void *user_data)
{
    kl_data *data = user_data;
    const double *x = N_VGetArrayPointer(y);
    double *dx = N_VGetArrayPointer(ydot);
    double lam[KL_R + 1], mu[KL_S + 1];
    memcpy(dx, x + KL_M, KL_M * sizeof(double));
    if (!kronlag_forward_dynamics(t, x, x + KL_M, data->p, data->alpha, data->beta, dx + KL_M, lam, mu)) return 0;
    /* A singular configuration is unrecoverable: remember where, for the message. */
    data->singular = 1;
    data->t_singular = t;
    memcpy(data->y_singular, x, sizeof data->y_singular);
    return -1;
}

/* The constraint rows B = [Phi_q; A] (k x m) and offsets c = [Phi_t; b] at (t, q): B qd + c = 0. */
static void kl_constraints(double t, const double *q, const double *p, double *terms, double *B, double *c)
{
    double zero[KL_M];
    memset(zero, 0, sizeof zero);
    kronlag_dynamics(t, q, zero, p, terms);
    memcpy(B, terms + KL_PHI_Q, KL_R * KL_M * sizeof(double));
    memcpy(B + KL_R * KL_M, terms + KL_A, KL_S * KL_M * sizeof(double));
    for (int i = 0; i < KL_R; ++i) c[i] = terms[KL_PHI_T + i];
    for (int i = 0; i < KL_S; ++i) c[KL_R + i] = terms[KL_B + i];
}

/* Project x = [q, qd] in place.  Returns 0, or 1 if the projection failed. */
static int kl_project(double t, double *x, const kl_data *data)
{
    double terms[KL_TERMS_ + 1], B[KL_K * KL_M + 1], c[KL_K + 1], residual[KL_K + 1];
    double *q = x, *qd = x + KL_M;
    if (KL_R > 0) {
        int converged = 0, stalled = 0;
        for (int iteration = 0; iteration < KL_MAX_PROJECTION_ITERATIONS; ++iteration) {
            kl_constraints(t, q, data->p, terms, B, c);
            double largest = 0.0;
            for (int i = 0; i < KL_R; ++i) largest = fmax(largest, fabs(terms[KL_PHI + i]));
            if (largest <= data->tol || stalled) { converged = 1; break; }
            double before[KL_M];
            memcpy(before, q, sizeof before);
            if (min_norm_correction(B, KL_R, KL_M, terms + KL_PHI, q) == 0) return 1;
            stalled = 1;  /* a step at rounding level: Phi is as small as it gets */
            for (int i = 0; i < KL_M; ++i)
                if (fabs(q[i] - before[i]) > KL_STALL * (1.0 + fabs(q[i]))) stalled = 0;
        }
        if (!converged) return 1;
    }
    if (KL_K > 0) {
        if (KL_R == 0) kl_constraints(t, q, data->p, terms, B, c);  /* else still current from the loop */
        for (int i = 0; i < KL_K; ++i) {
            double sum = c[i];
            for (int j = 0; j < KL_M; ++j) sum += B[i * KL_M + j] * qd[j];
            residual[i] = sum;
        }
        if (min_norm_correction(B, KL_K, KL_M, residual, qd) == 0) return 1;
    }
    return 0;
}

/* Name of a return value of kronlag_cvode. */
const char *kronlag_cvode_flag_name(int flag)
{
    if (flag == KL_SETUP_FAILED) return "setting up CVODE failed";
    if (flag == KL_VERSION_MISMATCH) return "the SUNDIALS library is not version 7";
    if (flag == KL_PROJECTION_FAILED) return "the projection onto the constraints failed";
    if (flag == KL_APPROACH) return "approach to a singular configuration";
    if (flag == KL_OUTPUTS_FULL) return "more steps than output rows: pass t_eval to choose the outputs";
    if (flag == KL_SINGULAR) return "singular configuration: M is not positive definite on the null space of "
                                    "[Phi_q; A], the accelerations are not determined (e.g. Euler angles at gimbal lock)";
    return CVodeGetReturnFlagName(flag);
}

/* Integrate from (t0, y0) to t1 in at most max_steps steps.  Outputs: the n_eval times t_eval
 * (interpolated by CVODE) or, with n_eval == 0, every step (at most max_rows rows), each projected
 * onto the constraints: t_out, y_out (rows x 2m), *n_out rows written; stats = [steps,
 * right-hand sides, Jacobians, output projections].  progress (may be NULL) is called with the time
 * after every step.  Singular passages go to events (monitor.c, *n_events).  Returns 0, KL_APPROACH
 * (*t_end, y_end: the projected state at the approach), or a negative CVODE flag
 * (kronlag_cvode_flag_name) with the outputs up to the failure. */
int kronlag_cvode(const double *p, double t0, double t1, const double *y0, int n_eval, const double *t_eval,
                  double rtol, double atol, double alpha, double beta, double max_step, long max_steps, int max_rows,
                  double *t_out, double *y_out, int *n_out, long *stats, double *events, int max_events,
                  int *n_events, double *t_end, double *y_end, void (*progress)(double))
{
    int major = 0, minor = 0, patch = 0;
    char label[64];
    SUNDIALSGetVersionNumber(&major, &minor, &patch, label, sizeof label);
    if (major != 7) return KL_VERSION_MISMATCH;
    kl_data data = {p, alpha, beta, atol / 100.0, 0, 0.0, {0.0}};
    SUNContext ctx = NULL;
    N_Vector y = NULL, dense = NULL;
    SUNMatrix J = NULL;
    SUNLinearSolver LS = NULL;
    void *mem = NULL;
    int flag = KL_SETUP_FAILED, rows = 0, next = 0;
    long projections = 0;
    double t = t0, terms[KL_TERMS_ + 1], B[KL_K * KL_M + 1], c[KL_K + 1];
    kl_monitor monitor;
    kl_constraints(t0, y0, p, terms, B, c);
    kl_monitor_start(&monitor, t0, y0, terms + KL_PHI_Q, events, max_events);
    memcpy(y_end, y0, KL_N * sizeof(double));
    if (SUNContext_Create(0, &ctx) || SUNContext_ClearErrHandlers(ctx)) goto done;
    if (!(y = N_VNew_Serial(KL_N, ctx)) || !(dense = N_VNew_Serial(KL_N, ctx)) || !(J = SUNDenseMatrix(KL_N, KL_N, ctx))
        || !(LS = SUNLinSol_Dense(y, J, ctx)) || !(mem = CVodeCreate(CV_ADAMS, ctx))) goto done;
    double *x = N_VGetArrayPointer(y), *xi = N_VGetArrayPointer(dense);
    memcpy(x, y0, KL_N * sizeof(double));
    if (CVodeInit(mem, kl_rhs, t0, y) || CVodeSStolerances(mem, rtol, atol) || CVodeSetUserData(mem, &data)
        || CVodeSetLinearSolver(mem, LS, J)
        || CVodeSetMaxNumSteps(mem, max_steps) || CVodeSetStopTime(mem, t1) || CVodeSetMaxHnilWarns(mem, -1))
        goto done;
    flag = 0;
    if (n_eval == 0) {
        t_out[0] = t0;
        memcpy(y_out, x, KL_N * sizeof(double));
        rows = 1;
    } else {
        for (; next < n_eval && t_eval[next] <= t0; ++next, ++rows) {
            t_out[rows] = t_eval[next];
            memcpy(y_out + rows * KL_N, x, KL_N * sizeof(double));
        }
    }
    for (long steps = 0; t < t1; ++steps) {
        if (steps >= max_steps) { flag = KL_TOO_MUCH_WORK; break; }
        double limit = kl_monitor_max_step(&monitor);
        if (max_step > 0.0) limit = limit > 0.0 ? fmin(limit, max_step) : max_step;
        CVodeSetMaxStep(mem, limit);
        flag = CVode(mem, t1, y, &t, CV_ONE_STEP);
        if (flag < 0) break;
        flag = 0;
        double ratio = 1.0;
        if (KL_R > 0) {  /* the watch needs only Phi_q: its own kernel, far smaller than the dynamics */
            double zero[KL_M + 1] = {0.0}, Phi_q[KL_R * KL_M + 1];
            kronlag_Phi_q(t, x, zero, p, Phi_q);
            ratio = kl_monitor_observe(&monitor, t, x, Phi_q);
        }
        if (n_eval == 0) {
            if (rows == max_rows) { flag = KL_OUTPUTS_FULL; break; }
            ++projections;
            t_out[rows] = t;
            memcpy(y_out + rows * KL_N, x, KL_N * sizeof(double));
            if (kl_project(t, y_out + rows * KL_N, &data)) { flag = KL_PROJECTION_FAILED; break; }
            ++rows;
        } else {
            for (; next < n_eval && t_eval[next] <= t; ++next, ++rows) {
                ++projections;
                CVodeGetDky(mem, t_eval[next], 0, dense);
                t_out[rows] = t_eval[next];
                memcpy(y_out + rows * KL_N, xi, KL_N * sizeof(double));
                if (kl_project(t_eval[next], y_out + rows * KL_N, &data)) { flag = KL_PROJECTION_FAILED; break; }
            }
            if (flag) break;
        }
        if (progress) progress(t);
        if (ratio < KRONLAG_APPROACH_RTOL) { flag = KL_APPROACH; break; }
    }
    memcpy(y_end, x, KL_N * sizeof(double));
    if (flag == KL_APPROACH && kl_project(t, y_end, &data)) flag = KL_PROJECTION_FAILED;
    if (flag < 0 && data.singular) {
        flag = KL_SINGULAR;
        t = data.t_singular;
        memcpy(y_end, data.y_singular, KL_N * sizeof(double));
    }
done:
    *n_out = rows;
    *n_events = monitor.count;
    *t_end = t;
    stats[0] = stats[1] = stats[2] = 0;
    stats[3] = projections;
    if (mem) {
        long lin_rhs = 0;
        CVodeGetNumSteps(mem, &stats[0]);
        CVodeGetNumRhsEvals(mem, &stats[1]);
        CVodeGetNumLinRhsEvals(mem, &lin_rhs);
        stats[1] += lin_rhs;
        CVodeGetNumJacEvals(mem, &stats[2]);
        CVodeFree(&mem);
    }
    if (LS) SUNLinSolFree(LS);
    if (J) SUNMatDestroy(J);
    if (dense) N_VDestroy(dense);
    if (y) N_VDestroy(y);
    if (ctx) SUNContext_Free(&ctx);
    return flag;
}

/* Derived outputs at the n states y (n x 2m) at times t: qdd (n x m), lam (n x r), mu (n x s) from
 * forward dynamics without Baumgarte terms (NaN where the configuration is singular), the kinetic
 * energy T = 1/2 qd^T M qd (n), the potential energy (n), Phi (n x r) and [Phi_q qd; A qd + b]
 * (n x (r + s)). */
void kronlag_outputs(const double *p, int n, const double *t, const double *y, double *qdd, double *lam,
                     double *mu, double *kinetic, double *potential, double *phi, double *velocity)
{
    double terms[KL_TERMS_ + 1], B[KL_K * KL_M + 1], c[KL_K + 1];
    for (int k = 0; k < n; ++k) {
        const double *q = y + k * KL_N, *qd = q + KL_M;
        double *a = qdd + k * KL_M, *l = lam + k * KL_R, *u = mu + k * KL_S;
        if (kronlag_forward_dynamics(t[k], q, qd, p, 0.0, 0.0, a, l, u)) {
            for (int i = 0; i < KL_M; ++i) a[i] = NAN;
            for (int i = 0; i < KL_R; ++i) l[i] = NAN;
            for (int i = 0; i < KL_S; ++i) u[i] = NAN;
        }
        kl_constraints(t[k], q, p, terms, B, c);
        double energy = 0.0;
        for (int i = 0; i < KL_M; ++i)
            for (int j = 0; j < KL_M; ++j) energy += qd[i] * terms[i * KL_M + j] * qd[j];
        kinetic[k] = 0.5 * energy;
        kronlag_potential_energy(t[k], q, qd, p, potential + k);
        memcpy(phi + k * KL_R, terms + KL_PHI, KL_R * sizeof(double));
        for (int i = 0; i < KL_K; ++i) {
            double sum = c[i];
            for (int j = 0; j < KL_M; ++j) sum += B[i * KL_M + j] * qd[j];
            velocity[k * KL_K + i] = sum;
        }
    }
}
