/* kronlag FMU: the model instance behind the FMI functions of fmu2.c (FMI 2.0) and fmu3.c (FMI 3.0).
 *
 * Appended (by kronlag.views.fmu) to the C source of a kronlag NumericModel (NumericModel.c_source)
 * with its "potential_energy" and "Phi_q" kernels, the declarations of kronlag.simulation.interface,
 * monitor.c, progress.c and cvode.c of kronlag.simulation (whose right-hand side kl_rhs, projection
 * kl_project and constraint rows kl_constraints this file uses: one integrator, one projection),
 * then the generated FMU header (value references KL_VR_*, start values, the parameter definitions
 * kl_fmu_definitions, the joint reactions kl_fmu_reactions; kronlag/views/fmu/build.py).
 *
 * States x = [q, qd] (2 m).  Model Exchange: the derivatives are the Baumgarte index-1 form
 * [qd, qdd(alpha, beta)] (kl_rhs); after a completed integrator step, a step event is asked for
 * when the drift, max |Phi| or max |Phi_q qd + Phi_t; A qd + b|, exceeds the parameter
 * kronlag.drift_tolerance, and the event update then projects the states onto the constraints.
 * Co-Simulation: CVODE (Adams, as kronlag.simulate's compiled method, at its tolerances) from
 * communication point to communication point, the state handed out projected onto the constraints
 * (the integrator's own state left alone, as kronlag.simulate does); a change of an input or a
 * parameter restarts CVODE from the projected state.  Both: the start values are projected onto
 * the constraints when initialization ends.  Outputs: multipliers, joint reactions and energies
 * from forward dynamics without Baumgarte terms (as kronlag's Trajectory).
 *
 * The functions return 0, or 1 after logging the error through the instance's log function. */

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

enum { KL_MODE_INSTANTIATED, KL_MODE_INITIALIZATION, KL_MODE_RUNNING, KL_MODE_TERMINATED, KL_MODE_ERROR };
enum { KL_NP = KL_FMU_PARAMETERS };

typedef struct kl_fmu kl_fmu;
/* Passes an error message to the importer (the FMI version's logger). */
typedef void (*kl_log_function)(const kl_fmu *fmu, const char *message);

struct kl_fmu {
    kl_log_function log;
    const void *logger;        /* the importer's callback(s), for log */
    void *environment;         /* the importer's environment pointer, for log */
    char name[256];
    int cosimulation, mode;
    double t, start_time, rtol;
    double x[KL_N];            /* [q, qd]: the states (Model Exchange), the projected state (Co-Simulation) */
    double p[KL_NP + 1];       /* the model's parameter vector (inputs included) */
    double alpha, beta, drift_tolerance;
    int generic_rank;
    /* derived quantities at (t, x, p), computed on demand */
    int have_derivatives, have_outputs;
    double dx[KL_N];
    double outputs[KL_VR_OUTPUTS_COUNT + 1];  /* lambda, reactions, energies */
    /* Co-Simulation: CVODE, restarted from x when restart is set */
    SUNContext ctx;
    N_Vector y;
    SUNMatrix J;
    SUNLinearSolver LS;
    void *cvode;
    int restart;
    kl_data data;
};

static int kl_error(const kl_fmu *fmu, const char *format, ...)
{
    char message[1024];
    va_list arguments;
    va_start(arguments, format);
    vsnprintf(message, sizeof message, format, arguments);
    va_end(arguments);
    if (fmu->log) fmu->log(fmu, message);
    return 1;
}

/* The start values: the model's parameter values, the start state, the settings. */
static void kl_defaults(kl_fmu *fmu)
{
    static const double p0[KL_NP + 1] = KL_FMU_START_PARAMETERS;
    static const double x0[KL_N] = KL_FMU_START_STATE;
    memcpy(fmu->p, p0, sizeof fmu->p);
    memcpy(fmu->x, x0, sizeof fmu->x);
    fmu->alpha = KL_FMU_ALPHA;
    fmu->beta = KL_FMU_BETA;
    fmu->drift_tolerance = KL_FMU_DRIFT_TOLERANCE;
    fmu->t = fmu->start_time = 0.0;
    fmu->rtol = KL_FMU_RTOL;
    fmu->have_derivatives = fmu->have_outputs = 0;
    fmu->restart = 1;
    fmu->mode = KL_MODE_INSTANTIATED;
}

static void kl_free_cvode(kl_fmu *fmu)
{
    if (fmu->cvode) CVodeFree(&fmu->cvode);
    if (fmu->LS) SUNLinSolFree(fmu->LS);
    if (fmu->J) SUNMatDestroy(fmu->J);
    if (fmu->y) N_VDestroy(fmu->y);
    if (fmu->ctx) SUNContext_Free(&fmu->ctx);
    fmu->cvode = NULL, fmu->LS = NULL, fmu->J = NULL, fmu->y = NULL, fmu->ctx = NULL;
}

