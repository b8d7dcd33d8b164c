# Integration: the particle loop (summing the pair loop's forces, gravity, viscous forces,
# velocity Verlet kicks) and the drift.

cdef inline const double* origins(const State* c) noexcept nogil:
    """x0 for a drift that measures displacements, else NULL (see State.measure)."""
    return c.particles.x0 if c.measure else NULL


cdef inline void clear_forces(const State* c, int i) noexcept nogil:
    """Particle i's f and t set to +0.0, for the pair loop to add into."""
    memset(&c.particles.f[3 * i], 0, 3 * sizeof(double))
    memset(&c.particles.t[3 * i], 0, 3 * sizeof(double))


cdef inline void drift_row(const State* c, int i, int tid) noexcept nogil:
    """First half kick of particle i by the force and torque of the last step (in f and t, which
    are cleared then for the pair loop) and drift; its squared speed and, if measured,
    displacement since the rebuild raise thread ``tid``'s maxima (per-thread maxima are a cache
    line apart)."""
    cdef double s, u
    cdef double* F = &c.particles.f[3 * i]
    cdef double* T = &c.particles.t[3 * i]
    pg_row_kick_factors(i, c.dt, c.particles.m, c.particles.r, &s, &u)
    pg_row_drift(i, c.dt, s, u, &c.tmax[PAD * tid], c.particles.x, c.particles.v, c.particles.w, origins(c), F, T)
    clear_forces(c, i)


cdef inline void add_halos(const State* c, int i, int first, int end, double* F, double* T) noexcept nogil:
    """Add row i's halo entries to its force F and torque T, and clear them: the near halos of
    the pair blocks ``first`` to ``end - 1`` that wrote it, then the far halos holding it, each
    in block order."""
    cdef int k, q
    cdef double* b
    for k in range(first, end):
        if i > c.schedule.tstat[PAD * k + 1]:
            continue
        b = &c.lists.halo[(c.lists.halos[k].near_off + i - c.schedule.pb[k + 1]) * 6]
        for q in range(3):
            F[q] += b[q]
            T[q] += b[3 + q]
        memset(b, 0, 6 * sizeof(double))
    for k in range(c.lists.nfarblocks):
        if not c.lists.halos[k].far_lo <= i <= c.lists.halos[k].far_hi:
            continue
        b = &c.lists.halo[(c.lists.halos[k].far_off + i - c.lists.halos[k].far_lo) * 6]
        for q in range(3):
            F[q] += b[q]
            T[q] += b[3 + q]
        memset(b, 0, 6 * sizeof(double))


cdef void particle_row(const State* c, int i, int tid, int first, int end) noexcept nogil:
    """Sum the pair loop's forces (the row's own, in f and t, which are cleared, then its
    halos': see add_halos), add gravity and viscous forces; second half kick, and with ``fuse``
    the first half kick and drift of the next step (one pass instead of two, the same
    arithmetic). Without ``fuse`` (a run's last step) f and t keep the forces, for the output and
    the next run's first drift. A clump's sphere only stores the pair loop's sums in f and t,
    for its body (see body_row), which gravity and drag act on. A fused pass always kicks (see
    run_steps)."""
    cdef bint member = c.clumps.nbody and c.particles.mem[i] >= 0
    cdef double F[3]
    cdef double T[3]
    cdef double s, u
    cdef int q
    if member:
        for q in range(3):
            F[q] = 0.0 + c.particles.f[3 * i + q]
            T[q] = 0.0 + c.particles.t[3 * i + q]
    else:
        pg_row_forces(i, c.grav[0], c.grav[1], c.grav[2], c.particles.m, c.particles.type, c.visc, c.particles.f,
                      c.particles.t, c.particles.v, F, T)
    add_halos(c, i, first, end, F, T)
    if not c.fuse or member:
        for q in range(3):
            c.particles.f[3 * i + q] = F[q]
            c.particles.t[3 * i + q] = T[q]
    if member:
        return
    if c.fuse:
        pg_row_kick_drift(i, c.dt, &c.tmax[PAD * tid], c.particles.m, c.particles.r, c.particles.x, c.particles.v, c.particles.w, origins(c), F, T)
    elif c.kick:
        pg_row_kick_factors(i, c.dt, c.particles.m, c.particles.r, &s, &u)
        pg_row_kick(i, s, u, c.particles.v, c.particles.w, F, T)


