/* kronlag FMU: the FMI 2.0 functions of one shared library for Model Exchange and Co-Simulation.
 *
 * Appended (by kronlag.views.fmu) to the C source of a kronlag NumericModel (NumericModel.c_source)
 * with its "potential_energy" and "Phi_q" kernels, the declarations of kronlag.simulation.interface,
 * monitor.c, progress.c and cvode.c of kronlag.simulation (whose right-hand side kl_rhs, projection
 * kl_project and constraint rows kl_constraints this file uses: one integrator, one projection),
 * then the generated FMU header (value references KL_VR_*, the parameter definitions, the joint
 * reactions; see kronlag/views/fmu/build.py) and the FMI 2.0 headers.
 *
 * States x = [q, qd] (2 m).  Model Exchange: the derivatives are the Baumgarte index-1 form
 * [qd, qdd(alpha, beta)] (kl_rhs); fmi2CompletedIntegratorStep asks for a step event when the
 * drift, max |Phi| or max |Phi_q qd + Phi_t; A qd + b|, exceeds the parameter
 * kronlag.drift_tolerance, and fmi2NewDiscreteStates then projects the states onto the constraints.
 * Co-Simulation: CVODE (Adams, as kronlag.simulate's compiled method) from communication point to
 * communication point, the state handed out projected onto the constraints (the integrator's own
 * state left alone, as kronlag.simulate does); a change of an input or a parameter restarts
 * CVODE from the projected state.  Both: the start values are projected onto the constraints in
 * fmi2ExitInitializationMode.  Outputs: multipliers, joint reactions and energies from forward
 * dynamics without Baumgarte terms (as kronlag's Trajectory). */

#include <stdarg.h>
#include <stdio.h>
#include "fmi2Functions.h"

enum { KL_MODE_INSTANTIATED, KL_MODE_INITIALIZATION, KL_MODE_RUNNING, KL_MODE_TERMINATED, KL_MODE_ERROR };
enum { KL_NP = KL_FMU_PARAMETERS };

typedef struct {
    fmi2CallbackFunctions functions;
    char name[256];
    fmi2Type type;
    int mode;
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
} kl_fmu;

static void kl_log(kl_fmu *fmu, fmi2Status status, const char *category, const char *format, ...)
{
    char message[1024];
    va_list arguments;
    va_start(arguments, format);
    vsnprintf(message, sizeof message, format, arguments);
    va_end(arguments);
    if (fmu->functions.logger)
        fmu->functions.logger(fmu->functions.componentEnvironment, fmu->name, status, category, "%s", message);
}

static fmi2Status kl_fail(kl_fmu *fmu, const char *format, const char *detail)
{
    kl_log(fmu, fmi2Error, "logStatusError", format, detail);
    return fmi2Error;
}

/* The start values: the model's parameter values, the start state, Baumgarte's alpha and beta. */
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

static void kl_changed(kl_fmu *fmu)
{
    fmu->have_derivatives = fmu->have_outputs = 0;
    fmu->restart = 1;
}

static kl_data kl_fmu_data(const kl_fmu *fmu, double tol)
{
    kl_data data;
    memset(&data, 0, sizeof data);
    data.p = fmu->p;
    data.alpha = fmu->alpha;
    data.beta = fmu->beta;
    data.tol = tol;
    data.generic_rank = fmu->generic_rank;
    return data;
}

/* max |Phi| and max |[Phi_q qd + Phi_t; A qd + b]| at the current state. */
static void kl_drift(const kl_fmu *fmu, double *position, double *velocity)
{
    double terms[KL_TERMS_ + 1], B[KL_K * KL_M + 1], c[KL_K + 1];
    kl_constraints(fmu->t, fmu->x, fmu->p, terms, B, c);
    *position = *velocity = 0.0;
    for (int i = 0; i < KL_R; ++i) *position = fmax(*position, fabs(terms[KL_PHI + i]));
    for (int i = 0; i < KL_K; ++i) {
        double sum = c[i];
        for (int j = 0; j < KL_M; ++j) sum += B[i * KL_M + j] * fmu->x[KL_M + j];
        *velocity = fmax(*velocity, fabs(sum));
    }
}