/* A new instance (NULL when out of memory or the SUNDIALS loaded is not version 7: logged). */
static kl_fmu *kl_new(const char *name, int cosimulation, kl_log_function log, const void *logger,
                      void *environment)
{
    kl_fmu probe;
    memset(&probe, 0, sizeof probe);
    probe.log = log, probe.logger = logger, probe.environment = environment;
    snprintf(probe.name, sizeof probe.name, "%s", name ? name : "");
    int major = 0, minor = 0, patch = 0;
    char label[64];
    SUNDIALSGetVersionNumber(&major, &minor, &patch, label, sizeof label);
    if (major != 7) {
        kl_error(&probe, "the SUNDIALS library loaded is version %d, not 7", major);
        return NULL;
    }
    kl_fmu *fmu = calloc(1, sizeof(kl_fmu));
    if (!fmu) {
        kl_error(&probe, "out of memory");
        return NULL;
    }
    *fmu = probe;
    fmu->cosimulation = cosimulation;
    kl_defaults(fmu);
    return fmu;
}

static void kl_delete(kl_fmu *fmu)
{
    if (!fmu) return;
    kl_free_cvode(fmu);
    free(fmu);
}

static void kl_reset(kl_fmu *fmu)
{
    kl_free_cvode(fmu);
    kl_defaults(fmu);
}

static void kl_changed(kl_fmu *fmu)
{
    fmu->have_derivatives = fmu->have_outputs = 0;
    fmu->restart = 1;
}

static void kl_setup(kl_fmu *fmu, int tolerance_defined, double tolerance, double start_time)
{
    if (tolerance_defined && tolerance > 0.0) fmu->rtol = tolerance;
    fmu->t = fmu->start_time = start_time;
    kl_changed(fmu);
}

/* The driver's options seen by its right-hand side: none set (no controller, no limits). */
static const kronlag_options kl_fmu_no_options;

static kl_data kl_fmu_data(const kl_fmu *fmu, double tol)
{
    kl_data data;
    memset(&data, 0, sizeof data);
    data.o = &kl_fmu_no_options;
    data.p = fmu->p;
    data.alpha = fmu->alpha;
    data.beta = fmu->beta;
    data.tol = tol;
    data.generic_rank = fmu->generic_rank;
    return data;
}

/* max(max |Phi|, max |[Phi_q qd + Phi_t; A qd + b]|) at the current state. */
static double kl_drift(const kl_fmu *fmu)
{
    double terms[KL_TERMS_ + 1], B[KL_K * KL_M + 1], c[KL_K + 1], drift = 0.0;
    kl_constraints(fmu->t, fmu->x, fmu->p, terms, B, c);
    for (int i = 0; i < KL_R; ++i) drift = fmax(drift, fabs(terms[KL_PHI + i]));
    for (int i = 0; i < KL_K; ++i) {
        double sum = c[i];
        for (int j = 0; j < KL_M; ++j) sum += B[i * KL_M + j] * fmu->x[KL_M + j];
        drift = fmax(drift, fabs(sum));
    }
    return drift;
}

/* Project the state onto the constraints (residual drift_tolerance / 100, as kronlag projects
 * to atol / 100). */
static int kl_fmu_project(kl_fmu *fmu)
{
    kl_data data = kl_fmu_data(fmu, fmu->drift_tolerance / 100.0);
    kl_changed(fmu);
    if (kl_project(fmu->t, fmu->x, &data)) return kl_error(fmu, "the projection onto the constraints failed at "
                                                          "t = %.9g", fmu->t);
    return 0;
}

static int kl_derivatives(kl_fmu *fmu)
{
    if (fmu->have_derivatives) return 0;
    double lam[KL_R + 1], mu[KL_S + 1];
    memcpy(fmu->dx, fmu->x + KL_M, KL_M * sizeof(double));
    if (kronlag_forward_dynamics_ranked(fmu->t, fmu->x, fmu->x + KL_M, fmu->p, fmu->alpha, fmu->beta,
                                        fmu->generic_rank, fmu->dx + KL_M, lam, mu))
        return kl_error(fmu, "singular configuration at t = %.9g: the mass matrix is singular on the constraints' "
                        "null space, or [Phi_q; A] lost rank (the FMU cannot pass singular configurations)", fmu->t);
    fmu->have_derivatives = 1;
    return 0;
}

