#ifndef PYGRAN_KICK_DRIFT_H
#define PYGRAN_KICK_DRIFT_H

/* The particle loop's common case (used by _integrate.pxi): no clumps, and a step that both
   kicks and fuses the next drift. The same operations in the same order as particle_row and
   drift_one, so the same results to the bit, without per-row flags to test and with restrict
   pointers: a store to a particle's arrays does not make the compiler reload the state (which
   particle_row must, through State*). That cuts the loop's time by about 40 %. Rows whose
   forces are all in the shared buffer (no pair block's halo holds them; with one thread, every
   row) go through pg_kick_drift in runs; the others through pg_row_forces, their halos, then
   pg_row_kick_drift. */
#include <math.h>

/* Row i's forces from ``buf`` (then cleared), gravity (g0, g1, g2) and viscous drag into F and
   its torque into T, as particle_row sums them before it adds any halo. */
static inline void pg_row_forces(long long i, double g0, double g1, double g2, const double* restrict m,
                                 const int* restrict type, const double* restrict visc,
                                 double* restrict buf, const double* restrict v, double* restrict F,
                                 double* restrict T)
{
    double mi = m[i], g = visc[type[i]];
    double* b = buf + 6 * i;
    const double* vi = v + 3 * i;
    F[0] = (mi * g0 - g * vi[0]) + b[0];
    F[1] = (mi * g1 - g * vi[1]) + b[1];
    F[2] = (mi * g2 - g * vi[2]) + b[2];
    T[0] = 0.0 + b[3];
    T[1] = 0.0 + b[4];
    T[2] = 0.0 + b[5];
    b[0] = b[1] = b[2] = b[3] = b[4] = b[5] = 0.0;
}

/* Row i's second half kick by force F and torque T, and the next step's first half kick and
   drift. Returns the largest squared displacement from x0 (INFINITY if it is not finite), at
   least ``tmax``. */
static inline double pg_row_kick_drift(long long i, double dt, double tmax, const double* restrict m,
                                       const double* restrict r, double* restrict x, double* restrict v,
                                       double* restrict w, const double* restrict x0,
                                       const double* restrict F, const double* restrict T)
{
    double mi = m[i], ri = r[i], half = 0.5 * dt;
    double* vi = v + 3 * i;
    double* wi = w + 3 * i;
    double* xi = x + 3 * i;
    const double* oi = x0 + 3 * i;
    double s = half / mi;
    double u = half / (((0.4 * mi) * ri) * ri);
    vi[0] = (vi[0] + s * F[0]) + s * F[0];   /* the second half kick, then the next first one */
    vi[1] = (vi[1] + s * F[1]) + s * F[1];
    vi[2] = (vi[2] + s * F[2]) + s * F[2];
    wi[0] = (wi[0] + u * T[0]) + u * T[0];
    wi[1] = (wi[1] + u * T[1]) + u * T[1];
    wi[2] = (wi[2] + u * T[2]) + u * T[2];
    xi[0] += dt * vi[0];
    xi[1] += dt * vi[1];
    xi[2] += dt * vi[2];
    double q0 = xi[0] - oi[0], q1 = xi[1] - oi[1], q2 = xi[2] - oi[2];
    double dd = ((0.0 + q0 * q0) + q1 * q1) + q2 * q2;
    if (!(dd <= tmax))   /* as drift_one: a non-finite particle forces a rebuild */
        tmax = isfinite(dd) ? dd : INFINITY;
    return tmax;
}

/* Rows [lo, hi), none of which a halo holds (see pg_row_kick_drift for the result). */
static double pg_kick_drift(int lo, int hi, double dt, double tmax, const double* restrict grav,
                            const double* restrict m, const double* restrict r, const int* restrict type,
                            const double* restrict visc, double* restrict buf, double* restrict x,
                            double* restrict v, double* restrict w, const double* restrict x0)
{
    double F[3], T[3];
    for (long long i = lo; i < hi; i++) {
        pg_row_forces(i, grav[0], grav[1], grav[2], m, type, visc, buf, v, F, T);
        tmax = pg_row_kick_drift(i, dt, tmax, m, r, x, v, w, x0, F, T);
    }
    return tmax;
}

#endif