/* Project the state onto the constraints (residual drift_tolerance / 100, as kronlag projects
 * to atol / 100); 0, or 1 when the projection failed. */
static int kl_fmu_project(kl_fmu *fmu)
{
    kl_data data = kl_fmu_data(fmu, fmu->drift_tolerance / 100.0);
    kl_changed(fmu);
    return kl_project(fmu->t, fmu->x, &data);
}

static fmi2Status kl_derivatives(kl_fmu *fmu)
{
    if (fmu->have_derivatives) return fmi2OK;
    kl_data data = kl_fmu_data(fmu, 0.0);
    double lam[KL_R + 1], mu[KL_S + 1];
    memcpy(fmu->dx, fmu->x + KL_M, KL_M * sizeof(double));
    if (kronlag_forward_dynamics_ranked(fmu->t, fmu->x, fmu->x + KL_M, fmu->p, data.alpha, data.beta,
                                        data.generic_rank, fmu->dx + KL_M, lam, mu)) {
        char where[64];
        snprintf(where, sizeof where, "%.9g", fmu->t);
        return kl_fail(fmu, "singular configuration at t = %s: the mass matrix is singular on the constraints' "
                       "null space, or [Phi_q; A] lost rank (the FMU cannot pass singular configurations)", where);
    }
    fmu->have_derivatives = 1;
    return fmi2OK;
}

static fmi2Status kl_outputs_now(kl_fmu *fmu)
{
    if (fmu->have_outputs) return fmi2OK;
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
    return fmi2OK;
}

/* ---- Co-Simulation: CVODE ---------------------------------------------------------------- */

static fmi2Status kl_cvode_start(kl_fmu *fmu)
{
    kl_free_cvode(fmu);
    /* kronlag's tolerances (tolerance = the global accuracy asked for): CVODE's local ones are
     * divided by KL_FMU_TOLERANCE_SCALE, no tighter than KL_FMU_TIGHTEST_*, as in kronlag.simulate */
    double rtol = fmax(fmu->rtol / KL_FMU_TOLERANCE_SCALE, KL_FMU_TIGHTEST_RTOL);
    double atol = fmax(fmu->rtol * KL_FMU_ATOL_RATIO / KL_FMU_TOLERANCE_SCALE, KL_FMU_TIGHTEST_ATOL);
    fmu->data = kl_fmu_data(fmu, fmax(atol / 100.0, KL_FMU_TIGHTEST_ATOL));
    if (SUNContext_Create(0, &fmu->ctx) || SUNContext_ClearErrHandlers(fmu->ctx)
        || !(fmu->y = N_VNew_Serial(KL_N, fmu->ctx)) || !(fmu->J = SUNDenseMatrix(KL_N, KL_N, fmu->ctx))
        || !(fmu->LS = SUNLinSol_Dense(fmu->y, fmu->J, fmu->ctx)) || !(fmu->cvode = CVodeCreate(CV_ADAMS, fmu->ctx)))
        return kl_fail(fmu, "%s", "setting up CVODE failed");
    memcpy(N_VGetArrayPointer(fmu->y), fmu->x, sizeof fmu->x);
    if (CVodeInit(fmu->cvode, kl_rhs, fmu->t, fmu->y) || CVodeSStolerances(fmu->cvode, rtol, atol)
        || CVodeSetUserData(fmu->cvode, &fmu->data) || CVodeSetLinearSolver(fmu->cvode, fmu->LS, fmu->J)
        || CVodeSetMaxNumSteps(fmu->cvode, KL_FMU_MAX_STEPS) || CVodeSetMaxHnilWarns(fmu->cvode, -1))
        return kl_fail(fmu, "%s", "setting up CVODE failed");
    fmu->restart = 0;
    return fmi2OK;
}

