# Clumps: rigid bodies of overlapping spheres (multisphere species).
#
# A body holds its mass, principal moments, centre, velocity, orientation (the unit quaternion
# of its principal axes) and angular momentum in its principal frame; its spheres (members,
# one member slot each) are particles like the others in the pair loop, except that no pair
# of one body is listed (scan_pairs) and their forces go to the body: after the particle loop,
# the body loop (P_BODIES, blocks of bodies on the team) sums them in slot order, adds gravity
# and viscous drag on the body, kicks and drifts it, and puts its spheres where the body is:
# positions from its centre and orientation (so the shape never drifts), velocities
# v + w x r, spins w. The sums' order depends on the slots only: bitwise reproducible.
#
# Rotation: the symplectic splitting of Dullweber, Leimkuhler and McLachlan (J. Chem. Phys. 107
# (1997) 5840; NO_SQUISH of Miller et al., J. Chem. Phys. 116 (2002) 8649, in quaternions):
# half kicks of the angular momentum by the torque around the free rotor, itself exact
# rotations about the principal axes 1 (h/2), 2 (h/2), 3 (h), 2 (h/2), 1 (h/2). It is
# time-reversible and symplectic: a free body's angular momentum is conserved to round-off and
# its energy oscillates at O(h^2) without drift.

cdef inline void quat_matrix(const double* q, double* R) noexcept nogil:
    """Row-major rotation matrix of the unit quaternion q = (w, x, y, z)."""
    cdef double w = q[0], x = q[1], y = q[2], z = q[3]
    R[0] = 1.0 - 2.0 * (y * y + z * z)
    R[1] = 2.0 * (x * y - w * z)
    R[2] = 2.0 * (x * z + w * y)
    R[3] = 2.0 * (x * y + w * z)
    R[4] = 1.0 - 2.0 * (x * x + z * z)
    R[5] = 2.0 * (y * z - w * x)
    R[6] = 2.0 * (x * z - w * y)
    R[7] = 2.0 * (y * z + w * x)
    R[8] = 1.0 - 2.0 * (x * x + y * y)


cdef inline void mat_vec(const double* R, const double* a, double* out) noexcept nogil:
    cdef int d
    for d in range(3):
        out[d] = R[3 * d] * a[0] + R[3 * d + 1] * a[1] + R[3 * d + 2] * a[2]


cdef inline void mat_tvec(const double* R, const double* a, double* out) noexcept nogil:
    cdef int d
    for d in range(3):
        out[d] = R[d] * a[0] + R[3 + d] * a[1] + R[6 + d] * a[2]


cdef inline void rotate_principal(double* q, double* p, const double* I, int k, double h) noexcept nogil:
    """The exact flow of ``p_k^2 / 2 I_k`` for time h: the body turns by ``theta = h p_k / I_k``
    about its principal axis k (q becomes q (cos theta/2, sin theta/2 e_k)), so the other two
    components of its angular momentum, in its frame, turn by -theta."""
    cdef int a = (k + 1) % 3, b = (k + 2) % 3
    cdef double th = h * p[k] / I[k]
    cdef double c = cos(th), s = sin(th), ch = cos(0.5 * th), sh = sin(0.5 * th)
    cdef double pa = p[a], pb = p[b], w = q[0], vk = q[1 + k], va = q[1 + a], vb = q[1 + b]
    p[a] = c * pa + s * pb
    p[b] = c * pb - s * pa
    q[0] = ch * w - sh * vk
    q[1 + k] = ch * vk + sh * w
    q[1 + a] = ch * va + sh * vb
    q[1 + b] = ch * vb - sh * va


cdef inline void free_rotor(double* q, double* p, const double* I, double h) noexcept nogil:
    """A free rigid body's rotation for time h (see the splitting above); q renormalised."""
    cdef double norm
    cdef int d
    rotate_principal(q, p, I, 0, 0.5 * h)
    rotate_principal(q, p, I, 1, 0.5 * h)
    rotate_principal(q, p, I, 2, h)
    rotate_principal(q, p, I, 1, 0.5 * h)
    rotate_principal(q, p, I, 0, 0.5 * h)
    norm = 1.0 / sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    for d in range(4):
        q[d] *= norm


