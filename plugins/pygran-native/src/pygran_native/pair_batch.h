#ifndef PYGRAN_PAIR_BATCH_H
#define PYGRAN_PAIR_BATCH_H

/* The pair loop's batched path (used by _pairs.pxi): the forces of a batch of pairs within
   reach, hertz with tangential history and no rolling resistance, computed together in one
   loop without branches, which the compiler vectorises (AVX2 where the CPU has it, chosen at
   load time). The pair law is the per-contact path's (pair_law.h), and IEEE arithmetic
   rounds each operation alike in vector and scalar registers, so the results are those of the
   scalar path to the bit. */
#include "pair_law.h"

#define PG_BATCH 128

/* One entry per pair within reach (in: gathered by batched_rows; out: added up by it). Vectors
   are three rows of PG_BATCH: component q of entry t at [q * PG_BATCH + t]. */
typedef struct {
    double d[3 * PG_BATCH];     /* in: x_i - x_j, minimum image */
    double dist2[PG_BATCH];     /* in: |d|^2 */
    double ri[PG_BATCH], rj[PG_BATCH], mi[PG_BATCH], mj[PG_BATCH];
    double vr[3 * PG_BATCH];    /* in: v_i - v_j */
    double wi[3 * PG_BATCH], wj[3 * PG_BATCH];   /* in: angular velocities */
    double E[PG_BATCH], G[PG_BATCH], mu[PG_BATCH], damp[PG_BATCH], tdamp[PG_BATCH];
    double coh[PG_BATCH], limit[PG_BATCH];      /* in: the pair's Coef (one type: not used) */
    double xi[3 * PG_BATCH];    /* in and out: the tangential displacement history */
    double fn[PG_BATCH];        /* out: normal force */
    double F[3 * PG_BATCH];     /* out: force on i */
    double Ti[3 * PG_BATCH];    /* out: torque on i */
    double Tj[3 * PG_BATCH];    /* out: minus the torque on j */
    double touch[PG_BATCH];     /* out: 1 in contact, 0 apart after all (overlap rounded to 0) */
} pg_pair_batch;

/* The loop of pg_hertz_batch, with ``update`` and ``one`` (the pair values are those of ``cf``)
   constants where it is called. */
static inline __attribute__((always_inline)) void pg_hertz_entries(pg_pair_batch* restrict b, int n,
                                                                   double dt, const int update,
                                                                   const int one, const double* cf)
{
    const int B = PG_BATCH;
#pragma GCC ivdep
    for (int t = 0; t < n; t++) {
        double dist2 = b->dist2[t], ri = b->ri[t], rj = b->rj[t], mi = b->mi[t], mj = b->mj[t];
        double E = one ? cf[0] : b->E[t], G = one ? cf[1] : b->G[t], mu = one ? cf[2] : b->mu[t];
        double damp = one ? cf[3] : b->damp[t], tdamp = one ? cf[4] : b->tdamp[t];
        double coh = one ? cf[5] : b->coh[t], limit = one ? cf[6] : b->limit[t];
        double rs = ri + rj;
        double inv = 1.0 / sqrt(dist2);
        double delta = rs - dist2 * inv;
        double cri = ri - 0.5 * delta, crj = rj - 0.5 * delta;   /* levers to the contact point */
        double n0 = b->d[t] * inv, n1 = b->d[B + t] * inv, n2 = b->d[2 * B + t] * inv;
        double vr0 = b->vr[t], vr1 = b->vr[B + t], vr2 = b->vr[2 * B + t];
        double rw0 = cri * b->wi[t] + crj * b->wj[t];
        double rw1 = cri * b->wi[B + t] + crj * b->wj[B + t];
        double rw2 = cri * b->wi[2 * B + t] + crj * b->wj[2 * B + t];
        double den = 1.0 / (rs * (mi + mj));
        double Rs = ((ri * rj) * (mi + mj)) * den;
        double ms = ((mi * mj) * rs) * den;
        /* normal and tangential (pair_law.h) */
        double vn = -((vr0 * n0 + vr1 * n1) + vr2 * n2);
        double kn, kt, gt;
        double fn = pg_hertz_normal(E, G, damp, tdamp, coh, limit, delta, Rs, ms, vn, &kn, &kt, &gt);
        double nv[3] = {n0, n1, n2}, vr[3] = {vr0, vr1, vr2}, rw[3] = {rw0, rw1, rw2};
        double x0 = b->xi[t], x1 = b->xi[B + t], x2 = b->xi[2 * B + t];
        double xi[3] = {x0, x1, x2}, ft[3];
        pg_tangential(mu, kt, gt, fn, vn, nv, vr, rw, xi, dt, update, ft);
        int friction = mu > 0.0;
        double f0 = friction ? ft[0] : 0.0, f1 = friction ? ft[1] : 0.0, f2 = friction ? ft[2] : 0.0;
        b->xi[t] = friction ? xi[0] : x0;
        b->xi[B + t] = friction ? xi[1] : x1;
        b->xi[2 * B + t] = friction ? xi[2] : x2;
        double fb0 = fn * n0, fb1 = fn * n1, fb2 = fn * n2;
        double ff0 = fb0 + f0, ff1 = fb1 + f1, ff2 = fb2 + f2;
        b->F[t] = friction ? ff0 : fb0;
        b->F[B + t] = friction ? ff1 : fb1;
        b->F[2 * B + t] = friction ? ff2 : fb2;
        /* torques: the tangential force at the contact point (pair_row) */
        double cx0 = n1 * f2 - n2 * f1, cx1 = n2 * f0 - n0 * f2, cx2 = n0 * f1 - n1 * f0;
        b->Ti[t] = 0.0 - cri * cx0;
        b->Ti[B + t] = 0.0 - cri * cx1;
        b->Ti[2 * B + t] = 0.0 - cri * cx2;
        b->Tj[t] = 0.0 + crj * cx0;
        b->Tj[B + t] = 0.0 + crj * cx1;
        b->Tj[2 * B + t] = 0.0 + crj * cx2;
        b->fn[t] = fn;
        b->touch[t] = delta <= 0.0 ? 0.0 : 1.0;   /* as normal_force: NaN stays in contact */
    }
}

/* Forces of entries 0..n-1 (see contact_force; ``update``: advance the histories). ``cf``: the
   pair values E, G, mu, damp, tdamp, coh, limit of every entry, or NULL: each entry's own. */
__attribute__((target_clones("avx2", "default")))
static void pg_hertz_batch(pg_pair_batch* restrict b, int n, double dt, int update, const double* cf)
{
    if (cf != NULL && update)
        pg_hertz_entries(b, n, dt, 1, 1, cf);
    else if (cf != NULL)
        pg_hertz_entries(b, n, dt, 0, 1, cf);
    else if (update)
        pg_hertz_entries(b, n, dt, 1, 0, cf);
    else
        pg_hertz_entries(b, n, dt, 0, 0, cf);
}

#endif
