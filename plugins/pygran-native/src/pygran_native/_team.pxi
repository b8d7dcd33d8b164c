# The team: parallel phases handed out in blocks to the solver's threads (team.h), timers, and
# the balance of the pair loop's blocks.

cdef inline double lap(State* sim, int k, double since) noexcept nogil:
    """Add the wall-clock time since ``since`` to timer k; returns now."""
    cdef double now = pg_now()
    sim.schedule.timers[k] += now - since
    return now


cdef void parallel_rows(State* sim, int phase, int rows) noexcept nogil:
    """Run a phase over rows [0, rows) in ``nblocks`` equal blocks on the team."""
    sim.schedule.rows = rows
    run_phase(sim, phase, sim.schedule.nblocks)


cdef void run_phase(State* sim, int phase, int nblocks) noexcept nogil:
    """Master: open a phase, take blocks of it like the other threads, and return when
    all its blocks are done (whichever threads ran them); alone, run them in order."""
    cdef int b
    if sim.schedule.nthreads == 1 or sim.schedule.tuner.solo:
        for b in range(nblocks):
            run_block(sim, phase, b, nblocks, 0, 0)
        return
    take(sim, pg_begin(sim.schedule.team, phase, nblocks, 0), phase, nblocks, 0)
    pg_wait_done(sim.schedule.team)


cdef void force_phase(State* sim) noexcept nogil:
    """Master: the pair loop's blocks, then the particle loop's (SPLIT parts of each pair
    block), in one phase of two stages: a part waits only for the pair blocks that read its
    rows or put forces on them (see await_pairs), so a thread that ends its pair blocks early
    goes on with its particles, and the particle loop's small parts even out the threads.
    ``turn``: when the master began the particle loop (0 if the team left it none)."""
    cdef int b, nparts = sim.schedule.nblocks * SPLIT
    cdef double t0, t1
    if sim.schedule.nthreads == 1 or sim.schedule.tuner.solo:
        t0 = thread_cpu()
        for b in range(sim.schedule.nblocks):
            pair_block(sim, b)
        t1 = thread_cpu()
        sim.schedule.turn = pg_now()
        for b in range(nparts):
            particle_part(sim, b, 0, 0)
        sim.schedule.cpu[2] += t1 - t0
        sim.schedule.cpu[3] += thread_cpu() - t1
        return
    sim.schedule.turn = 0.0
    take(sim, pg_begin(sim.schedule.team, P_FORCES, sim.schedule.nblocks, nparts), P_FORCES, sim.schedule.nblocks + nparts, 0)
    pg_wait_done(sim.schedule.team)


cdef inline void await_pair(State* sim, int b, unsigned int epoch, int tid) noexcept nogil:
    """Thread ``tid``: wait until pair block b of phase ``epoch`` is done; the CPU time of the
    wait is not the particle loop's."""
    cdef double t0
    if not pg_posted(&sim.schedule.posted[b], epoch):
        t0 = thread_cpu()
        pg_await(&sim.schedule.posted[b], epoch)
        sim.schedule.cpu[PAD * tid + 3] -= thread_cpu() - t0


cdef void await_pairs(State* sim, int b, int lo, int hi, unsigned int epoch, int tid) noexcept nogil:
    """Thread ``tid``: wait for the pair blocks of phase ``epoch`` that read rows [lo, hi) of
    pair block b or put forces on them: b, those before it whose near halo reaches lo, and
    those whose far halo meets the rows. The others' ``tstat`` halo ends, which particle_block
    reads, are -1 or final (see place_halos), and either way below lo."""
    cdef int k
    for k in range(b):
        if sim.lists.halos[k].near_end >= lo:
            await_pair(sim, k, epoch, tid)
    await_pair(sim, b, epoch, tid)
    for k in range(sim.lists.nfarblocks):
        if sim.lists.halos[k].far_lo < hi and sim.lists.halos[k].far_hi >= lo:
            await_pair(sim, k, epoch, tid)


cdef inline void particle_part(State* sim, int p, int tid, unsigned int epoch) noexcept nogil:
    """Part p of the particle loop: part p % SPLIT of pair block p // SPLIT, run by thread
    ``tid``; in phase ``epoch`` of the team once the pair blocks it reads are done (0: alone)."""
    cdef int b = p // SPLIT, lo = part_start(sim.schedule.pb[b], sim.schedule.pb[b + 1], p % SPLIT, SPLIT)
    cdef int hi = part_start(sim.schedule.pb[b], sim.schedule.pb[b + 1], p % SPLIT + 1, SPLIT)
    if lo == hi:
        return
    if epoch:
        await_pairs(sim, b, lo, hi, epoch, tid)
    particle_block(sim, lo, hi, tid)


