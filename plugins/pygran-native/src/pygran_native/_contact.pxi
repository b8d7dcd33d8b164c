# Contact laws: normal force (hooke, hertz, Thornton-Ning with JKR adhesion), damping,
# tangential (Coulomb-limited history) and rolling resistance (cdt, epsd, epsd2).

# --- Thornton-Ning JKR geometry (the reference model's formulas) ------------------------
cdef inline double tn_overlap(double a, double R, double E, double g) noexcept nogil:
    return a * a / R - 2.0 * sqrt(M_PI * g * a / E)


cdef inline double tn_force(double a, double R, double E, double g) noexcept nogil:
    return 4.0 * E * a * a * a / (3.0 * R) - 4.0 * sqrt(M_PI * g * E * a * a * a)


cdef inline double tn_sep_radius(double R, double E, double g) noexcept nogil:
    return cbrt(M_PI * g * R * R / (4.0 * E))


cdef double tn_contact_radius(double overlap, double R, double E, double g) noexcept nogil:
    """Stable-branch contact radius at this overlap, -1 where the contact cannot exist."""
    cdef double q, c, xmin, x, xn, slope
    cdef int it
    if overlap < tn_overlap(tn_sep_radius(R, E, g), R, E, g):
        return -1.0
    q = R * overlap
    if g == 0.0:
        return sqrt(q if q > 0.0 else 0.0)
    c = 2.0 * R * sqrt(M_PI * g / E)
    xmin = cbrt(c / 4.0)
    x = sqrt(sqrt(2.0 * (q if q > 0.0 else 0.0)))
    if cbrt(2.0 * c) > x:
        x = cbrt(2.0 * c)
    for it in range(200):
        slope = 4.0 * x * x * x - c
        xn = x - ((x * x * x * x - c * x - q) / slope if slope > 0.0 else 0.0)
        if xn < xmin:
            xn = xmin
        if fabs(xn - x) <= 1e-15 * x:
            x = xn
            break
        x = xn
    return x * x


cdef void tn_unloading(double dm, double R, const Coef* c, double* Rp, double* dp) noexcept nogil:
    """Unloading curvature radius R_p and plastic offset delta_p for the largest overlap dm."""
    cdef double am = tn_contact_radius(dm, R, c.E, c.coh)
    cdef double ay = M_PI * c.py * R / (2.0 * c.E)
    cdef double F1
    Rp[0] = R
    if am < 0.0:
        am = 0.0
    if am > ay:
        F1 = 4.0 * c.E * ay * ay * ay / (3.0 * R) + M_PI * c.py * (am * am - ay * ay)
        Rp[0] = 4.0 * c.E * am * am * am / (3.0 * F1)
    dp[0] = am * am * (1.0 / R - 1.0 / Rp[0])


cdef double hooke_stiffness(const Coef* c, double Rs, double ms) noexcept nogil:
    """LIGGGHTS hooke: ``16/15 sqrt(R*) E* (15 m* V^2 / (16 sqrt(R*) E*))^(1/5)``."""
    cdef double a = sqrt(Rs)
    return 16.0 / 15.0 * a * c.E * (15.0 * ms * c.vchar * c.vchar / (16.0 * a * c.E)) ** 0.2


cdef int tn_normal(const Coef* c, double delta, double Rs, double* hist, bint update,
                   double* fn, double* kt) noexcept nogil:
    """Thornton-Ning normal force and tangential stiffness, updating the normal history.

    ``hist[H_DMAX]`` is the largest overlap (negated while the contact is broken but the bodies
    still overlap: the plastic offset ``hist[H_DP]`` is remembered and the contact forms again
    when the overlap reaches it), ``hist[H_RP]`` the unloading curvature radius, ``hist[H_DP]``
    the plastic offset.
    """
    cdef double dm = hist[H_DMAX], Rp, dp, a
    if dm < 0.0:
        if delta <= 0.0:
            return NO_CONTACT
        if delta < hist[H_DP]:
            return MEMORY
        dm = -dm
        if update:
            hist[H_DMAX] = dm
    elif dm == 0.0 and delta <= 0.0:
        return NO_CONTACT
    Rp = hist[H_RP]
    dp = hist[H_DP]
    if delta > dm:
        tn_unloading(delta, Rs, c, &Rp, &dp)
        if update:
            hist[H_DMAX] = delta
            hist[H_RP] = Rp
            hist[H_DP] = dp
    a = tn_contact_radius(delta - dp, Rp, c.E, c.coh)
    if a < 0.0:
        if delta <= 0.0:
            return NO_CONTACT
        if update:
            hist[H_DMAX] = -(delta if delta > dm else dm)
            hist[H_SHEAR] = hist[H_SHEAR + 1] = hist[H_SHEAR + 2] = hist[H_FN] = 0.0
        return MEMORY
    fn[0] = tn_force(a, Rp, c.E, c.coh)
    kt[0] = 8.0 * c.G * a
    return IN_CONTACT