/* ---- FMI 2.0: common functions ------------------------------------------------------------ */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[])
{
    (void)c, (void)loggingOn, (void)nCategories, (void)categories;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    (void)fmuResourceLocation, (void)visible, (void)loggingOn;
    if (!functions || !functions->allocateMemory || !functions->freeMemory) return NULL;
    if (!fmuGUID || strcmp(fmuGUID, KL_FMU_GUID) != 0) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                              "the GUID %s is not this FMU's (%s)", fmuGUID ? fmuGUID : "(none)", KL_FMU_GUID);
        return NULL;
    }
    kl_fmu *fmu = functions->allocateMemory(1, sizeof(kl_fmu));
    if (!fmu) return NULL;
    memset(fmu, 0, sizeof *fmu);
    fmu->functions = *functions;
    snprintf(fmu->name, sizeof fmu->name, "%s", instanceName ? instanceName : "");
    fmu->type = fmuType;
    int major = 0, minor = 0, patch = 0;
    char label[64];
    SUNDIALSGetVersionNumber(&major, &minor, &patch, label, sizeof label);
    if (major != 7) {
        kl_log(fmu, fmi2Error, "logStatusError", "the SUNDIALS library loaded is version %d, not 7", major);
        functions->freeMemory(fmu);
        return NULL;
    }
    kl_defaults(fmu);
    fmu->mode = KL_MODE_INSTANTIATED;
    return fmu;
}

void fmi2FreeInstance(fmi2Component c)
{
    kl_fmu *fmu = c;
    if (!fmu) return;
    kl_free_cvode(fmu);
    fmu->functions.freeMemory(fmu);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    kl_fmu *fmu = c;
    (void)stopTimeDefined, (void)stopTime;
    if (toleranceDefined && tolerance > 0.0) fmu->rtol = tolerance;
    fmu->t = fmu->start_time = startTime;
    kl_changed(fmu);
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    ((kl_fmu *)c)->mode = KL_MODE_INITIALIZATION;
    return fmi2OK;
}

