/* kronlag: forward dynamics over many states, split over POSIX threads (appended after augmented.c;
 * see kronlag.codegen.CLibrary.forward_dynamics_batch). */

struct kronlag_forward_job {
    long n_parameters, t_step, p_step;
    const double *t, *q, *qd, *p;
    double alpha, beta;
    double *out;
    int *rank;
};

static void kronlag_forward_range(const void *argument, long begin, long end)
{
    const struct kronlag_forward_job *job = argument;
    double in[3 + 2 * KRONLAG_M + job->n_parameters];
    in[1] = job->alpha;
    in[2] = job->beta;
    for (long i = begin; i < end; ++i) {
        in[0] = job->t[i * job->t_step];
        memcpy(in + 3, job->q + i * KRONLAG_M, KRONLAG_M * sizeof(double));
        memcpy(in + 3 + KRONLAG_M, job->qd + i * KRONLAG_M, KRONLAG_M * sizeof(double));
        memcpy(in + 3 + 2 * KRONLAG_M, job->p + i * job->p_step, job->n_parameters * sizeof(double));
        job->rank[i] = kronlag_forward_dynamics_packed(in, job->out + i * (KRONLAG_M + KRONLAG_K));
    }
}

void kronlag_forward_dynamics_batch(long n, long n_parameters, const double *t, long t_step, const double *q,
                                    const double *qd, const double *p, long p_step, double alpha, double beta,
                                    double *out, int *rank, int threads)
{
    struct kronlag_forward_job job = {n_parameters, t_step, p_step, t, q, qd, p, alpha, beta, out, rank};
    kronlag_parallel(kronlag_forward_range, &job, n, threads);
}