cdef inline void elastic_plastic_rolling(int rolling, const Coef* c, double fn, double kn, double kt,
                                         double Rs, double Ir, const double* n, const double* wrel,
                                         double* h, double dt, bint update, double* Mr) noexcept nogil:
    """Rolling torque on i of LIGGGHTS' ``rolling_friction epsd`` and ``epsd2`` (doc pages
    gran_rolling_friction_epsd.html and gran_rolling_friction_epsd2.html; Ai et al., Powder
    Technology 206 (2011) 269, and Iwashita & Oda 1998).

    A spring torque ``M`` (history ``h``, 3 values) grows by ``k_r w_t dt`` with the relative
    rotation rate about axes in the contact plane ``w_t``, and is limited to the full
    mobilisation torque ``mu_r R* |F_n|``. ``k_r = 2.25 k_n mu_r^2 R*^2`` (epsd) or
    ``k_t R*^2`` (epsd2), with the normal and tangential stiffness ``k_n, k_t`` of the normal
    law. epsd adds, below the limit, the dashpot ``eta_r 2 sqrt(I_r k_r) w_t`` (``eta_r``:
    coefficientRollingViscousDamping, ``I_r`` the rolling inertia of the pair).
    """
    cdef double wt[3]
    cdef double M[3]
    cdef double wn = dot3(wrel, n), kr, lim, mag2, ratio, cr = 0.0
    cdef int k
    kr = 2.25 * kn * c.mur * c.mur * Rs * Rs if rolling == EPSD else kt * Rs * Rs
    for k in range(3):
        wt[k] = wrel[k] - wn * n[k]
        M[k] = h[k] + (dt * kr * wt[k] if update else 0.0)
    mag2 = dot3(M, M)
    lim = c.mur * Rs * fabs(fn)
    if mag2 > lim * lim:
        ratio = lim / sqrt(mag2)
        for k in range(3):
            M[k] *= ratio
    elif rolling == EPSD:
        cr = c.rdamp * 2.0 * sqrt(Ir * kr)
    for k in range(3):
        if update:
            h[k] = M[k]
        Mr[k] = -(M[k] + cr * wt[k])


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
    cdef double vn, a, kn, gn, kt, gt, fn, ftm, lim, ratio, s, wm
    cdef double vt[3]
    cdef double cw[3]
    cdef int k, res
    vn = -dot3(vr, n)   # overlap rate, positive approaching
    if model == HERTZ:
        if delta <= 0.0:
            return NO_CONTACT
        a = sqrt(Rs * delta)
        kn = 4.0 / 3.0 * c.E * a
        gn = c.damp * sqrt(2.0 * c.E * a * ms)
        kt = 8.0 * c.G * a
        gt = c.tdamp * gn
        fn = kn * delta + gn * vn
        if fn < 0.0 and c.limit != 0.0:
            fn = 0.0
        if c.coh > 0.0:
            fn -= c.coh * M_PI * delta * (2.0 * Rs - delta)
    elif model == HOOKE:
        if delta <= 0.0:
            return NO_CONTACT
        kn = hooke_stiffness(c, Rs, ms)
        gn = c.damp * sqrt(kn * ms)
        kt = kn
        gt = gn
        fn = kn * delta + gn * vn
        if fn < 0.0 and c.limit != 0.0:
            fn = 0.0
        if c.coh > 0.0:
            fn -= c.coh * M_PI * delta * (2.0 * Rs - delta)
    else:
        res = tn_normal(c, delta, Rs, hist, update, &fn, &kt)
        if res != IN_CONTACT:
            if res == MEMORY and update and rolling != CDT:
                memset(&hist[roff], 0, 3 * sizeof(double))
            return res
        gt = 0.0
        kn = kt * c.E / (6.0 * c.G)   # 4/3 E* a, as hertz (kt = 8 G* a)
    hist[H_FN] = fn
    for k in range(3):
        F[k] = fn * n[k]
        Ft[k] = 0.0
        Mr[k] = 0.0
    if c.mu > 0.0:
        cross3(rw, n, cw)
        for k in range(3):
            vt[k] = vr[k] + vn * n[k] - cw[k]
        if update:
            s = dot3(&hist[H_SHEAR], n)
            for k in range(3):
                hist[H_SHEAR + k] += vt[k] * dt - s * n[k]
        for k in range(3):
            Ft[k] = -kt * hist[H_SHEAR + k] - gt * vt[k]
        ftm = dot3(Ft, Ft)
        lim = c.mu * fabs(fn)
        if ftm > lim * lim:
            ratio = lim / sqrt(ftm)
            for k in range(3):
                Ft[k] *= ratio
                if update and kt > 0.0:
                    hist[H_SHEAR + k] = ratio * (hist[H_SHEAR + k] + gt * vt[k] / kt) - gt * vt[k] / kt
        for k in range(3):
            F[k] += Ft[k]
    if c.mur > 0.0:
        if rolling != CDT:
            elastic_plastic_rolling(rolling, c, fn, kn, kt, Rs, Ir, n, wrel, &hist[roff], dt, update, Mr)
            return IN_CONTACT
        wm = sqrt(dot3(wrel, wrel))
        if wm > 0.0:   # as LIGGGHTS' cdt, without the torque's torsion part (along n)
            s = -c.mur * Rs * fabs(fn) / wm
            for k in range(3):
                Mr[k] = s * wrel[k]
            s = dot3(Mr, n)
            for k in range(3):
                Mr[k] -= s * n[k]
    return IN_CONTACT