cdef inline void kick_drift_rows(const State* c, int lo, int hi, int tid, double* halo) noexcept nogil:
    """Rows [lo, hi) of the particle loop through kick_drift.h (see particle_block): ``halo``
    NULL, or the entry for row lo of the one halo that holds them."""
    pg_kick_drift(lo, hi, c.dt, &c.tmax[PAD * tid], c.grav, c.particles.m, c.particles.r, c.particles.type, c.visc,
                  c.particles.f, c.particles.t, c.particles.x, c.particles.v, c.particles.w, origins(c), halo)


cdef inline int halo_run(const State* c, int i, int hi, int first, int end, int nearmax,
                         double** halo) noexcept nogil:
    """The end of the run of rows from i (before hi) that no halo holds (``halo`` set to NULL)
    or that one halo alone holds, the near halo of block ``end - 1`` or a block's far halo
    (``halo`` set to its entry for row i); i if two halos hold row i, or a near halo of another
    block. ``nearmax``: the last row that the near halos of blocks 0 to ``end - 1`` (those
    ending at or before i) hold; block ``end``'s near halo starts where that block ends, so a
    run stops there."""
    cdef int k, far = -1, stop = hi
    halo[0] = NULL
    if i <= nearmax:   # a near halo holds row i: it must be block end - 1's, and only it
        if i > c.schedule.tstat[PAD * (end - 1) + 1]:
            return i
        for k in range(first, end - 1):
            if i <= c.schedule.tstat[PAD * k + 1]:
                return i
        stop = min(hi, <int>c.schedule.tstat[PAD * (end - 1) + 1] + 1)
        halo[0] = &c.lists.halo[(c.lists.halos[end - 1].near_off + i - c.schedule.pb[end]) * 6]
    elif end < c.schedule.nblocks - 1 and c.schedule.pb[end + 1] < stop:
        stop = c.schedule.pb[end + 1]
    for k in range(c.lists.nfarblocks):
        if c.lists.halos[k].far_lo <= i <= c.lists.halos[k].far_hi:
            if halo[0] != NULL or far >= 0:
                return i
            far = k
        elif i < c.lists.halos[k].far_lo < stop:
            stop = c.lists.halos[k].far_lo
    if far >= 0:
        halo[0] = &c.lists.halo[(c.lists.halos[far].far_off + i - c.lists.halos[far].far_lo) * 6]
        stop = min(stop, c.lists.halos[far].far_hi + 1)
    return stop


cdef void particle_block(const State* c, int lo, int hi, int tid) noexcept nogil:
    """Rows [lo, hi) of the particle loop, inside one pair block (a run that halo_run finds
    in a near halo stops only at hi or at the halo's end). The pair blocks whose near halo
    can hold row i are among ``first`` to ``end - 1``: those ending at or before i whose rows
    have a near partner at or after i (``last``); both bounds move forward with i. Without
    clumps, at a step that kicks and fuses the next drift, runs of rows that no halo holds,
    and runs that one halo alone holds (see halo_run), go through kick_drift.h in one call."""
    cdef int i = lo, stop, first = 0, end = 0, nearmax = -1
    cdef bint plain = not c.clumps.nbody and c.kick and c.fuse
    cdef double* halo = NULL
    while i < hi:
        while end < c.schedule.nblocks - 1 and c.schedule.pb[end + 1] <= i:
            nearmax = max(nearmax, <int>c.schedule.tstat[PAD * end + 1])
            end += 1
        while first < end and (c.schedule.pb[first + 1] == 0 or c.lists.last[c.schedule.pb[first + 1] - 1] < i):
            first += 1
        stop = halo_run(c, i, hi, first, end, nearmax, &halo) if plain else i
        if stop > i:
            kick_drift_rows(c, i, stop, tid, halo)
            i = stop
            continue
        particle_row(c, i, tid, first, end)
        i += 1


cdef void drift_block(const State* c, int lo, int hi, int t) noexcept nogil:
    """Rows [lo, hi) of the drift; clumps' spheres move with their bodies (see body_row)."""
    cdef int i
    for i in range(lo, hi):
        if c.clumps.nbody and c.particles.mem[i] >= 0:
            clear_forces(c, i)
        else:
            drift_row(c, i, t)


