/* kronlag: the watch for singular configurations during an integration (policy: tolerances.py).
 *
 * At every accepted step, ratio = magnitude[rho - 1] / magnitude[0] of the pivoted QR of Phi_q^T, each
 * row divided by its norm at the start of the run (its unit: the ratio does not depend on the
 * constraints' units; rho: the generic rank, the rank at the start; redundant constraints lower it
 * for good).  Near
 * a singular configuration the ratio falls like |t - t*| and rises again.
 *
 * - approach: ratio < KRONLAG_APPROACH_RTOL.  The index-1 methods cannot be sure of their branch
 *   past this point and stop there; the switching method hands over to ALI3-P.  To reach the
 *   approach before stepping across it, the next step is limited so that the ratio, extrapolated
 *   linearly, keeps half its value (kl_monitor_max_step).
 * - passage: a local minimum of the sampled ratio below KRONLAG_APPROACH_RTOL.  Each passage is one
 *   event record of KL_EVENT_SIZE doubles:
 *     [t_enter, t_exit, t*, smallest sampled ratio, row, q at that sample (m)]
 *   with t* the extrapolated time of the singular configuration and row the constraint row
 *   (0-based) that the pivoting put last there. */

#define KL_EVENT_SIZE (5 + KRONLAG_M)

typedef struct {
    int generic_rank, count, capacity, samples;
    double t[3], ratio[3], row[3];
    double q[3][KRONLAG_M];
    double scale[KRONLAG_R + 1];       /* the constraint rows' units (kl_row_scales) */
    double *records;
} kl_monitor;

/* The units of the constraint rows in the approach test (row_scales of tolerances.py): their norms in
 * Phi_q; a row at most KRONLAG_RANK_RTOL times the largest gets the largest (1 if all are zero). */
static void kl_row_scales(const double *Phi_q, double *scale)
{
    double largest = 0.0;
    for (int i = 0; i < KRONLAG_R; ++i) {
        double sum = 0.0;
        for (int j = 0; j < KRONLAG_M; ++j) sum += Phi_q[i * KRONLAG_M + j] * Phi_q[i * KRONLAG_M + j];
        scale[i] = sqrt(sum);
        largest = fmax(largest, scale[i]);
    }
    for (int i = 0; i < KRONLAG_R; ++i)
        if (!(scale[i] > KRONLAG_RANK_RTOL * largest)) scale[i] = largest > 0.0 ? largest : 1.0;
}

/* magnitude[rho - 1] / magnitude[0] of Phi_q's rows divided by scale (1 when there is nothing to lose)
 * and its row: singular_ratio of tolerances.py, step for step.  Of a rank deficient Phi_q only the
 * generic_rank rows its own pivoted QR puts first (the independent ones, in their order) are kept. */
static double kl_singular_ratio(const double *Phi_q, const double *scale, int generic_rank, int *row)
{
    double magnitudes[KRONLAG_R + 1], scaled[KRONLAG_R * KRONLAG_M + 1];
    int perm[KRONLAG_R + 1], rows[KRONLAG_R + 1];
    *row = -1;
    if (KRONLAG_R == 0 || generic_rank == 0) return 1.0;
    if (generic_rank < KRONLAG_R) {
        rank_magnitudes(Phi_q, KRONLAG_R, KRONLAG_M, magnitudes, perm);
        for (int i = 0; i < generic_rank; ++i) {  /* perm[:rho], sorted (insertion) */
            int j = i;
            for (; j > 0 && rows[j - 1] > perm[i]; --j) rows[j] = rows[j - 1];
            rows[j] = perm[i];
        }
    } else {
        for (int i = 0; i < KRONLAG_R; ++i) rows[i] = i;
    }
    for (int i = 0; i < generic_rank; ++i)
        for (int j = 0; j < KRONLAG_M; ++j) scaled[i * KRONLAG_M + j] = Phi_q[rows[i] * KRONLAG_M + j] / scale[rows[i]];
    rank_magnitudes(scaled, generic_rank, KRONLAG_M, magnitudes, perm);
    *row = rows[perm[generic_rank - 1]];
    return magnitudes[0] > 0.0 ? magnitudes[generic_rank - 1] / magnitudes[0] : 0.0;
}

