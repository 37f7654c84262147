/* kronlag compiled explicit integrator: DOP853 (Dormand & Prince; Hairer, Norsett & Wanner, Solving
 * ODEs I, Sec. II.10) on the Baumgarte index-1 ODE of cvode.c, the outputs projected onto the
 * constraints as there.
 *
 * Appended after cvode.c, whose right-hand side (kl_index1_rhs), start (kl_index1_start), watch
 * (kl_watch_step, kl_rank_rose), projection (kl_project) and outputs (kl_outputs_at, kl_outputs) it
 * shares, and after the coefficient tables KL8_* that kronlag.simulation.dop853.c_coefficients
 * prints from scipy's DOP853 (kronlag.simulation.solvers.compiled_dop853).
 *
 * The stepping is scipy's DOP853 (scipy/integrate/_ivp/rk.py) step for step, so that both take the
 * same steps up to rounding: 12 stages and the first-same-as-last 13th, the error estimate of
 * Hairer's code (the 5th- and 3rd-order estimators combined), step factors 0.9 err^(-1/8) within
 * [0.2, 10] (no growth right after a rejection), the first step of Hairer's Sec. II.4 (one extra
 * evaluation), the 7th-order dense output from three more stages, computed only for a step with
 * outputs inside.  An explicit method suits mechanisms, which are not stiff: on the four-bar (10 s,
 * rtol 1e-8) it takes 400 steps of 15 evaluations where CVODE's Adams, at the 1e4 times tighter
 * tolerances its larger global error needs (CompiledSolver.TOLERANCE_SCALE), takes 5900 of 1.3.
 *
 * Limits and exact stiction (o->gaps) are not watched here: such runs are refused in Python before
 * they reach this driver. */

#include <stdlib.h>

enum { KL8_STAGES = 12, KL8_FSAL = 12, KL8_EXTENDED = 16, KL8_POWER = 7 };
#define KL8_SAFETY 0.9
#define KL8_MIN_FACTOR 0.2
#define KL8_MAX_FACTOR 10.0
#define KL8_ERROR_EXPONENT (-1.0 / 8.0)

typedef struct {
    kl_data *data;
    double y_old[KL_N], y[KL_N], f[KL_N];  /* the last step ended at y with slope f, from y_old */
    double K[KL8_EXTENDED][KL_N];          /* its stages (K[0]: the slope at y_old; K[12]: f) */
    double F[KL8_POWER][KL_N];             /* its dense output, once asked (dense = 1) */
    double t_old, h;
    int dense;
    long nfev;
} kl8_state;

static int kl8_rhs(kl8_state *s, double t, const double *x, double *dx)
{
    ++s->nfev;
    return kl_index1_rhs(s->data, t, x, dx);
}

/* y_old + h sum_j a[j] K[j] over the first `stages` stages into `out` (scipy: dot(K[:s].T, a[:s]) * h). */
static void kl8_combine(const kl8_state *s, const double *a, int stages, double h, double *out)
{
    for (int i = 0; i < KL_N; ++i) {
        double sum = 0.0;
        for (int j = 0; j < stages; ++j) sum += s->K[j][i] * a[j];
        out[i] = s->y_old[i] + sum * h;
    }
}

/* RMS norm of x / scale (scipy's common.norm). */
static double kl8_norm(const double *x, const double *scale)
{
    double sum = 0.0;
    for (int i = 0; i < KL_N; ++i) sum += (x[i] / scale[i]) * (x[i] / scale[i]);
    return sqrt(sum / KL_N);
}

/* The first step from (t0, y0) with slope f0 towards t1 (scipy's select_initial_step, order 7 of the
 * error estimator); *h_abs set.  Returns 0 or -1 (the evaluation failed). */
static int kl8_first_step(kl8_state *s, double t0, double t1, double max_step, double rtol, double atol,
                          double *h_abs)
{
    double scale[KL_N], y1[KL_N], f1[KL_N], difference[KL_N];
    double interval = fabs(t1 - t0);
    for (int i = 0; i < KL_N; ++i) scale[i] = atol + fabs(s->y[i]) * rtol;
    double d0 = kl8_norm(s->y, scale), d1 = kl8_norm(s->f, scale);
    double h0 = d0 < 1e-5 || d1 < 1e-5 ? 1e-6 : 0.01 * d0 / d1;
    h0 = fmin(h0, interval);
    for (int i = 0; i < KL_N; ++i) y1[i] = s->y[i] + h0 * s->f[i];
    if (kl8_rhs(s, t0 + h0, y1, f1)) return -1;
    for (int i = 0; i < KL_N; ++i) difference[i] = f1[i] - s->f[i];
    double d2 = kl8_norm(difference, scale) / h0;
    double h1 = d1 <= 1e-15 && d2 <= 1e-15 ? fmax(1e-6, h0 * 1e-3) : pow(0.01 / fmax(d1, d2), 1.0 / 8.0);
    *h_abs = fmin(fmin(100 * h0, h1), fmin(interval, max_step));
    return 0;
}

