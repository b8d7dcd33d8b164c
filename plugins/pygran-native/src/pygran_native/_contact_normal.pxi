# Normal contact laws (LAMMPS GRANULAR's normal and damping sub-models): hooke and hertz
# spring-dashpots with limitForce and SJKR cohesion, and Thornton-Ning's elastic-plastic JKR
# adhesion with its history. Each gives the normal force and the normal and tangential stiffness
# and tangential damping that the tangential and rolling laws use.

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


cdef inline int normal_force(int model, const Coef* c, double delta, double Rs, double ms, double vn,
                             double* hist, bint update, double* fn, double* kn, double* kt,
                             double* gt) noexcept nogil:
    """Normal force ``fn`` of a contact of overlap ``delta`` closing at ``vn``, its normal and
    tangential stiffness ``kn``, ``kt`` and tangential damping ``gt``: IN_CONTACT, or
    NO_CONTACT / MEMORY (Thornton-Ning) with nothing set. Updates Thornton-Ning's history."""
    cdef double gn
    cdef int res
    if model == HERTZ:
        if delta <= 0.0:
            return NO_CONTACT
        fn[0] = pg_hertz_normal(c.E, c.G, c.damp, c.tdamp, c.coh, c.limit, delta, Rs, ms, vn, kn, kt, gt)
        return IN_CONTACT
    if model == HOOKE:
        if delta <= 0.0:
            return NO_CONTACT
        kn[0] = hooke_stiffness(c, Rs, ms)
        gn = c.damp * sqrt(kn[0] * ms)
        kt[0] = kn[0]
        gt[0] = gn
        fn[0] = pg_viscoelastic(kn[0], gn, delta, Rs, vn, c.coh, c.limit)
        return IN_CONTACT
    res = tn_normal(c, delta, Rs, hist, update, fn, kt)
    if res == IN_CONTACT:
        gt[0] = 0.0
        kn[0] = kt[0] * c.E / (6.0 * c.G)   # 4/3 E* a, as hertz (kt = 8 G* a)
    return res
