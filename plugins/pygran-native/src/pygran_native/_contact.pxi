# A contact's force and torque from its sub-models: normal (with damping and cohesion,
# _contact_normal.pxi), tangential (_contact_tangential.pxi) and rolling (_contact_rolling.pxi).

cdef inline int contact_force(int model, int rolling, int roff, const Coef* c, double delta, double Rs,
                              double ms, double Ir, const double* n, const double* vr, const double* rw,
                              const double* wrel, double* hist, double dt, bint update,
                              double* F, double* Ft, double* Mr) noexcept nogil:
    """Force on body i of a contact: IN_CONTACT, or NO_CONTACT / MEMORY with nothing set.

    ``n`` points from j to i, ``delta`` is the overlap, ``vr = v_i - v_j`` at the centres,
    ``rw = r_i w_i + r_j w_j``, ``wrel = w_i - w_j``, ``Ir`` the pair's rolling inertia
    (epsd). Sets ``F`` (total force on i), ``Ft`` (its tangential part, for torques) and ``Mr``
    (rolling torque on i); updates ``hist`` (the rolling spring's from ``roff``).
    """
    cdef double vn, kn, kt, gt, fn
    cdef int k, res
    vn = -dot3(vr, n)   # overlap rate, positive approaching
    res = normal_force(model, c, delta, Rs, ms, vn, hist, update, &fn, &kn, &kt, &gt)
    if res != IN_CONTACT:
        if res == MEMORY and update and rolling != CDT:
            memset(&hist[roff], 0, 3 * sizeof(double))
        return res
    hist[H_FN] = fn
    for k in range(3):
        F[k] = fn * n[k]
        Ft[k] = 0.0
        Mr[k] = 0.0
    if c.mu > 0.0:
        tangential_force(c, fn, kt, gt, vn, n, vr, rw, hist, dt, update, Ft)
        for k in range(3):
            F[k] += Ft[k]
    if c.mur > 0.0:
        if rolling != CDT:
            elastic_plastic_rolling(rolling, c, fn, kn, kt, Rs, Ir, n, wrel, &hist[roff], dt, update, Mr)
        else:
            cdt_rolling(c, kn * delta, Rs, n, wrel, Mr)
    return IN_CONTACT