/* One attempt from (t, s->y, s->f) over h: the stages into s->K, the new state into y_new (its slope
 * is K[12]); returns the error norm (NaN when the state is not finite), or -1.0 when an evaluation
 * failed. */
static double kl8_attempt(kl8_state *s, double t, double h, double rtol, double atol, double *y_new)
{
    double stage[KL_N];
    memcpy(s->y_old, s->y, sizeof s->y_old);
    memcpy(s->K[0], s->f, sizeof s->f);
    for (int k = 1; k < KL8_STAGES; ++k) {
        kl8_combine(s, KL8_A[k], k, h, stage);
        if (kl8_rhs(s, t + KL8_C[k] * h, stage, s->K[k])) return -1.0;
    }
    for (int i = 0; i < KL_N; ++i) {
        double sum = 0.0;
        for (int j = 0; j < KL8_STAGES; ++j) sum += s->K[j][i] * KL8_B[j];
        y_new[i] = s->y[i] + h * sum;
    }
    if (kl8_rhs(s, t + h, y_new, s->K[KL8_FSAL])) return -1.0;
    double error5 = 0.0, error3 = 0.0;
    for (int i = 0; i < KL_N; ++i) {
        double scale = atol + fmax(fabs(s->y[i]), fabs(y_new[i])) * rtol, e5 = 0.0, e3 = 0.0;
        for (int j = 0; j <= KL8_FSAL; ++j) { e5 += s->K[j][i] * KL8_E5[j]; e3 += s->K[j][i] * KL8_E3[j]; }
        error5 += (e5 / scale) * (e5 / scale);
        error3 += (e3 / scale) * (e3 / scale);
    }
    if (error5 == 0.0 && error3 == 0.0) return 0.0;
    return fabs(h) * error5 / sqrt((error5 + 0.01 * error3) * KL_N);
}

/* The dense output of the last step (three more stages), once. Returns 0 or -1. */
static int kl8_dense(kl8_state *s)
{
    if (s->dense) return 0;
    double h = s->h, stage[KL_N];
    for (int k = KL8_FSAL + 1; k < KL8_EXTENDED; ++k) {
        kl8_combine(s, KL8_A[k], k, h, stage);
        if (kl8_rhs(s, s->t_old + KL8_C[k] * h, stage, s->K[k])) return -1;
    }
    for (int i = 0; i < KL_N; ++i) {
        double delta = s->y[i] - s->y_old[i];
        s->F[0][i] = delta;
        s->F[1][i] = h * s->K[0][i] - delta;
        s->F[2][i] = 2 * delta - h * (s->f[i] + s->K[0][i]);
        for (int d = 0; d < KL8_POWER - 3; ++d) {
            double sum = 0.0;
            for (int k = 0; k < KL8_EXTENDED; ++k) sum += KL8_D[d][k] * s->K[k][i];
            s->F[3 + d][i] = h * sum;
        }
    }
    s->dense = 1;
    return 0;
}

/* The dense output at t inside the last step into out (scipy's Dop853DenseOutput). */
static void kl8_interpolate(const kl8_state *s, double t, double *out)
{
    double x = (t - s->t_old) / s->h;
    for (int i = 0; i < KL_N; ++i) {
        double y = 0.0;
        for (int power = 0; power < KL8_POWER; ++power) {
            y += s->F[KL8_POWER - 1 - power][i];
            y *= power % 2 == 0 ? x : 1 - x;
        }
        out[i] = y + s->y_old[i];
    }
}

/* Integrate o->y0 from o->t0 to o->t1 in at most o->max_steps accepted steps.  Outputs: the n_eval
 * times t_eval (dense output) or, with n_eval == 0, every step (at most max_rows rows), each projected
 * onto the constraints, with the derived quantities there (kl_outputs).  Singular passages go to
 * o->events (monitor.c).  Returns KRONLAG_RESULT_SUCCESS, KRONLAG_RESULT_APPROACH (o->t_end, o->y_end:
 * the projected state at the approach) or another KRONLAG_RESULT_* failure, with the outputs up to
 * the failure. */
