# Rolling resistance (LAMMPS GRANULAR's rolling sub-model; LIGGGHTS' rolling_friction): cdt,
# and the elastic-plastic spring-dashpot models epsd and epsd2 with their torque history.

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


cdef inline void cdt_rolling(const Coef* c, double fe, double Rs, const double* n, const double* wrel,
                             double* Mr) noexcept nogil:
    """Rolling torque on i of LIGGGHTS' ``rolling_friction cdt`` (rolling_model_cdt.h):
    ``-mu_r R* fe`` along the relative rotation rate ``wrel``, without the torque's torsion
    part (along ``n``). ``fe = k_n delta`` is the normal force's elastic part: unlike epsd's
    limit, cdt leaves out the damping and cohesion."""
    cdef double s, wm = sqrt(dot3(wrel, wrel))
    cdef int k
    if wm > 0.0:
        s = -c.mur * Rs * fe / wm
        for k in range(3):
            Mr[k] = s * wrel[k]
        s = dot3(Mr, n)
        for k in range(3):
            Mr[k] -= s * n[k]