/* Start watching at the initial Jacobian; records: room for capacity events; scale: the rows' units
 * (kl_row_scales at the start of the run), or NULL for those of Phi_q here. */
static void kl_monitor_start(kl_monitor *monitor, double t, const double *q, const double *Phi_q, double *records,
                             int capacity, const double *scale)
{
    double magnitudes[KRONLAG_R + 1];
    int perm[KRONLAG_R + 1], row;
    memset(monitor, 0, sizeof *monitor);
    monitor->records = records;
    monitor->capacity = capacity;
    if (KRONLAG_R > 0) {
        rank_magnitudes(Phi_q, KRONLAG_R, KRONLAG_M, magnitudes, perm);
        monitor->generic_rank = rank_of(magnitudes, KRONLAG_M < KRONLAG_R ? KRONLAG_M : KRONLAG_R);
        if (scale) memcpy(monitor->scale, scale, KRONLAG_R * sizeof(double));
        else kl_row_scales(Phi_q, monitor->scale);
    }
    monitor->t[2] = t;
    monitor->ratio[2] = kl_singular_ratio(Phi_q, monitor->scale, monitor->generic_rank, &row);
    monitor->row[2] = row;
    memcpy(monitor->q[2], q, sizeof monitor->q[2]);
    monitor->samples = 1;
}

/* Record the passage at the local minimum in sample 1: t* where the falling line through samples
 * 0 and 1 reaches zero, if that lies before sample 2 (else sample 1's time); the ratio reported is
 * the smallest sampled. */
static void kl_monitor_passage(kl_monitor *monitor)
{
    const double *t = monitor->t, *ratio = monitor->ratio;
    double slope = (ratio[1] - ratio[0]) / (t[1] - t[0]);
    double t_star = slope < 0.0 ? t[1] - ratio[1] / slope : t[1];
    if (!(t_star <= t[2])) t_star = t[1];
    if (monitor->count < monitor->capacity) {
        double *record = monitor->records + monitor->count * KL_EVENT_SIZE;
        record[0] = t[0]; record[1] = t[2]; record[2] = t_star; record[3] = ratio[1]; record[4] = monitor->row[1];
        memcpy(record + 5, monitor->q[1], sizeof monitor->q[1]);
    }
    ++monitor->count;
}

/* Observe the accepted state (t, q) with Jacobian Phi_q; returns the ratio. */
static double kl_monitor_observe(kl_monitor *monitor, double t, const double *q, const double *Phi_q)
{
    int row;
    double ratio = kl_singular_ratio(Phi_q, monitor->scale, monitor->generic_rank, &row);
    for (int i = 0; i < 2; ++i) {
        monitor->t[i] = monitor->t[i + 1]; monitor->ratio[i] = monitor->ratio[i + 1];
        monitor->row[i] = monitor->row[i + 1];
        memcpy(monitor->q[i], monitor->q[i + 1], sizeof monitor->q[i]);
    }
    monitor->t[2] = t; monitor->ratio[2] = ratio; monitor->row[2] = row;
    memcpy(monitor->q[2], q, sizeof monitor->q[2]);
    if (++monitor->samples >= 3 && monitor->ratio[1] < KRONLAG_APPROACH_RTOL
        && monitor->ratio[1] < monitor->ratio[0] && monitor->ratio[1] <= monitor->ratio[2])
        kl_monitor_passage(monitor);
    return ratio;
}

/* Largest next step that keeps the ratio, extrapolated from the last two samples, above half
 * its value (0: no limit). */
static double kl_monitor_max_step(const kl_monitor *monitor)
{
    if (monitor->samples < 2) return 0.0;
    double rate = (monitor->ratio[1] - monitor->ratio[2]) / (monitor->t[2] - monitor->t[1]);
    return rate > 0.0 ? 0.5 * monitor->ratio[2] / rate : 0.0;
}