cdef void displacement_block(const State* c, int lo, int hi, int tid) noexcept nogil:
    """Rows [lo, hi) of a pass measuring the displacements (see displacement)."""
    cdef int i
    for i in range(lo, hi):
        pg_row_displacement(i, &c.tmax[PAD * tid], c.particles.x, c.particles.x0)


cdef inline bint surely_within(const State* sim, double travel, double dw) noexcept nogil:
    """Whether no particle can have moved more than ``0.5 skin - dw`` since the last rebuild
    if none moved further than ``travel`` in its drifts: with a margin for the round-off of
    summing travel and of the positions' updates (at most 4 ulp of the largest coordinate per
    step, particles being in the box or within a skin of it)."""
    cdef double xmag = 0.0
    cdef int d
    for d in range(3):
        xmag = max(xmag, fabs(sim.lo[d]), fabs(sim.hi[d]))
    xmag += sim.skin + travel
    return travel * (1.0 + 1e-6) + (sim.since + 1) * 4.0 * DBL_EPSILON * xmag + dw <= 0.5 * sim.skin


cdef double displacement(State* sim, double dw) noexcept nogil:
    """The largest displacement since the last rebuild, after a drift, or a value that like it
    leaves ``displacement + dw`` at most half the skin. A drift that did not measure it
    (``measure`` off) leaves travel to prove that, or a pass over the particles to measure."""
    cdef double t0
    if sim.measure:
        sim.measured += 1
        return max_displacement(sim)
    if surely_within(sim, sim.travel, dw):
        return 0.0
    sim.passes += 1
    t0 = pg_now()
    parallel_rows(sim, P_DISPLACEMENT, sim.particles.n)
    lap(sim, T_DRIFT, t0)
    return max_displacement(sim)


cdef inline void plan_measure(State* sim, double dt, double dw) noexcept nogil:
    """Whether the next drift measures displacements: with clumps always (their spheres move
    with their bodies), else unless travel, even with twice the last drift's speed added, and
    the walls' move ``dw`` prove no rebuild due (when speeds or walls outgrow that, displacement
    measures in a pass of its own)."""
    sim.measure = sim.clumps.nbody > 0 or not surely_within(sim, sim.travel + 2.0 * dt * sim.vlast, dw)


cdef double max_displacement(State* sim) noexcept nogil:
    """The largest displacement since the last rebuild."""
    cdef int i
    cdef double dmax = 0.0
    for i in range(sim.schedule.nthreads):
        if sim.tmax[PAD * i] > dmax:
            dmax = sim.tmax[PAD * i]
    return sqrt(dmax)


cdef double max_speed(State* sim) noexcept nogil:
    """The largest speed of the last drift (a non-finite one forces a rebuild: see pg_row_drift)."""
    cdef int i
    cdef double vmax = 0.0
    for i in range(sim.schedule.nthreads):
        if sim.tmax[PAD * i + 1] > vmax:
            vmax = sim.tmax[PAD * i + 1]
    return sqrt(vmax)


cdef inline void reset_peaks(State* sim) noexcept nogil:
    """Clear each thread's largest squared displacement and speed (see pg_row_drift)."""
    cdef int t
    for t in range(sim.schedule.nthreads):
        sim.tmax[PAD * t] = 0.0
        sim.tmax[PAD * t + 1] = 0.0


cdef void drift(State* sim, double dt) noexcept nogil:
    """First half kick and drift."""
    cdef double t0 = pg_now()
    sim.dt = dt
    reset_peaks(sim)
    parallel_rows(sim, P_DRIFT, sim.particles.n)
    if sim.clumps.nbody:
        body_loop(sim, P_BODY_DRIFT)
    lap(sim, T_DRIFT, t0)


