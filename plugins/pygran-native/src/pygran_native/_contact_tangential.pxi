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
    the history set to match (LIGGGHTS ``tangential_model_history.h``; the law is pair_law.h's,
    which the batched loop shares). ``n``, ``vr``, ``rw``: see contact_force."""
    pg_tangential(c.mu, kt, gt, fn, vn, n, vr, rw, &hist[H_SHEAR], dt, update, Ft)