static void kl_outputs_now(kl_fmu *fmu)
{
    if (fmu->have_outputs) return;
    const double *q = fmu->x, *qd = fmu->x + KL_M;
    double qdd[KL_M + 1], mu[KL_S + 1], *lam = fmu->outputs + KL_OUT_LAMBDA;
    if (kronlag_forward_dynamics(fmu->t, q, qd, fmu->p, 0.0, 0.0, qdd, lam, mu))
        for (int i = 0; i < KL_R; ++i) lam[i] = NAN;
    kl_fmu_reactions(fmu->t, q, qd, fmu->p, lam, fmu->outputs + KL_OUT_REACTIONS);
    double terms[KL_TERMS_ + 1], kinetic = 0.0, potential = 0.0;
    kronlag_dynamics(fmu->t, q, qd, fmu->p, terms);
    for (int i = 0; i < KL_M; ++i)
        for (int j = 0; j < KL_M; ++j) kinetic += qd[i] * terms[i * KL_M + j] * qd[j];
    kinetic *= 0.5;
    kronlag_potential_energy(fmu->t, q, qd, fmu->p, &potential);
    fmu->outputs[KL_OUT_ENERGY] = kinetic;
    fmu->outputs[KL_OUT_ENERGY + 1] = potential;
    fmu->outputs[KL_OUT_ENERGY + 2] = kinetic + potential;
    fmu->have_outputs = 1;
}

/* CVODE started at (t, x).  kronlag's tolerances (tolerance = the accuracy asked for): CVODE's
 * local ones are divided by KL_FMU_TOLERANCE_SCALE, no tighter than KL_FMU_TIGHTEST_*, the outputs
 * projected to atol / 100, as in kronlag.simulate's compiled method. */
static int kl_cvode_start(kl_fmu *fmu)
{
    double rtol = fmax(fmu->rtol / KL_FMU_TOLERANCE_SCALE, KL_FMU_TIGHTEST_RTOL);
    double atol = fmax(fmu->rtol * KL_FMU_ATOL_RATIO / KL_FMU_TOLERANCE_SCALE, KL_FMU_TIGHTEST_ATOL);
    kl_free_cvode(fmu);
    fmu->data = kl_fmu_data(fmu, fmax(atol / 100.0, KL_FMU_TIGHTEST_ATOL));
    if (SUNContext_Create(0, &fmu->ctx) || SUNContext_ClearErrHandlers(fmu->ctx)
        || !(fmu->y = N_VNew_Serial(KL_N, fmu->ctx)) || !(fmu->J = SUNDenseMatrix(KL_N, KL_N, fmu->ctx))
        || !(fmu->LS = SUNLinSol_Dense(fmu->y, fmu->J, fmu->ctx)) || !(fmu->cvode = CVodeCreate(CV_ADAMS, fmu->ctx)))
        return kl_error(fmu, "setting up CVODE failed");
    memcpy(N_VGetArrayPointer(fmu->y), fmu->x, sizeof fmu->x);
    if (CVodeInit(fmu->cvode, kl_rhs, fmu->t, fmu->y) || CVodeSStolerances(fmu->cvode, rtol, atol)
        || CVodeSetUserData(fmu->cvode, &fmu->data) || CVodeSetLinearSolver(fmu->cvode, fmu->LS, fmu->J)
        || CVodeSetMaxNumSteps(fmu->cvode, KL_FMU_MAX_STEPS) || CVodeSetMaxHnilWarns(fmu->cvode, -1))
        return kl_error(fmu, "setting up CVODE failed");
    fmu->restart = 0;
    return 0;
}

/* Consistent initialisation: the start values projected onto the constraints, the generic rank of
 * [Phi_q; A] there (redundant constraints stay dependent, as in kronlag's drivers). */
static int kl_exit_initialization(kl_fmu *fmu)
{
    kl_fmu_definitions(fmu->p);
    fmu->generic_rank = KL_K;
    if (kl_fmu_project(fmu)) {
        fmu->mode = KL_MODE_ERROR;
        return kl_error(fmu, "the start values cannot be projected onto the constraints: set q (and qd) to an "
                        "assembled state (kronlag: model.assemble)");
    }
    if (KL_K > 0) {
        double terms[KL_TERMS_ + 1], B[KL_K * KL_M + 1], c[KL_K + 1], magnitudes[KL_K + 1];
        int perm[KL_K + 1];
        kl_constraints(fmu->t, fmu->x, fmu->p, terms, B, c);
        rank_magnitudes(B, KL_K, KL_M, magnitudes, perm);
        fmu->generic_rank = rank_of(magnitudes, KL_K < KL_M ? KL_K : KL_M);
    }
    fmu->mode = KL_MODE_RUNNING;
    kl_changed(fmu);
    return fmu->cosimulation ? kl_cvode_start(fmu) : 0;
}