cdef double body_members(const State* c, int b, bint positions) noexcept nogil:
    """Put body b's spheres where the body is: positions (with ``positions``: centre + R d +
    their periodic shift), velocities and spins. Returns their largest squared displacement
    since the rebuild (0 without ``positions``, INFINITY if not finite)."""
    cdef double R[9]
    cdef double wb[3]
    cdef double om[3]
    cdef double rk[3]
    cdef double cx[3]
    cdef double dd, q, dmax = 0.0
    cdef int s, i, d
    quat_matrix(&c.clumps.bq[4 * b], R)
    for d in range(3):
        wb[d] = c.clumps.bp[3 * b + d] / c.clumps.bI[3 * b + d]
    mat_vec(R, wb, om)
    for s in range(c.clumps.mstart[b], c.clumps.mstart[b + 1]):
        i = c.clumps.mrow[s]
        mat_vec(R, &c.clumps.md[3 * s], rk)
        cross3(om, rk, cx)
        dd = 0.0
        for d in range(3):
            if positions:
                c.particles.x[3 * i + d] = c.clumps.bx[3 * b + d] + rk[d] + c.clumps.mimg[3 * s + d]
                q = c.particles.x[3 * i + d] - c.particles.x0[3 * i + d]
                dd += q * q
            c.particles.v[3 * i + d] = c.clumps.bv[3 * b + d] + cx[d]
            c.particles.w[3 * i + d] = om[d]
        if not dd <= dmax:
            dmax = dd if isfinite(dd) else INFINITY
    return dmax


cdef inline void body_kick(const State* c, int b, const double* R, const double* F, const double* T) noexcept nogil:
    """Half kick of body b by force F and torque T (world frame; R: its orientation)."""
    cdef double s = 0.5 * c.dt / c.clumps.bm[b]
    cdef double tb[3]
    cdef int d
    mat_tvec(R, T, tb)
    for d in range(3):
        c.clumps.bv[3 * b + d] += s * F[d]
        c.clumps.bp[3 * b + d] += 0.5 * c.dt * tb[d]


cdef void body_row(const State* c, int b, int phase) noexcept nogil:
    """Body b in the body loop. P_BODIES: sum its spheres' forces and torques (the pair loop's
    sums, stored by the particle loop in their f and t; with ``fuse`` then cleared for the next
    pair loop, else kept as a run's last forces) about its centre, with gravity and viscous
    drag, into bf and bt; with ``kick`` the second half kick, with ``fuse`` then the first half
    kick and drift of the next step (as particle_row does). P_BODY_DRIFT: first half kick by bf,
    bt and drift. Its spheres follow (see body_members); ``bdd[b]``: their displacement."""
    cdef double R[9]
    cdef double F[3]
    cdef double T[3]
    cdef double rk[3]
    cdef double cx[3]
    cdef double g
    cdef int s, i, d
    quat_matrix(&c.clumps.bq[4 * b], R)
    if phase == P_BODIES:
        g = c.visc[c.clumps.btype[b]]
        for d in range(3):
            F[d] = c.clumps.bm[b] * c.grav[d] - g * c.clumps.bv[3 * b + d]
            T[d] = 0.0
        for s in range(c.clumps.mstart[b], c.clumps.mstart[b + 1]):
            i = c.clumps.mrow[s]
            mat_vec(R, &c.clumps.md[3 * s], rk)
            cross3(rk, &c.particles.f[3 * i], cx)
            for d in range(3):
                F[d] += c.particles.f[3 * i + d]
                T[d] += c.particles.t[3 * i + d] + cx[d]
            if c.fuse:
                clear_forces(c, i)
        for d in range(3):
            c.clumps.bf[3 * b + d] = F[d]
            c.clumps.bt[3 * b + d] = T[d]
        if c.kick:
            body_kick(c, b, R, F, T)
        if not c.fuse:
            body_members(c, b, False)
            return
    body_kick(c, b, R, &c.clumps.bf[3 * b], &c.clumps.bt[3 * b])
    free_rotor(&c.clumps.bq[4 * b], &c.clumps.bp[3 * b], &c.clumps.bI[3 * b], c.dt)
    for d in range(3):
        c.clumps.bx[3 * b + d] += c.dt * c.clumps.bv[3 * b + d]
    c.clumps.bdd[b] = body_members(c, b, True)


cdef void body_rows(const State* c, int phase, int lo, int hi) noexcept nogil:
    """Bodies [lo, hi) of a body loop (a block of P_BODIES or P_BODY_DRIFT)."""
    cdef int b
    for b in range(lo, hi):
        body_row(c, b, phase)


cdef void body_loop(State* sim, int phase) noexcept nogil:
    """Run a body loop on the team; when it moved the bodies, their spheres' largest
    displacement raises the first thread's maximum (see drift_row)."""
    cdef int b
    cdef double dmax = sim.tmax[0]
    parallel_rows(sim, phase, sim.clumps.nbody)
    if phase == P_BODY_DRIFT or sim.fuse:
        for b in range(sim.clumps.nbody):
            if not sim.clumps.bdd[b] <= dmax:
                dmax = sim.clumps.bdd[b] if isfinite(sim.clumps.bdd[b]) else INFINITY
        sim.tmax[0] = dmax


