#ifndef PYGRAN_KICK_DRIFT_H
#define PYGRAN_KICK_DRIFT_H

/* The particle loop's and the drift's arithmetic per row (used by _integrate.pxi), in C with
   restrict pointers: a store to a particle's arrays does not make the compiler reload the
   solver's state, as Cython code reading through State* must. That cuts the particle loop's
   time by about 40 %. Rows whose pair forces are in their own f and t and at most one pair
   block's halo (with one thread, every row) go through pg_kick_drift in runs, at steps without
   clumps that kick and fuse the next drift. */
#include <math.h>

/* Row i's pair forces from ``f`` and ``t`` (then cleared: the pair loop adds into them), gravity
   (g0, g1, g2) and viscous drag into F and its torque into T, as particle_row sums them before
   it adds any halo. */
static inline void pg_row_forces(long long i, double g0, double g1, double g2, const double* restrict m,
                                 const int* restrict type, const double* restrict visc,
                                 double* restrict f, double* restrict t, const double* restrict v,
                                 double* restrict F, double* restrict T)
{
    double mi = m[i], g = visc[type[i]];
    double* fi = f + 3 * i;
    double* ti = t + 3 * i;
    const double* vi = v + 3 * i;
    F[0] = (mi * g0 - g * vi[0]) + fi[0];
    F[1] = (mi * g1 - g * vi[1]) + fi[1];
    F[2] = (mi * g2 - g * vi[2]) + fi[2];
    T[0] = 0.0 + ti[0];
    T[1] = 0.0 + ti[1];
    T[2] = 0.0 + ti[2];
    fi[0] = fi[1] = fi[2] = ti[0] = ti[1] = ti[2] = 0.0;
}

/* One half kick (``s F``, ``u T``) of a velocity v and spin w (3 values each). */
static inline void pg_kick(double* restrict v, double* restrict w, double s, double u,
                           const double* restrict F, const double* restrict T)
{
    v[0] += s * F[0];
    v[1] += s * F[1];
    v[2] += s * F[2];
    w[0] += u * T[0];
    w[1] += u * T[1];
    w[2] += u * T[2];
}

/* Row i's half kick (see pg_kick). */
static inline void pg_row_kick(long long i, double s, double u, double* restrict v, double* restrict w,
                               const double* restrict F, const double* restrict T)
{
    pg_kick(v + 3 * i, w + 3 * i, s, u, F, T);
}

/* Raises peak[0] to row i's squared displacement from x0 (INFINITY if it is not finite: that
   forces a rebuild, which drops the particle). */
static inline void pg_row_displacement(long long i, double* restrict peak, const double* restrict x,
                                       const double* restrict x0)
{
    const double* xi = x + 3 * i;
    const double* oi = x0 + 3 * i;
    double q0 = xi[0] - oi[0], q1 = xi[1] - oi[1], q2 = xi[2] - oi[2];
    double dd = ((0.0 + q0 * q0) + q1 * q1) + q2 * q2;
    if (!(dd <= peak[0]))
        peak[0] = isfinite(dd) ? dd : INFINITY;
}

/* Row i's ``kicks`` half kicks (1 or 2, see pg_kick; v and w kept in registers between them)
   and drift. Raises ``peak``: [0] with x0 (not NULL) the largest squared displacement (see
   pg_row_displacement), [1] the largest squared speed of a drift (INFINITY if it is not
   finite; see State.travel and State.sub_travel). */
static inline void pg_row_kicks_drift(long long i, int kicks, double dt, double s, double u,
                                      double* restrict peak, double* restrict x, double* restrict v,
                                      double* restrict w, const double* restrict x0,
                                      const double* restrict F, const double* restrict T)
{
    double* vi = v + 3 * i;
    double* wi = w + 3 * i;
    double* xi = x + 3 * i;
    double vl[3] = {vi[0], vi[1], vi[2]}, wl[3] = {wi[0], wi[1], wi[2]};
    for (int k = 0; k < kicks; k++)
        pg_kick(vl, wl, s, u, F, T);
    double v0 = vl[0], v1 = vl[1], v2 = vl[2];
    vi[0] = v0;
    vi[1] = v1;
    vi[2] = v2;
    wi[0] = wl[0];
    wi[1] = wl[1];
    wi[2] = wl[2];
    double p0 = xi[0] + dt * v0, p1 = xi[1] + dt * v1, p2 = xi[2] + dt * v2;
    xi[0] = p0;
    xi[1] = p1;
    xi[2] = p2;
    if (x0)
        pg_row_displacement(i, peak, x, x0);
    double vv = (v0 * v0 + v1 * v1) + v2 * v2;
    if (!(vv <= peak[1]))
        peak[1] = isfinite(vv) ? vv : INFINITY;
}

/* Row i's first half kick and drift (see pg_row_kicks_drift). */
static inline void pg_row_drift(long long i, double dt, double s, double u, double* restrict peak,
                                double* restrict x, double* restrict v, double* restrict w,
                                const double* restrict x0, const double* restrict F, const double* restrict T)
{
    pg_row_kicks_drift(i, 1, dt, s, u, peak, x, v, w, x0, F, T);
}

/* Row i's half kick factors for force (``s``) and torque (``u``). */
static inline void pg_row_kick_factors(long long i, double dt, const double* restrict m,
                                       const double* restrict r, double* s, double* u)
{
    double mi = m[i], ri = r[i];
    *s = (0.5 * dt) / mi;
    *u = (0.5 * dt) / (((0.4 * mi) * ri) * ri);
}

/* Row i's second half kick by force F and torque T, then the next step's first half kick and
   drift (see pg_row_drift). */
static inline void pg_row_kick_drift(long long i, double dt, double* restrict peak, const double* restrict m,
                                     const double* restrict r, double* restrict x, double* restrict v,
                                     double* restrict w, const double* restrict x0,
                                     const double* restrict F, const double* restrict T)
{
    double s, u;
    pg_row_kick_factors(i, dt, m, r, &s, &u);
    pg_row_kicks_drift(i, 2, dt, s, u, peak, x, v, w, x0, F, T);
}

/* Rows [lo, hi) (see pg_row_kick_drift for ``peak`` and x0) that no halo holds, or with ``halo``
   (not NULL) that one halo holds, from its entry for row lo (added after the rows' own pair
   forces, as particle_row adds it, and cleared). */
static void pg_kick_drift(int lo, int hi, double dt, double* restrict peak, const double* restrict grav,
                          const double* restrict m, const double* restrict r, const int* restrict type,
                          const double* restrict visc, double* restrict f, double* restrict t, double* restrict x,
                          double* restrict v, double* restrict w, const double* restrict x0,
                          double* restrict halo)
{
    double F[3], T[3], top[2] = {peak[0], peak[1]};
    for (long long i = lo; i < hi; i++) {
        pg_row_forces(i, grav[0], grav[1], grav[2], m, type, visc, f, t, v, F, T);
        if (halo) {
            double* h = halo + 6 * (i - lo);
            F[0] += h[0];
            F[1] += h[1];
            F[2] += h[2];
            T[0] += h[3];
            T[1] += h[4];
            T[2] += h[5];
            h[0] = h[1] = h[2] = h[3] = h[4] = h[5] = 0.0;
        }
        pg_row_kick_drift(i, dt, top, m, r, x, v, w, x0, F, T);
    }
    peak[0] = top[0];
    peak[1] = top[1];
}

#endif
