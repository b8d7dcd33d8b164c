# The contact table (see Contacts): a slot per pair in contact, taken by the pass in which the
# contact begins (spilled when the table is full) and freed after the pass in which it ends.

cdef extern from *:
    """
    /* the next slot number; relaxed: the numbers need only be distinct, the team's phases order the rest */
    static inline long long pg_take_slot(long long* counter) { return __atomic_fetch_add(counter, 1, __ATOMIC_RELAXED); }
    /* ask for a cache line that is soon read and written (a contact's history: the slots of the
       pairs a pass visits one after the other lie anywhere in the table) */
    static inline void pg_prefetch(const void* p) { __builtin_prefetch(p, 1, 1); }
    """
    long long pg_take_slot(long long* counter) noexcept nogil
    void pg_prefetch(const void* p) noexcept nogil


#: the history of a pair not in contact (zeros)
cdef double NO_HISTORY[MAXHS]


cdef inline double* slot_history(const State* c, long long slot) noexcept nogil:
    """The history of the contact in ``slot`` (hs values)."""
    return &c.contacts.h[slot * c.hs]


cdef inline const double* pair_history(const State* c, long long k, const double* none) noexcept nogil:
    """Listed pair k's history, ``none`` (zeros) if it is not in contact."""
    cdef int slot = c.lists.nb_c[k]
    return slot_history(c, slot) if slot >= 0 else none


cdef inline void forget_pair(const State* c, int b, long long k) noexcept nogil:
    """Listed pair k (in pair block b) is apart: no longer touching, its slot freed after the
    pass (or, if the block's list of them cannot grow, at the next rebuild)."""
    cdef int slot = c.lists.nb_c[k]
    cdef Spill* s = &c.contacts.spill[b]
    cdef void* p
    c.lists.nb_c[k] = -1
    c.lists.nb_s[k] &= ~TOUCH
    if slot < 0:
        return
    if s.nended == s.ended_cap:
        p = grow(s.ended, max(2 * s.ended_cap, 256) * sizeof(int))
        if p == NULL:
            return
        s.ended = <int*>p
        s.ended_cap = max(2 * s.ended_cap, 256)
    s.ended[s.nended] = slot
    s.nended += 1


cdef int grow_spill(Spill* s, int hs) noexcept nogil:
    """Double a spill's capacity (at least 256 contacts); -1 when out of memory."""
    cdef long long cap = max(2 * s.cap, 256)
    cdef void* p = grow(s.k, cap * sizeof(int))
    if p == NULL:
        return -1
    s.k = <int*>p
    p = grow(s.slot, cap * sizeof(long long))
    if p == NULL:
        return -1
    s.slot = <long long*>p
    p = grow(s.h, cap * hs * sizeof(double))
    if p == NULL:
        return -1
    s.h = <double*>p
    p = grow(s.f, cap * 3 * sizeof(double))
    if p == NULL:
        return -1
    s.f = <double*>p
    s.cap = cap
    return 0


cdef int new_contact(const State* c, int b, long long k, const double* h) noexcept nogil:
    """Listed pair k came into contact in this pass (in pair block b): it gets a slot, holding
    its history ``h``. Returns the slot, or -2 - e when the table is full: the contact is entry e
    of the block's spill (it gets its slot after the pass, see settle_slots), or -1 when the spill
    is out of memory (then the run fails after the pass)."""
    cdef long long t = pg_take_slot(c.contacts.take), slot
    cdef Spill* s = &c.contacts.spill[b]
    slot = c.contacts.free[c.contacts.nfree - 1 - t] if t < c.contacts.nfree else c.contacts.n + (t - c.contacts.nfree)
    if slot < c.contacts.cap:
        memcpy(slot_history(c, slot), h, c.hs * sizeof(double))
        c.lists.nb_c[k] = <int>slot
        return <int>slot
    if s.n == s.cap and grow_spill(s, c.hs) < 0:
        s.failed = 1
        return -1
    s.k[s.n] = <int>k
    s.slot[s.n] = slot
    memcpy(&s.h[s.n * c.hs], h, c.hs * sizeof(double))
    c.lists.nb_c[k] = <int>(-2 - s.n)
    s.n += 1
    return c.lists.nb_c[k]


