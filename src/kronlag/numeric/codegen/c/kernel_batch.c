/* kronlag: evaluation of a kernel over many states, split over POSIX threads (see
 * kronlag.codegen.CLibrary.evaluate_batch). */

#if KRONLAG_IN_PART(0)
#include <pthread.h>
#define KRONLAG_MAX_THREADS 64
#define KRONLAG_MIN_STATES_PER_THREAD 256
typedef void (*kronlag_range_work)(const void *job, long begin, long end);
struct kronlag_range { kronlag_range_work work; const void *job; long begin, end; };

static void *kronlag_run_range(void *argument)
{
    const struct kronlag_range *range = argument;
    range->work(range->job, range->begin, range->end);
    return NULL;
}

static void kronlag_parallel(kronlag_range_work work, const void *job, long n, int threads)
{
    if (threads > KRONLAG_MAX_THREADS) threads = KRONLAG_MAX_THREADS;
    if (threads > n / KRONLAG_MIN_STATES_PER_THREAD) threads = (int)(n / KRONLAG_MIN_STATES_PER_THREAD);
    if (threads < 2) {
        work(job, 0, n);
        return;
    }
    pthread_t handles[KRONLAG_MAX_THREADS];
    struct kronlag_range ranges[KRONLAG_MAX_THREADS];
    int started[KRONLAG_MAX_THREADS];
    for (int k = 0; k < threads; ++k) {
        ranges[k] = (struct kronlag_range){work, job, n * k / threads, n * (k + 1) / threads};
        started[k] = k > 0 && pthread_create(&handles[k], NULL, kronlag_run_range, &ranges[k]) == 0;
    }
    for (int k = 0; k < threads; ++k)
        if (!started[k]) kronlag_run_range(&ranges[k]);
    for (int k = 1; k < threads; ++k)
        if (started[k]) pthread_join(handles[k], NULL);
}

typedef void (*kronlag_kernel_function)(double t, const double *q, const double *qd, const double *p, double *out);
struct kronlag_kernel_job {
    kronlag_kernel_function kernel;
    long m, size, t_step, qd_step, p_step;
    const double *t, *q, *qd, *p;
    double *out;
};

static void kronlag_kernel_range(const void *argument, long begin, long end)
{
    const struct kronlag_kernel_job *job = argument;
    for (long i = begin; i < end; ++i)
        job->kernel(job->t[i * job->t_step], job->q + i * job->m, job->qd + i * job->qd_step,
                    job->p + i * job->p_step, job->out + i * job->size);
}

void kronlag_kernel_batch(kronlag_kernel_function kernel, long n, long m, long size, const double *t, long t_step,
                          const double *q, const double *qd, long qd_step, const double *p, long p_step,
                          double *out, int threads)
{
    struct kronlag_kernel_job job = {kernel, m, size, t_step, qd_step, p_step, t, q, qd, p, out};
    kronlag_parallel(kronlag_kernel_range, &job, n, threads);
}
#endif