/* Consistent initialisation: the start values projected onto the constraints. */
fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    kl_fmu *fmu = c;
    double terms[KL_TERMS_ + 1], B[KL_K * KL_M + 1], cc[KL_K + 1];
    kl_fmu_definitions(fmu->p);
    fmu->generic_rank = KL_K;
    if (kl_fmu_project(fmu)) {
        fmu->mode = KL_MODE_ERROR;
        return kl_fail(fmu, "%s", "the start values cannot be projected onto the constraints: set q (and qd) "
                       "to an assembled state (kronlag: model.assemble)");
    }
    if (KL_K > 0) {
        double magnitudes[KL_K + 1];
        int perm[KL_K + 1];
        kl_constraints(fmu->t, fmu->x, fmu->p, terms, B, cc);
        rank_magnitudes(B, KL_K, KL_M, magnitudes, perm);
        fmu->generic_rank = rank_of(magnitudes, KL_K < KL_M ? KL_K : KL_M);
    }
    fmu->mode = KL_MODE_RUNNING;
    kl_changed(fmu);
    if (fmu->type == fmi2CoSimulation) return kl_cvode_start(fmu);
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c)
{
    ((kl_fmu *)c)->mode = KL_MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c)
{
    kl_fmu *fmu = c;
    kl_free_cvode(fmu);
    kl_defaults(fmu);
    fmu->mode = KL_MODE_INSTANTIATED;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    kl_fmu *fmu = c;
    for (size_t k = 0; k < nvr; ++k) {
        fmi2ValueReference r = vr[k];
        if (r < KL_VR_DERIVATIVES) value[k] = fmu->x[r];
        else if (r < KL_VR_PARAMETERS) {
            if (kl_derivatives(fmu) != fmi2OK) return fmi2Error;
            value[k] = fmu->dx[r - KL_VR_DERIVATIVES];
        } else if (r < KL_VR_ALPHA) {
            if (fmu->mode == KL_MODE_INITIALIZATION) kl_fmu_definitions(fmu->p);
            value[k] = fmu->p[r - KL_VR_PARAMETERS];
        } else if (r == KL_VR_ALPHA) value[k] = fmu->alpha;
        else if (r == KL_VR_BETA) value[k] = fmu->beta;
        else if (r == KL_VR_DRIFT_TOLERANCE) value[k] = fmu->drift_tolerance;
        else if (r < KL_VR_COUNT) {
            if (fmu->mode == KL_MODE_INITIALIZATION) kl_fmu_definitions(fmu->p);
            if (kl_outputs_now(fmu) != fmi2OK) return fmi2Error;
            value[k] = fmu->outputs[r - KL_VR_OUTPUTS];
        } else {
            char text[32];
            snprintf(text, sizeof text, "%u", (unsigned)r);
            return kl_fail(fmu, "fmi2GetReal: no variable has the value reference %s", text);
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    static const int calculated[KL_NP + 1] = KL_FMU_CALCULATED;
    kl_fmu *fmu = c;
    for (size_t k = 0; k < nvr; ++k) {
        fmi2ValueReference r = vr[k];
        if (r < KL_VR_DERIVATIVES) {
            if (fmu->mode == KL_MODE_RUNNING && fmu->type == fmi2CoSimulation)
                return kl_fail(fmu, "%s", "fmi2SetReal: the states of a co-simulation cannot be set after "
                               "initialization");
            fmu->x[r] = value[k];
        } else if (r >= KL_VR_PARAMETERS && r < KL_VR_ALPHA && !calculated[r - KL_VR_PARAMETERS])
            fmu->p[r - KL_VR_PARAMETERS] = value[k];
        else if (r == KL_VR_ALPHA) fmu->alpha = value[k];
        else if (r == KL_VR_BETA) fmu->beta = value[k];
        else if (r == KL_VR_DRIFT_TOLERANCE) fmu->drift_tolerance = value[k];
        else {
            char text[32];
            snprintf(text, sizeof text, "%u", (unsigned)r);
            return kl_fail(fmu, "fmi2SetReal: the variable with value reference %s cannot be set", text);
        }
    }
    if (fmu->mode == KL_MODE_RUNNING) kl_fmu_definitions(fmu->p);
    kl_changed(fmu);
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[])
{
    (void)vr, (void)value;
    return nvr ? kl_fail(c, "%s", "this FMU has no Integer variables") : fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    (void)vr, (void)value;
    return nvr ? kl_fail(c, "%s", "this FMU has no Boolean variables") : fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[])
{
    (void)vr, (void)value;
    return nvr ? kl_fail(c, "%s", "this FMU has no String variables") : fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[])
{
    (void)vr, (void)value;
    return nvr ? kl_fail(c, "%s", "this FMU has no Integer variables") : fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[])
{
    (void)vr, (void)value;
    return nvr ? kl_fail(c, "%s", "this FMU has no Boolean variables") : fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    (void)vr, (void)value;
    return nvr ? kl_fail(c, "%s", "this FMU has no String variables") : fmi2OK;
}

/* canGetAndSetFMUstate, canSerializeFMUstate and providesDirectionalDerivative are false. */
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    (void)state;
    return kl_fail(c, "%s", "fmi2GetFMUstate is not supported");
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    (void)state;
    return kl_fail(c, "%s", "fmi2SetFMUstate is not supported");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    (void)state;
    return kl_fail(c, "%s", "fmi2FreeFMUstate is not supported");
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    (void)state, (void)size;
    return kl_fail(c, "%s", "fmi2SerializedFMUstateSize is not supported");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    (void)state, (void)bytes, (void)size;
    return kl_fail(c, "%s", "fmi2SerializeFMUstate is not supported");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state)
{
    (void)bytes, (void)size, (void)state;
    return kl_fail(c, "%s", "fmi2DeSerializeFMUstate is not supported");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknowns[], size_t nUnknown,
                                        const fmi2ValueReference knowns[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    (void)unknowns, (void)nUnknown, (void)knowns, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    return kl_fail(c, "%s", "fmi2GetDirectionalDerivative is not supported");
}

/* ---- FMI 2.0: Model Exchange -------------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component c)
{
    (void)c;
    return fmi2OK;
}

/* The event step: project the states when they drifted off the constraints. */
fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info)
{
    kl_fmu *fmu = c;
    double position, velocity;
    kl_drift(fmu, &position, &velocity);
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    if (fmax(position, velocity) > fmu->drift_tolerance / 100.0) {
        if (kl_fmu_project(fmu)) {
            char where[64];
            snprintf(where, sizeof where, "%.9g", fmu->t);
            return kl_fail(fmu, "the projection onto the constraints failed at t = %s", where);
        }
        info->valuesOfContinuousStatesChanged = fmi2True;
    }
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c)
{
    (void)c;
    return fmi2OK;
}

/* A step event when the drift exceeds kronlag.drift_tolerance (fmi2NewDiscreteStates projects). */
fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation)
{
    kl_fmu *fmu = c;
    double position, velocity;
    (void)noSetFMUStatePriorToCurrentPoint;
    kl_drift(fmu, &position, &velocity);
    *enterEventMode = fmax(position, velocity) > fmu->drift_tolerance ? fmi2True : fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time)
{
    kl_fmu *fmu = c;
    fmu->t = time;
    fmu->have_derivatives = fmu->have_outputs = 0;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx)
{
    kl_fmu *fmu = c;
    if (nx != KL_N) return kl_fail(fmu, "%s", "fmi2SetContinuousStates: wrong number of states");
    memcpy(fmu->x, x, sizeof fmu->x);
    fmu->have_derivatives = fmu->have_outputs = 0;
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx)
{
    kl_fmu *fmu = c;
    if (nx != KL_N) return kl_fail(fmu, "%s", "fmi2GetDerivatives: wrong number of states");
    if (kl_derivatives(fmu) != fmi2OK) return fmi2Error;
    memcpy(derivatives, fmu->dx, sizeof fmu->dx);
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni)
{
    (void)eventIndicators;
    return ni ? kl_fail(c, "%s", "this FMU has no event indicators") : fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx)
{
    kl_fmu *fmu = c;
    if (nx != KL_N) return kl_fail(fmu, "%s", "fmi2GetContinuousStates: wrong number of states");
    memcpy(x, fmu->x, sizeof fmu->x);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx)
{
    (void)c;
    for (size_t i = 0; i < nx; ++i) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ---- FMI 2.0: Co-Simulation --------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return kl_fail(c, "%s", "fmi2SetRealInputDerivatives is not supported (canInterpolateInputs is false)");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return kl_fail(c, "%s", "fmi2GetRealOutputDerivatives is not supported (maxOutputDerivativeOrder is 0)");
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    kl_fmu *fmu = c;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (communicationStepSize <= 0.0) return fmi2OK;
    if (fmu->restart) {
        fmu->t = currentCommunicationPoint;
        if (kl_cvode_start(fmu) != fmi2OK) return fmi2Error;
    }
    double target = currentCommunicationPoint + communicationStepSize, reached = fmu->t;
    CVodeSetStopTime(fmu->cvode, target);
    int flag = CVode(fmu->cvode, target, fmu->y, &reached, 1 /* CV_NORMAL */);
    if (flag < 0) {
        char where[96];
        snprintf(where, sizeof where, "%.9g (%s)", reached,
                 fmu->data.singular ? "a singular configuration" : CVodeGetReturnFlagName(flag));
        fmu->mode = KL_MODE_ERROR;
        return kl_fail(fmu, "CVODE failed at t = %s", where);
    }
    fmu->t = target;
    memcpy(fmu->x, N_VGetArrayPointer(fmu->y), sizeof fmu->x);
    fmu->have_derivatives = fmu->have_outputs = 0;
    if (kl_project(fmu->t, fmu->x, &fmu->data)) {
        char where[64];
        snprintf(where, sizeof where, "%.9g", fmu->t);
        return kl_fail(fmu, "the projection onto the constraints failed at t = %s", where);
    }
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c)
{
    return kl_fail(c, "%s", "fmi2CancelStep: the steps are not asynchronous");
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value)
{
    (void)s, (void)value;
    return kl_fail(c, "%s", "fmi2GetStatus: the steps are not asynchronous");
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value)
{
    kl_fmu *fmu = c;
    if (s == fmi2LastSuccessfulTime) { *value = fmu->t; return fmi2OK; }
    return kl_fail(c, "%s", "fmi2GetRealStatus: only fmi2LastSuccessfulTime");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value)
{
    (void)s, (void)value;
    return kl_fail(c, "%s", "fmi2GetIntegerStatus is not supported");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value)
{
    (void)s, (void)value;
    return kl_fail(c, "%s", "fmi2GetBooleanStatus is not supported");
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value)
{
    (void)s, (void)value;
    return kl_fail(c, "%s", "fmi2GetStringStatus is not supported");
}