cdef inline double* record_of(const State* c, int b, int slot) noexcept nogil:
    """Where a recording pass puts the force of the contact in ``slot`` (new_contact's result
    in pair block b); NULL when forces are not recorded or the contact has no slot."""
    if not c.record or slot == -1:
        return NULL
    if slot >= 0:
        return &c.contacts.f[3 * <long long>slot]
    return &c.contacts.spill[b].f[3 * <long long>(-2 - slot)]


cdef int reserve_contacts(State* sim, long long need) noexcept nogil:
    """Grow the contact table to ``need`` slots at least (a sixteenth more); -1 when out of memory."""
    cdef long long cap = need + need // 16 + 64
    cdef void* p
    if need <= sim.contacts.cap:
        return 0
    p = grow(sim.contacts.h, cap * sim.hs * sizeof(double))
    if p == NULL:
        return -1
    sim.contacts.h = <double*>p
    if sim.contacts.recording:
        p = grow(sim.contacts.f, cap * 3 * sizeof(double))
        if p == NULL:
            return -1
        sim.contacts.f = <double*>p
    p = grow(sim.contacts.free, cap * sizeof(int))
    if p == NULL:
        return -1
    sim.contacts.free = <int*>p
    sim.contacts.cap = cap
    return 0


cdef int settle_slots(State* sim) noexcept nogil:
    """After a pass: the slots it took counted, the table grown if it ran out and the spilled
    contacts moved into their slots, and the slots of the contacts that ended freed; -1 when
    out of memory."""
    cdef long long taken = sim.contacts.take[0], e, slot
    cdef int b
    cdef Spill* s
    sim.contacts.take[0] = 0
    if taken <= sim.contacts.nfree:
        sim.contacts.nfree -= taken
    else:
        sim.contacts.n += taken - sim.contacts.nfree
        sim.contacts.nfree = 0
    if sim.contacts.n > sim.contacts.cap and reserve_contacts(sim, sim.contacts.n) < 0:
        return -1
    for b in range(sim.schedule.nblocks):
        s = &sim.contacts.spill[b]
        if s.failed:
            return -1
        for e in range(s.n):
            slot = s.slot[e]
            memcpy(slot_history(sim, slot), &s.h[e * sim.hs], sim.hs * sizeof(double))
            if sim.contacts.recording:
                memcpy(&sim.contacts.f[3 * slot], &s.f[3 * e], 3 * sizeof(double))
            sim.lists.nb_c[s.k[e]] = <int>slot
        s.n = 0
        for e in range(s.nended):
            sim.contacts.free[sim.contacts.nfree] = s.ended[e]
            sim.contacts.nfree += 1
        s.nended = 0
        if s.cap > SPILL_KEPT:   # a pass that began many contacts at once (the first): not kept for the next
            free_spill(s)
        if s.ended_cap > SPILL_KEPT:
            release(s.ended)
            s.ended = NULL
            s.ended_cap = 0
    return 0


cdef void free_spill(Spill* s) noexcept nogil:
    """Release a spill's new contacts' buffers."""
    release(s.k)
    release(s.slot)
    release(s.h)
    release(s.f)
    s.k = NULL
    s.slot = NULL
    s.h = NULL
    s.f = NULL
    s.cap = 0


cdef inline void swap_slot(State* sim, long long slot, double* carry) noexcept nogil:
    """Exchange the contents of ``slot`` (history, and force when recording) with ``carry``."""
    cdef double tmp
    cdef int q
    cdef double* h = slot_history(sim, slot)
    for q in range(sim.hs):
        tmp = h[q]
        h[q] = carry[q]
        carry[q] = tmp
    if sim.contacts.recording:
        for q in range(3):
            tmp = sim.contacts.f[3 * slot + q]
            sim.contacts.f[3 * slot + q] = carry[MAXHS + q]
            carry[MAXHS + q] = tmp