static int kl_get(kl_fmu *fmu, unsigned r, double *value)
{
    if (fmu->mode == KL_MODE_INITIALIZATION) kl_fmu_definitions(fmu->p);
    if (r < KL_VR_DERIVATIVES) *value = fmu->x[r];
    else if (r < KL_VR_PARAMETERS) {
        if (kl_derivatives(fmu)) return 1;
        *value = fmu->dx[r - KL_VR_DERIVATIVES];
    } else if (r < KL_VR_ALPHA) *value = fmu->p[r - KL_VR_PARAMETERS];
    else if (r == KL_VR_ALPHA) *value = fmu->alpha;
    else if (r == KL_VR_BETA) *value = fmu->beta;
    else if (r == KL_VR_DRIFT_TOLERANCE) *value = fmu->drift_tolerance;
    else if (r < KL_VR_COUNT) {
        kl_outputs_now(fmu);
        *value = fmu->outputs[r - KL_VR_OUTPUTS];
    } else if (r == KL_VR_TIME) *value = fmu->t;
    else return kl_error(fmu, "no variable has the value reference %u", r);
    return 0;
}

static int kl_set(kl_fmu *fmu, unsigned r, double value)
{
    static const int calculated[KL_NP + 1] = KL_FMU_CALCULATED;
    if (r < KL_VR_DERIVATIVES) {
        if (fmu->mode == KL_MODE_RUNNING && fmu->cosimulation)
            return kl_error(fmu, "the states of a co-simulation cannot be set after initialization");
        fmu->x[r] = value;
    } else if (r >= KL_VR_PARAMETERS && r < KL_VR_ALPHA && !calculated[r - KL_VR_PARAMETERS])
        fmu->p[r - KL_VR_PARAMETERS] = value;
    else if (r == KL_VR_ALPHA) fmu->alpha = value;
    else if (r == KL_VR_BETA) fmu->beta = value;
    else if (r == KL_VR_DRIFT_TOLERANCE) fmu->drift_tolerance = value;
    else return kl_error(fmu, "the variable with value reference %u cannot be set", r);
    if (fmu->mode == KL_MODE_RUNNING) kl_fmu_definitions(fmu->p);
    kl_changed(fmu);
    return 0;
}

/* Model Exchange: a step event is needed (the drift exceeds kronlag.drift_tolerance). */
static int kl_step_event(const kl_fmu *fmu)
{
    return kl_drift(fmu) > fmu->drift_tolerance;
}

/* Model Exchange, the event update: the states projected when they drifted off the constraints
 * (*changed set). */
static int kl_event_update(kl_fmu *fmu, int *changed)
{
    *changed = 0;
    if (kl_drift(fmu) <= fmu->drift_tolerance / 100.0) return 0;
    if (kl_fmu_project(fmu)) return 1;
    *changed = 1;
    return 0;
}

static void kl_set_time(kl_fmu *fmu, double t)
{
    fmu->t = t;
    fmu->have_derivatives = fmu->have_outputs = 0;
}

static int kl_set_states(kl_fmu *fmu, const double *x, size_t n)
{
    if (n != KL_N) return kl_error(fmu, "%zu continuous states given, the FMU has %d", n, KL_N);
    memcpy(fmu->x, x, sizeof fmu->x);
    fmu->have_derivatives = fmu->have_outputs = 0;
    return 0;
}

static int kl_get_states(kl_fmu *fmu, double *x, size_t n)
{
    if (n != KL_N) return kl_error(fmu, "%zu continuous states asked for, the FMU has %d", n, KL_N);
    memcpy(x, fmu->x, sizeof fmu->x);
    return 0;
}

static int kl_get_derivatives(kl_fmu *fmu, double *dx, size_t n)
{
    if (n != KL_N) return kl_error(fmu, "%zu derivatives asked for, the FMU has %d states", n, KL_N);
    if (kl_derivatives(fmu)) return 1;
    memcpy(dx, fmu->dx, sizeof fmu->dx);
    return 0;
}

/* Co-Simulation: from t to t + h (CVODE restarted first after a change of an input or a parameter). */
static int kl_do_step(kl_fmu *fmu, double t, double h)
{
    if (h <= 0.0) return 0;
    if (fmu->restart) {
        fmu->t = t;
        if (kl_cvode_start(fmu)) return 1;
    }
    double target = t + h, reached = fmu->t;
    CVodeSetStopTime(fmu->cvode, target);
    int flag = CVode(fmu->cvode, target, fmu->y, &reached, 1 /* CV_NORMAL */);
    if (flag < 0) {
        fmu->mode = KL_MODE_ERROR;
        return kl_error(fmu, "CVODE failed at t = %.9g (%s)", reached,
                        fmu->data.singular ? "a singular configuration" : CVodeGetReturnFlagName(flag));
    }
    fmu->t = target;
    memcpy(fmu->x, N_VGetArrayPointer(fmu->y), sizeof fmu->x);
    fmu->have_derivatives = fmu->have_outputs = 0;
    if (kl_project(fmu->t, fmu->x, &fmu->data))
        return kl_error(fmu, "the projection onto the constraints failed at t = %.9g", fmu->t);
    return 0;
}
