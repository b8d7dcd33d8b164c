#ifndef PYGRAN_PAIR_LAW_H
#define PYGRAN_PAIR_LAW_H

/* The spring-dashpot normal law (hooke, hertz), hertz's stiffness and damping, and the
   tangential law with history, for one contact: written once, used by the per-contact path
   (normal_force, tangential_force in _contact_*.pxi) and inlined into the batched loop
   (pair_batch.h), which the compiler vectorises. None has a branch: each computes every case,
   then chooses, so the loop has no control flow. */
#include <math.h>

/* Spring-dashpot normal force `kn delta + gn vn` of a contact of overlap `delta` (> 0)
   closing at `vn` (hooke, hertz), kept from turning attractive when `limit` != 0
   (limitForce), less the SJKR cohesion `coh pi delta (2 R* - delta)`. */
static inline __attribute__((always_inline)) double pg_viscoelastic(
    double kn, double gn, double delta, double Rs, double vn, double coh, double limit)
{
    double fn = kn * delta + gn * vn;
    double fc;
    fn = (fn < 0.0) & (limit != 0.0) ? 0.0 : fn;
    fc = fn - ((coh * M_PI) * delta) * ((2.0 * Rs) - delta);
    return coh > 0.0 ? fc : fn;
}

/* Hertz normal force (pg_viscoelastic with hertz's stiffness and damping); sets the normal and
   tangential stiffness `kn`, `kt` and the tangential damping `gt`. `damp` is
   -2 sqrt(5/6) beta, `tdamp` sqrt(4 G* / E*). */
static inline __attribute__((always_inline)) double pg_hertz_normal(
    double E, double G, double damp, double tdamp, double coh, double limit, double delta,
    double Rs, double ms, double vn, double* kn, double* kt, double* gt)
{
    double a = sqrt(Rs * delta);
    double gn = damp * sqrt(((2.0 * E) * a) * ms);
    *kn = ((4.0 / 3.0) * E) * a;
    *kt = (8.0 * G) * a;
    *gt = tdamp * gn;
    return pg_viscoelastic(*kn, gn, delta, Rs, vn, coh, limit);
}

/* Tangential force `Ft` on i (LIGGGHTS tangential_model_history): the spring `-kt xi` on the
   displacement history `xi` (advanced by the tangential velocity at the contact and rotated
   into the contact plane when `update`) plus the dashpot `-gt v_t`; if the spring alone
   exceeds `mu |fn|` the contact slides: the spring scaled to `mu |fn|`, no dashpot, and the
   history set to match. `n` points from j to i, `vr` = v_i - v_j, `rw` = r_i w_i + r_j w_j
   (the levers to the contact point), `vn` = -vr.n. */
static inline __attribute__((always_inline)) void pg_tangential(
    double mu, double kt, double gt, double fn, double vn, const double* n, const double* vr,
    const double* rw, double* xi, double dt, int update, double* Ft)
{
    double cw0 = rw[1] * n[2] - rw[2] * n[1];
    double cw1 = rw[2] * n[0] - rw[0] * n[2];
    double cw2 = rw[0] * n[1] - rw[1] * n[0];
    double vt0 = (vr[0] + vn * n[0]) - cw0;
    double vt1 = (vr[1] + vn * n[1]) - cw1;
    double vt2 = (vr[2] + vn * n[2]) - cw2;
    double x0 = xi[0], x1 = xi[1], x2 = xi[2];
    double s = (x0 * n[0] + x1 * n[1]) + x2 * n[2];
    double u0 = update ? x0 + ((vt0 * dt) - (s * n[0])) : x0;
    double u1 = update ? x1 + ((vt1 * dt) - (s * n[1])) : x1;
    double u2 = update ? x2 + ((vt2 * dt) - (s * n[2])) : x2;
    double f0 = (-kt) * u0, f1 = (-kt) * u1, f2 = (-kt) * u2;
    double ftm = (f0 * f0 + f1 * f1) + f2 * f2;
    double lim = mu * fabs(fn);
    double ratio = lim / sqrt(ftm);
    int slide = ftm > lim * lim;
    Ft[0] = slide ? f0 * ratio : f0 - gt * vt0;
    Ft[1] = slide ? f1 * ratio : f1 - gt * vt1;
    Ft[2] = slide ? f2 * ratio : f2 - gt * vt2;
    xi[0] = slide & update ? u0 * ratio : u0;
    xi[1] = slide & update ? u1 * ratio : u1;
    xi[2] = slide & update ? u2 * ratio : u2;
}

#endif