cdef int compact_slots(State* sim, long long npair) noexcept nogil:
    """The kept contacts of the new list (``npair`` entries) renumbered in list order and moved
    there; no free slot remains. The moves follow each chain of the renumbering once: first
    those starting at a kept slot beyond the new count, then the cycles. ``free`` holds the new
    number of each old slot meanwhile (-1: not kept). -1 when out of memory."""
    cdef long long k, slot, dest, m = 0, old = sim.contacts.n
    cdef double carry[MAXHS + 3]
    memset(carry, 0, sizeof(carry))
    for slot in range(old):
        sim.contacts.free[slot] = -1
    for k in range(npair):
        if sim.lists.nb_c[k] >= 0:
            sim.contacts.free[sim.lists.nb_c[k]] = <int>m
            sim.lists.nb_c[k] = <int>m
            m += 1
    for slot in range(m, old):   # chains from a slot no contact moves into, ending at a dropped one
        if sim.contacts.free[slot] < 0:
            continue
        swap_slot(sim, slot, carry)
        dest = sim.contacts.free[slot]
        sim.contacts.free[slot] = -1
        while True:
            swap_slot(sim, dest, carry)
            k = sim.contacts.free[dest]
            sim.contacts.free[dest] = -1
            if k < 0:
                break
            dest = k
    for slot in range(m):   # what is left are cycles (and contacts already in place)
        dest = sim.contacts.free[slot]
        if dest < 0 or dest == slot:
            continue
        swap_slot(sim, slot, carry)
        sim.contacts.free[slot] = -1
        while dest != slot:
            swap_slot(sim, dest, carry)
            k = sim.contacts.free[dest]
            sim.contacts.free[dest] = -1
            dest = k
        swap_slot(sim, slot, carry)
    sim.contacts.n = m
    sim.contacts.nfree = 0
    sim.contacts.take[0] = 0
    if sim.contacts.cap - m < m // 16 + 64:
        return reserve_contacts(sim, m + m // 16 + 64)
    return 0


cdef int free_dropped_slots(State* sim) noexcept nogil:
    """The free list made anew from the slots the new list does not keep (``free`` marks the
    kept ones with 1, the others 0: see the fill in rebuild_rows), the unused tail of the table
    given back; the table keeps room for a sixteenth more contacts. -1 when out of memory."""
    cdef long long slot, n = sim.contacts.n, nfree = 0
    while n > 0 and sim.contacts.free[n - 1] == 0:
        n -= 1
    for slot in range(n):   # in place: the entry written is never after the one read
        if sim.contacts.free[slot] == 0:
            sim.contacts.free[nfree] = <int>slot
            nfree += 1
    sim.contacts.n = n
    sim.contacts.nfree = nfree
    sim.contacts.take[0] = 0
    if nfree + sim.contacts.cap - n < (n - nfree) // 16 + 64:
        return reserve_contacts(sim, n + (n - nfree) // 16 + 64)
    return 0


cdef int renew_slots(State* sim, long long npair) noexcept nogil:
    """At a rebuild, once the new list (``npair`` entries) names the slots it keeps. Slots freed
    and retaken over a run scatter the contacts of neighbouring rows over the whole table, and a
    pass then reads it at random: when the kept contacts run in list order for fewer than
    ORDERED_RUN slots on average (counted by the fill, per block), they are renumbered in list
    order (compact_slots, serial); otherwise the numbering stays and only the free list is made
    anew (free_dropped_slots: a settle rebuilds every few steps). -1 when out of memory."""
    cdef long long kept = 0, breaks = 0
    cdef int b
    for b in range(sim.schedule.nblocks):
        kept += sim.lists.found[b].kept
        breaks += sim.lists.found[b].breaks
    if breaks * ORDERED_RUN > kept:
        return compact_slots(sim, npair)
    return free_dropped_slots(sim)


cdef void clear_contacts(State* sim) noexcept nogil:
    """Forget every contact's slot (the lists are emptied alongside: see Core.set_model)."""
    sim.contacts.n = sim.contacts.nfree = 0
    sim.contacts.take[0] = 0