cdef inline int part_start(int lo, int hi, int k, int parts) noexcept nogil:
    """Where part k of rows [lo, hi) cut in ``parts`` equal parts starts (k = parts: hi)."""
    return <int>(lo + <long long>(hi - lo) * k // parts)


cdef inline void run_block(State* sim, int phase, int b, int nblocks, int tid, unsigned int epoch) noexcept nogil:
    """Block b of a phase, run by thread ``tid`` (in phase ``epoch`` of the team; 0: alone): of
    the force phase, pair block b, then part b - nblocks of the particle loop (see
    force_phase); of the other loops over rows, part b of ``nblocks``."""
    cdef int lo, hi
    if phase == P_FORCES:
        if b < sim.schedule.nblocks:
            pair_block(sim, b)
            pg_post(&sim.schedule.posted[b], epoch)
        else:
            particle_part(sim, b - sim.schedule.nblocks, tid, epoch)
    else:
        lo = part_start(0, sim.schedule.rows, b, nblocks)
        hi = part_start(0, sim.schedule.rows, b + 1, nblocks)
        if phase == P_DRIFT:
            drift_block(sim, lo, hi, tid)
        elif phase == P_DISPLACEMENT:
            displacement_block(sim, lo, hi, tid)
        else:
            rebuild_rows(sim, phase, lo, hi, b)


cdef void take(State* sim, unsigned int epoch, int phase, int nblocks, int tid) noexcept nogil:
    """Claim and run blocks of phase ``epoch`` until none is left, then report them done;
    the CPU time of the pair and particle loops goes to thread ``tid``'s counters."""
    cdef int b, k = 0, stage = 2   # the force phase's counter the CPU time goes to
    cdef double t0 = 0.0, t1
    b = pg_claim(sim.schedule.team, epoch, tid)
    if b < 0:
        return
    if phase == P_FORCES:
        t0 = thread_cpu()
    while b >= 0:
        if phase == P_FORCES and stage == 2 and b >= sim.schedule.nblocks:
            t1 = thread_cpu()
            sim.schedule.cpu[PAD * tid + 2] += t1 - t0
            t0 = t1
            stage = 3
            if tid == 0:
                sim.schedule.turn = pg_now()
        run_block(sim, phase, b, nblocks, tid, epoch)
        k += 1
        b = pg_claim(sim.schedule.team, epoch, tid)
    if phase == P_FORCES:
        sim.schedule.cpu[PAD * tid + stage] += thread_cpu() - t0
    pg_finished(sim.schedule.team, k)


cdef void team_task(void* owner, unsigned int epoch, int phase, int nblocks, int tid) noexcept nogil:
    """What the team's threads run: their part of a phase of ``owner``, a :class:`State`."""
    take(<State*>owner, epoch, phase, nblocks, tid)


cdef inline int estimated_work(State* sim, int i) noexcept nogil:
    """Row i's work in the pair loop, counting the pairs that touched at the last step."""
    cdef int k, touching = 0
    for k in range(sim.lists.nb_start[i], sim.lists.nb_start[i + 1]):
        touching += (sim.lists.nb_s[k] & TOUCH) != 0
    return row_work(sim.lists.nb_start[i + 1] - sim.lists.nb_start[i], touching,
                    sim.lists.wl_start[i + 1] - sim.lists.wl_start[i])


cdef void balance(State* sim) noexcept nogil:
    """Split the (cell-sorted) rows of the pair loop into ``nblocks`` blocks of about equal
    ``work``: each a spatial slab, so few neighbours belong to another block."""
    cdef int t, i = 0, n = sim.particles.n, T = sim.schedule.nblocks
    cdef long long total = 0, prefix = 0
    for t in range(n):
        total += sim.schedule.work[t]
    for t in range(1, T):
        while i < n and prefix < total * t // T:
            prefix += sim.schedule.work[i]
            i += 1
        sim.schedule.pb[t] = i
    sim.schedule.pb[0] = 0
    sim.schedule.pb[T] = n


cdef void rebalance(State* sim) noexcept nogil:
    """Move each bound of the pair loop to where the work of the loop just run splits
    evenly (the first row where its prefix reaches ``total t / T``), walking from where the
    bound was: the partition follows contacts as they form, and depends only on the state."""
    cdef int t, b, T = sim.schedule.nblocks
    cdef long long total = 0, old = 0, prefix, target
    for t in range(T):
        total += sim.schedule.tstat[PAD * t]
    for t in range(1, T):
        old += sim.schedule.tstat[PAD * (t - 1)]   # the work before the old bound t
        target = total * t // T
        b = sim.schedule.pb[t]
        prefix = old
        while b > 0 and prefix - sim.schedule.work[b - 1] >= target:
            b -= 1
            prefix -= sim.schedule.work[b]
        while b < sim.particles.n and prefix < target:
            prefix += sim.schedule.work[b]
            b += 1
        sim.schedule.pb[t] = b
