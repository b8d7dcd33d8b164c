# The tangential contact law: a spring on the tangential displacement history and a dashpot,
# limited by Coulomb friction, as LIGGGHTS' tangential_model history has it (the dashpot
# acts only while the contact sticks).

cdef inline void tangential_force(const Coef* c, double fn, double kt, double gt, double vn, const double* n,
                                  const double* vr, const double* rw, double* hist, double dt, bint update,
                                  double* Ft) noexcept nogil:
    """Tangential force ``Ft`` on i: the spring ``-kt xi`` on the displacement history
    ``xi = hist[H_SHEAR..]`` (advanced by the tangential velocity at the contact and rotated
    into the contact plane when ``update``) plus the dashpot ``-gt v_t``; if the spring alone
    exceeds ``mu |fn|`` the contact slides: the spring scaled to ``mu |fn|``, no dashpot, and
    the history set to match (LIGGGHTS ``tangential_model_history.h``). ``n``, ``vr``,
    ``rw``: see contact_force."""
    cdef double ftm, lim, ratio, s
    cdef double vt[3]
    cdef double cw[3]
    cdef int k
    cross3(rw, n, cw)
    for k in range(3):
        vt[k] = vr[k] + vn * n[k] - cw[k]
    if update:
        s = dot3(&hist[H_SHEAR], n)
        for k in range(3):
            hist[H_SHEAR + k] += vt[k] * dt - s * n[k]
    for k in range(3):
        Ft[k] = -kt * hist[H_SHEAR + k]
    ftm = dot3(Ft, Ft)
    lim = c.mu * fabs(fn)
    if ftm > lim * lim:
        ratio = lim / sqrt(ftm)
        for k in range(3):
            Ft[k] *= ratio
            if update:
                hist[H_SHEAR + k] *= ratio
    else:
        for k in range(3):
            Ft[k] -= gt * vt[k]
