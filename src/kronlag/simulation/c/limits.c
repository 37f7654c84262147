/* kronlag compiled integrators: the functions a run with limits watches (kronlag.simulation.watch),
 * appended to the drivers' source after monitor.c and progress.c.  The watched functions are the
 * gaps of the limit sides not held as constraints (o->gaps, o->gap_watched; 1 for a held side), then
 * the contact forces -lam[row] of the held ones (o->contact_rows): each positive while nothing
 * happens; a segment ends where one falls through zero. */

/* The number of watched functions (0: no limits); after the gaps and contacts, one per joint with
 * friction (exact stiction, kronlag_stiction_values in augmented.c). */
static int kl_limit_count(const kronlag_options *o)
{
    return o->gaps ? o->n_gaps + o->n_contacts + KRONLAG_STICTION_WATCHED : 0;
}

/* The watched functions at q with the multipliers lam (used only when o->n_contacts > 0). */
static void kl_limit_values(const kronlag_options *o, const double *q, const double *lam, double *out)
{
    o->gaps((double *)q, (double *)o->gap_parameters, out);
    for (int i = 0; i < o->n_gaps; ++i)
        if (o->gap_watched[i] == 0.0) out[i] = 1.0;
    for (int j = 0; j < o->n_contacts; ++j) out[o->n_gaps + j] = -lam[(int)o->contact_rows[j]];
}

/* Mark in o->roots the functions that fell from positive (before) to zero or below (after);
 * returns how many did. */
static int kl_limit_fell(const kronlag_options *o, const double *before, const double *after)
{
    int count = 0, n = kl_limit_count(o);
    for (int i = 0; i < n; ++i) {
        int fell = before[i] > 0.0 && after[i] <= 0.0;
        o->roots[i] = fell;
        count += fell;
    }
    return count;
}