int kronlag_dop853(kronlag_options *o)
{
    const double *p = kl_control_parameters(o), *t_eval = o->t_eval;
    double t0 = o->t0, t1 = o->t1, rtol = o->rtol, atol = o->atol, *y_out = o->y_out;
    double max_step = o->max_step > 0.0 ? o->max_step : INFINITY;
    int n_eval = o->n_eval, rows = 0, next = 0, flag = KRONLAG_RESULT_SUCCESS;
    double terms[KL_TERMS_ + 1], B[KL_K * KL_M + 1], c[KL_K + 1];
    kl_data data;
    kl_monitor monitor;
    kl_progress progress = {kl_clock()};
    kl_index1_start(o, p, &data, &monitor, terms, B, c);
    kl8_state *s = calloc(1, sizeof *s);  /* 26 rows of 2 m: on the heap, not a thread's stack */
    double t = t0, t_sample = kl_control_next_sample(o), h_abs = 0.0;
    long steps = 0;
    memcpy(o->y_end, o->y0, KL_N * sizeof(double));
    if (!s) { flag = KRONLAG_RESULT_SOLVER_FAILED; goto done; }
    s->data = &data;
    memcpy(s->y, o->y0, sizeof s->y);
    rows = kl_outputs_first(o, s->y, &next);
    if (t0 < t1) {  /* the slope at the start and the first step (given, or Hairer's estimate) */
        if (kl8_rhs(s, t0, s->y, s->f)) flag = KRONLAG_RESULT_SINGULAR;
        else if (o->h0 > 0.0) h_abs = o->h0;
        else if (kl8_first_step(s, t0, fmin(t1, t_sample), max_step, rtol, atol, &h_abs)) flag = KRONLAG_RESULT_SINGULAR;
    }
    while (!flag && t < t1) {
        if (steps >= o->max_steps) { flag = KRONLAG_RESULT_MAX_STEPS; break; }
        double t_stop = fmin(t1, t_sample), watched = kl_monitor_max_step(&monitor);  /* 0: no limit */
        double limit = watched > 0.0 ? fmin(max_step, watched) : max_step;
        double min_step = 10 * fabs(nextafter(t, INFINITY) - t), y_new[KL_N], h = 0.0, t_new = t;
        if (h_abs > limit) h_abs = limit;
        else if (h_abs < min_step) h_abs = min_step;
        int accepted = 0, rejected = 0;
        while (!accepted) {
            if (h_abs < min_step) { flag = KRONLAG_RESULT_STEP_TOO_SMALL; break; }
            t_new = t + h_abs;
            if (t_new > t_stop) t_new = t_stop;
            h = t_new - t;
            h_abs = fabs(h);
            double error = kl8_attempt(s, t, h, rtol, atol, y_new);
            if (error < 0.0) { flag = KRONLAG_RESULT_SINGULAR; break; }  /* an evaluation failed */
            if (error < 1.0) {
                double factor = error == 0.0 ? KL8_MAX_FACTOR
                                             : fmin(KL8_MAX_FACTOR, KL8_SAFETY * pow(error, KL8_ERROR_EXPONENT));
                if (rejected) factor = fmin(1.0, factor);
                h_abs *= factor;
                accepted = 1;
            } else {  /* NaN too: fmax(0.2, NaN) = 0.2 */
                h_abs *= fmax(KL8_MIN_FACTOR, KL8_SAFETY * pow(error, KL8_ERROR_EXPONENT));
                rejected = 1;
            }
        }
        if (!accepted) break;
        ++steps;
        s->t_old = t;
        s->h = h;
        s->dense = 0;
        t = t_new;
        memcpy(s->y, y_new, sizeof s->y);
        memcpy(s->f, s->K[KL8_FSAL], sizeof s->f);
        double *x = s->y;
        int at_x = n_eval == 0 && KL_K > 0;
        double ratio = kl_watch_step(&monitor, t, x, p, terms, B, c, at_x);
        /* outputs before t (dense output); at a sample instant the controller is called and the slope
         * evaluated again; then the output at t itself, with the parameters that hold from t on */
        for (; n_eval > 0 && next < n_eval && t_eval[next] < t; ++next, ++rows) {
            if (kl8_dense(s)) { flag = KRONLAG_RESULT_SINGULAR; break; }
            o->t_out[rows] = t_eval[next];
            kl8_interpolate(s, t_eval[next], y_out + rows * KL_N);
            kl_control_record(o, rows);
            if (kl_project(t_eval[next], y_out + rows * KL_N, &data)) { flag = KRONLAG_RESULT_PROJECTION_FAILED; break; }
        }
        if (flag) break;
        if (t >= t_sample && t < t1) {
            if ((flag = kl_control_call(o, t, x, x + KL_M))) break;
            t_sample = kl_control_next_sample(o);
            if (kl8_rhs(s, t, x, s->f)) { flag = KRONLAG_RESULT_SINGULAR; break; }
        }
        if (n_eval == 0 && rows == o->max_rows) { flag = KRONLAG_RESULT_OUTPUTS_FULL; break; }
        if ((flag = kl_outputs_at(o, &data, t, x, &rows, &next, terms, B, c, at_x))) break;
        int stop = kl_progress_report(o, &progress, t);
        if (stop) { flag = stop; break; }
        if (ratio < KRONLAG_APPROACH_RTOL || kl_rank_rose(t, x, &data)) { flag = KRONLAG_RESULT_APPROACH; break; }
    }
    memcpy(o->y_end, s->y, KL_N * sizeof(double));
    if (flag == KRONLAG_RESULT_APPROACH && kl_project(t, o->y_end, &data)) flag = KRONLAG_RESULT_PROJECTION_FAILED;
    if (data.stopped) {
        flag = data.stopped;
    } else if (data.singular) {
        flag = KRONLAG_RESULT_SINGULAR;
        t = data.t_singular;
        memcpy(o->y_end, data.y_singular, KL_N * sizeof(double));
    }
done:
    kl_outputs(o, 0, rows, data.turned);
    o->n_out = rows;
    o->n_events = monitor.count;
    o->t_end = t;
    o->steps = steps;
    o->nfev = s ? s->nfev : 0;
    o->njev = 0;
    free(s);
    return flag;
}