cdef void place_bodies(State* sim) noexcept nogil:
    """At a rebuild, before the particles are wrapped: each body's centre wrapped into the
    periodic box, and its spheres put in the box too, their periodic shifts (mimg) updated."""
    cdef int b, s, i, d
    cdef double R[9]
    cdef double rk[3]
    cdef double p, shift
    for b in range(sim.clumps.nbody):
        for d in range(3):
            p = sim.clumps.bx[3 * b + d]
            if sim.per[d] and isfinite(p) and (p < sim.lo[d] or p >= sim.hi[d]):
                sim.clumps.bx[3 * b + d] = p - sim.L[d] * floor((p - sim.lo[d]) / sim.L[d])
        quat_matrix(&sim.clumps.bq[4 * b], R)
        for s in range(sim.clumps.mstart[b], sim.clumps.mstart[b + 1]):
            i = sim.clumps.mrow[s]
            mat_vec(R, &sim.clumps.md[3 * s], rk)
            for d in range(3):
                p = sim.clumps.bx[3 * b + d] + rk[d]
                shift = 0.0
                if sim.per[d] and isfinite(p):
                    shift = -sim.L[d] * floor((p - sim.lo[d]) / sim.L[d])
                    if p + shift >= sim.hi[d]:
                        shift -= sim.L[d]
                sim.clumps.mimg[3 * s + d] = shift
                sim.particles.x[3 * i + d] = p + shift


cdef int mark_dead_bodies(State* sim, long long* lost) noexcept nogil:
    """After the particles are placed: a body with a sphere lost or removed goes whole, each
    of its spheres sorted into the sentinel cell, and counts once as lost (where its first lost
    sphere is) when one was. Marks it (bdd -1) and returns how many went."""
    cdef int b, s, i, first, gone, dead = 0
    for b in range(sim.clumps.nbody):
        first = -1
        gone = 0
        for s in range(sim.clumps.mstart[b], sim.clumps.mstart[b + 1]):
            i = sim.clumps.mrow[s]
            if sim.particles.cell[i] < 0:
                gone = 1
                if sim.particles.cell[i] == -1 and first < 0:
                    first = i
        sim.clumps.bdd[b] = 0.0
        if not gone:
            continue
        sim.clumps.bdd[b] = -1.0
        dead += 1
        if first >= 0:
            lost[0] += 1
            count_lost(sim, first)
        for s in range(sim.clumps.mstart[b], sim.clumps.mstart[b + 1]):
            sim.particles.cell[sim.clumps.mrow[s]] = sim.lists.ncells
    return dead


cdef int drop_bodies(State* sim, int n) noexcept nogil:
    """Compact the bodies and member slots, leaving out the bodies marked dead, and renumber
    the slots of the ``n`` particles (all of live bodies or free); -1 when out of memory."""
    cdef Column bcols[NBCOLUMNS]
    cdef Column mcols[NMCOLUMNS]
    cdef int* slot = <int*>malloc(max(sim.clumps.nmem, 1) * sizeof(int))
    cdef int b, s, k, i, start, end, nb = 0, ns = 0
    if slot == NULL:
        return -1
    body_columns(sim, bcols)
    member_columns(sim, mcols)
    for b in range(sim.clumps.nbody):
        start = sim.clumps.mstart[b]
        end = sim.clumps.mstart[b + 1]
        if sim.clumps.bdd[b] < 0.0:
            continue
        for k in range(NBCOLUMNS - 1):   # all but mstart, set below
            memmove(<char*>bcols[k].p[0] + nb * bcols[k].size, <char*>bcols[k].p[0] + b * bcols[k].size,
                    bcols[k].size)
        sim.clumps.mstart[nb] = ns
        for s in range(start, end):
            for k in range(NMCOLUMNS):
                memmove(<char*>mcols[k].p[0] + ns * mcols[k].size, <char*>mcols[k].p[0] + s * mcols[k].size,
                        mcols[k].size)
            sim.clumps.mbody[ns] = nb
            slot[s] = ns
            ns += 1
        nb += 1
    sim.clumps.mstart[nb] = ns
    sim.clumps.nbody = nb
    sim.clumps.nmem = ns
    for i in range(n):
        if sim.particles.mem[i] >= 0:
            sim.particles.mem[i] = slot[sim.particles.mem[i]]
    free(slot)
    return 0


cdef void find_members(State* sim) noexcept nogil:
    """Each member slot's storage row (``mrow``), after the particles moved."""
    cdef int i
    for i in range(sim.particles.n):
        if sim.particles.mem[i] >= 0:
            sim.clumps.mrow[sim.particles.mem[i]] = i