cdef int forces(State* sim, double dt, bint update, bint kick, bint fuse) noexcept nogil:
    """Forces (pair loop, then per particle, then per clump), second half kick; ``fuse``: see
    particle_row.
    -1 when out of memory.

    The pair loop's blocks (see pair_row) fix the order of the sums and depend only on the
    state: results are deterministic for a given thread count, whichever thread runs a
    block. The particle loop takes the same blocks of rows, each in SPLIT parts, in the same
    pass (see force_phase), so a thread that ran a block of the pair loop usually sums and
    integrates the same rows.
    """
    cdef int t, T = sim.schedule.nthreads
    cdef double t0 = pg_now(), now, span = 0.0
    if place_halos(sim) < 0:
        return -1
    sim.dt = dt
    sim.update = update
    sim.kick = kick
    sim.fuse = fuse
    sim.record = not fuse and sim.contacts.recording   # an unfused pass is the last of its run (see run_steps)
    if sim.clumps.nbody:   # clumps' spheres move with their bodies, which sub_travel does not follow
        sim.lists.sub_build = 1
    reset_peaks(sim)
    for t in range(T):
        sim.schedule.cpu[PAD * t + 2] = 0.0
        sim.schedule.cpu[PAD * t + 3] = 0.0
    force_phase(sim)
    if settle_slots(sim) < 0:
        return -1
    now = pg_now()
    if sim.schedule.turn == 0.0:
        sim.schedule.turn = now
    sim.schedule.timers[T_PAIRS] += sim.schedule.turn - t0
    sim.schedule.timers[T_PARTICLES] += now - sim.schedule.turn
    t0 = now
    if sim.lists.sub_build:
        sim.lists.sub_build = 0
        sim.lists.sub_travel = 0.0
        sim.lists.sub_builds += 1
    sim.forces_valid = 1
    if sim.walls.nslots:
        servo_sums(sim)
        if update:
            servo_control(sim, dt)
    if sim.clumps.nbody:
        body_loop(sim, P_BODIES)
    rebalance(sim)
    lap(sim, T_PARTICLES, t0)
    for t in range(T):   # the busiest thread's CPU time: a lower bound of the loops' wall time on idle cores
        sim.schedule.cpu[PAD * t] += sim.schedule.cpu[PAD * t + 2]
        sim.schedule.cpu[PAD * t + 1] += sim.schedule.cpu[PAD * t + 3]
        span = max(span, sim.schedule.cpu[PAD * t + 2] + sim.schedule.cpu[PAD * t + 3])
    sim.schedule.timers[T_FORCES_SPAN] += span
    return 0


cdef int run_steps(State* sim, long long nsteps, double dt) noexcept nogil:
    cdef long long s
    cdef double dp, dw, moved, t0 = pg_now(), t1
    cdef bint fused = False
    if dt != sim.dt_base:
        sim.t_base = sim.time
        sim.step_base = sim.step
        sim.dt_base = dt
    if sim.walls.nslots:
        servo_start(sim, dt)
    if sim.dirty:
        if rebuild(sim) < 0:
            return -1
        if forces(sim, dt, False, False, False) < 0:
            return -1
        sim.dirty = 0
    sim.schedule.tuner.start = t0
    for s in range(nsteps):
        if PG_TEAM_HEURISTICS and sim.schedule.nthreads > 1:
            tune(sim)
        if not fused:
            plan_measure(sim, dt, sim.dw_last)
            drift(sim, dt)
        sim.vlast = max_speed(sim)
        moved = fabs(dt) * sim.vlast   # no particle moved further in this drift
        sim.lists.sub_travel += moved
        sim.travel += moved
        sim.since += 1
        sim.step += 1
        sim.time = sim.t_base + (sim.step - sim.step_base) * dt
        t1 = pg_now()
        servo_move(sim, dt)
        dw = move_walls(sim)
        sim.dw_last = dw
        lap(sim, T_WALLS, t1)
        dp = displacement(sim, dw)
        if dp + dw > 0.5 * sim.skin:
            if rebuild(sim) < 0:
                return -1
        if not sim.lists.sub_travel < 0.45 * SUB_SKIN * sim.skin:   # 0.5 less a margin for round-off
            sim.lists.sub_build = 1
        fused = s + 1 < nsteps   # the last step ends after its second half kick
        if fused:
            plan_measure(sim, dt, dw)
        if forces(sim, dt, True, True, fused) < 0:
            return -1
    sim.schedule.tuner.elapsed += lap(sim, T_RUN, t0) - sim.schedule.tuner.start
    return 0
