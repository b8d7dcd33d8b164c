# Integration: the particle loop (summing the pair loop's buffers, gravity, viscous
# forces, velocity Verlet kicks) and the drift.

cdef inline void drift_row(const Ctx* c, int i, int tid, const double* F, const double* T) noexcept nogil:
    """First half kick (force F, torque T) and drift of particle i; its squared displacement
    since the rebuild raises thread ``tid``'s maximum (per-thread maxima are a cache line apart)."""
    cdef int d
    cdef double s = 0.5 * c.dt / c.m[i], u = 0.5 * c.dt / (0.4 * c.m[i] * c.r[i] * c.r[i]), q, dd = 0.0
    for d in range(3):
        c.v[3 * i + d] += s * F[d]
        c.w[3 * i + d] += u * T[d]
        c.x[3 * i + d] += c.dt * c.v[3 * i + d]
        q = c.x[3 * i + d] - c.x0[3 * i + d]
        dd += q * q
    if not dd <= c.tmax[PAD * tid]:   # a non-finite particle forces a rebuild, which drops it
        c.tmax[PAD * tid] = dd if isfinite(dd) else INFINITY


cdef void particle_row(const Ctx* c, int i, int tid, int first, int end) noexcept nogil:
    """Sum the buffers (the shared one, then the near halos of the pair blocks ``first`` to
    ``end - 1`` that wrote row i, then the far halos holding it, each in block order) and
    clear them, add gravity and viscous forces; second half kick, and with ``fuse`` the first
    half kick and drift of the next step (one pass instead of two, the same arithmetic; ``f``
    and ``t`` are then left alone: they hold the forces of a run's last step, which is not
    fused)."""
    cdef double mi = c.m[i], g = c.visc[c.type[i]], s
    cdef double F[3]
    cdef double T[3]
    cdef double* b
    cdef int k, q
    b = &c.buf[<long long>i * 6]
    for q in range(3):
        F[q] = mi * c.grav[q] - g * c.v[3 * i + q]
        T[q] = 0.0
        F[q] += b[q]
        T[q] += b[3 + q]
    memset(b, 0, 6 * sizeof(double))
    for k in range(first, end):
        if i > c.tstat[PAD * k + 1]:
            continue
        b = &c.halo[(c.halos[k].near_off + i - c.pb[k + 1]) * 6]
        for q in range(3):
            F[q] += b[q]
            T[q] += b[3 + q]
        memset(b, 0, 6 * sizeof(double))
    for k in range(c.nfarblocks):
        if not c.halos[k].far_lo <= i <= c.halos[k].far_hi:
            continue
        b = &c.halo[(c.halos[k].far_off + i - c.halos[k].far_lo) * 6]
        for q in range(3):
            F[q] += b[q]
            T[q] += b[3 + q]
        memset(b, 0, 6 * sizeof(double))
    if not c.fuse:
        for q in range(3):
            c.f[3 * i + q] = F[q]
            c.t[3 * i + q] = T[q]
    if c.kick:
        s = 0.5 * c.dt / mi
        for q in range(3):
            c.v[3 * i + q] += s * F[q]
        s = 0.5 * c.dt / (0.4 * mi * c.r[i] * c.r[i])
        for q in range(3):
            c.w[3 * i + q] += s * T[q]
    if c.fuse:
        drift_row(c, i, tid, F, T)


cdef void particle_block(const Ctx* c, int lo, int hi, int tid) noexcept nogil:
    """Rows [lo, hi) of the particle loop. The pair blocks whose near halo can hold row i
    are among ``first`` to ``end - 1``: those ending at or before i whose rows have a near
    partner at or after i (``last``); both bounds move forward with i."""
    cdef int i, first = 0, end = 0
    for i in range(lo, hi):
        while end < c.nblocks - 1 and c.pb[end + 1] <= i:
            end += 1
        while first < end and (c.pb[first + 1] == 0 or c.last[c.pb[first + 1] - 1] < i):
            first += 1
        particle_row(c, i, tid, first, end)


cdef void drift_block(const Ctx* c, int lo, int hi, int t) noexcept nogil:
    cdef int i
    for i in range(lo, hi):
        drift_row(c, i, t, &c.f[3 * i], &c.t[3 * i])
