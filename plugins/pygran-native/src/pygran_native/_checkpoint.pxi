# Checkpoints: a Core's State as numpy arrays and back (Core.get_state, Core.set_state),
# and the copies between C arrays and numpy.

cdef object copy_column(const Column* c, long long rows):
    """A column's first ``rows`` entries (and its extra ones) as a numpy array."""
    cdef long long k = rows * c.count + c.extra
    if c.kind == I32:
        return _copy_i(<int*>c.p[0], k)
    if c.kind == I64:
        return _copy_l(<int64_t*>c.p[0], k)
    return _copy_d(<double*>c.p[0], k)


cdef void put_column(const Column* c, a, long long rows) except *:
    """Fill a column's first ``rows`` entries (and its extra ones) from ``a``."""
    cdef long long k = rows * c.count + c.extra
    a = np.ascontiguousarray(a, dtype=np.int32 if c.kind == I32 else np.int64 if c.kind == I64 else float)
    a = a.reshape(-1)
    if a.shape[0] != k:
        raise ValueError(f"{c.key.decode()}: expected {k} values, got {a.shape[0]}")
    if k:
        memcpy(c.p[0], cnp.PyArray_DATA(a), k * a.itemsize)


cdef void save_table(dict state, Column* cols, int ncols, long long rows):
    cdef int k
    for k in range(ncols):
        if cols[k].key != NULL:
            state[cols[k].key.decode()] = copy_column(&cols[k], rows)


cdef void load_table(state, Column* cols, int ncols, long long rows) except *:
    cdef int k
    for k in range(ncols):
        if cols[k].key != NULL:
            put_column(&cols[k], state[cols[k].key.decode()], rows)


cdef dict state_of(Core core):
    """Everything the time-step loop depends on, as numpy arrays (storage order): the saved
    columns of the allocation tables (see particle_columns), the lists and the scalars."""
    cdef int n = core.s.particles.n
    cdef long long npair = core.s.lists.nb_start[n], nwall = core.s.lists.wl_start[n]
    cdef Column cols[NCOLUMNS]
    state = {
        "nb_j": _copy_i(core.s.lists.nb_j, npair), "nb_s": _copy_b(core.s.lists.nb_s, npair),
        "nb_h": pair_histories(&core.s, npair), "wl_e": _copy_i(core.s.lists.wl_e, nwall),
        "wl_h": _copy_d(core.s.lists.wl_h, nwall * (core.s.hs + 1)), "visc": _copy_d(core.s.visc, core.s.ntypes),
        "slots": _copy_d(core.s.walls.slots, NSLOT * core.s.walls.nslots),
        "vib": _copy_d(core.s.walls.vib, NVIB * core.s.walls.nvib),
        "scalars": np.array([core.s.time, core.s.t_base, core.s.dt_base, core.s.lost_speed], dtype=float),
        "lost": np.array([core.s.lost_at[k] for k in range(7)], dtype=np.int64),
        "counters": np.array([core.s.step, core.s.lost, core.s.rebuilds, core.s.dirty, core.s.step_base],
                             dtype=np.int64),
        "bounds": _copy_i(core.s.schedule.pb, core.s.schedule.nblocks + 1),
    }
    particle_columns(&core.s, cols)
    save_table(state, cols, NCOLUMNS, n)
    element_columns(&core.s, cols)
    save_table(state, cols, NECOLUMNS, core.s.walls.ne)
    if core.s.clumps.nbody == 0:   # a state of spheres only is what it was before there were clumps
        return state
    state["mem"] = _copy_i(core.s.particles.mem, n)
    body_columns(&core.s, cols)
    save_table(state, cols, NBCOLUMNS, core.s.clumps.nbody)
    member_columns(&core.s, cols)
    save_table(state, cols, NMCOLUMNS, core.s.clumps.nmem)
    return state


cdef void restore(Core core, state) except *:
    """Restore :meth:`get_state` output (the contact model must be set already). The entries
    must be consistent (see ``solver._checked_state``); every copy checks its length."""
    cdef int n = state["r"].shape[0], ne = state["ekind"].shape[0], i
    cdef long long npair = state["nb_j"].shape[0], nwall = state["wl_e"].shape[0]
    cdef Column cols[NCOLUMNS]
    core.reserve(n)
    if reserve_pairs(&core.s, npair) < 0 or reserve_sublist(&core.s, npair) < 0 or reserve_walls(&core.s, nwall) < 0:
        raise MemoryError()
    core.s.particles.n = 0
    core.s.walls.ne = 0
    core.s.forces_valid = 0
    core.add_elements(np.ascontiguousarray(state["ekind"], dtype=np.int32),   # grows the element columns
                      np.ascontiguousarray(state["etype"], dtype=np.int32),
                      np.ascontiguousarray(state["ewall"], dtype=np.int32),
                      np.ascontiguousarray(state["egeo"], dtype=float).reshape(ne, 9),
                      np.ascontiguousarray(state["evid"], dtype=np.int32).reshape(ne, 3))
    element_columns(&core.s, cols)
    load_table(state, cols, NECOLUMNS, ne)
    core.set_slots(np.ascontiguousarray(state["slots"], dtype=float).reshape(-1, NSLOT))
    core.set_vibrations(np.ascontiguousarray(state["vib"], dtype=float).reshape(-1, NVIB))
    particle_columns(&core.s, cols)
    load_table(state, cols, NCOLUMNS, n)
    _put_d(core.s.lists.wl_h, state["wl_h"], nwall * (core.s.hs + 1))
    _put_i(core.s.lists.nb_j, state["nb_j"], npair)
    _put_i(core.s.lists.wl_e, state["wl_e"], nwall)
    nbs = np.ascontiguousarray(state["nb_s"], dtype=np.uint8)
    if nbs.shape[0] != npair:
        raise ValueError("nb_s: one per listed pair")
    if npair:
        memcpy(core.s.lists.nb_s, cnp.PyArray_DATA(nbs), npair)
    put_pair_histories(&core.s, state["nb_h"], npair)
    core.set_viscous(np.ascontiguousarray(state["visc"], dtype=float))
    core.s.particles.n = n
    restore_bodies(core, state)
    core.s.time, core.s.t_base, core.s.dt_base, core.s.lost_speed = (float(k) for k in state["scalars"])
    for i in range(7):
        core.s.lost_at[i] = state["lost"][i]
    core.s.step, core.s.lost, core.s.rebuilds, core.s.dirty, core.s.step_base = (
        int(k) for k in state["counters"])
    if state["bounds"].shape[0] == core.s.schedule.nblocks + 1:
        _put_i(core.s.schedule.pb, state["bounds"], core.s.schedule.nblocks + 1)
    else:   # another thread count: sums in another order anyway
        for i in range(n):
            core.s.schedule.work[i] = estimated_work(&core.s, i)
        balance(&core.s)
    for i in range(n):
        find_partners(&core.s, i)
    prefix_last(&core.s)
    core.s.lists.sub_build = 1
    core.s.travel = INFINITY   # not saved: drifts measure until the next rebuild
    core.s.measure = 1


cdef object pair_histories(State* sim, long long npair):
    """The listed pairs' histories, hs each (zeros for a pair not in contact)."""
    cdef long long k
    out = np.zeros(npair * sim.hs, dtype=float)
    cdef double[::1] h = out
    for k in range(npair):
        if sim.lists.nb_c[k] >= 0:
            memcpy(&h[k * sim.hs], slot_history(sim, sim.lists.nb_c[k]), sim.hs * sizeof(double))
    return out


cdef void put_pair_histories(State* sim, a, long long npair) except *:
    """Give each listed pair that touches or has a history other than zeros a slot holding it
    (in list order), the others none (see Contacts)."""
    cdef long long k, used = 0
    a = np.ascontiguousarray(a, dtype=float).reshape(-1)
    if a.shape[0] != npair * sim.hs:
        raise ValueError(f"nb_h: expected {npair * sim.hs} values, got {a.shape[0]}")
    a = a.reshape(npair, sim.hs)
    kept = ((a != 0).any(axis=1) | (_copy_b(sim.lists.nb_s, npair) & TOUCH != 0)).view(np.uint8)
    cdef const double[:, ::1] h = a
    cdef const uint8_t[::1] keep = kept
    clear_contacts(sim)
    if reserve_contacts(sim, int(np.count_nonzero(kept))) < 0:
        raise MemoryError()
    for k in range(npair):
        if keep[k]:
            memcpy(slot_history(sim, used), &h[k, 0], sim.hs * sizeof(double))
            sim.lists.nb_c[k] = <int>used
            used += 1
        else:
            sim.lists.nb_c[k] = -1
    sim.contacts.n = used


cdef void restore_bodies(Core core, state) except *:
    """The clumps of a :meth:`get_state` output (after the particles; none without "mem")."""
    cdef int nb, nm, b, s
    cdef Column cols[NBCOLUMNS]
    if "mem" not in state:
        core.s.clumps.nbody = core.s.clumps.nmem = 0
        for s in range(core.s.particles.n):
            core.s.particles.mem[s] = -1
        return
    nb = state["body_m"].shape[0]
    nm = state["member_offset"].shape[0] // 3
    core.reserve_bodies(nb, nm)
    core.s.clumps.nbody = 0
    body_columns(&core.s, cols)
    load_table(state, cols, NBCOLUMNS, nb)
    member_columns(&core.s, cols)
    load_table(state, cols, NMCOLUMNS, nm)
    _put_i(core.s.particles.mem, state["mem"], core.s.particles.n)
    for b in range(nb):
        core.s.clumps.bdd[b] = 0.0
        for s in range(core.s.clumps.mstart[b], core.s.clumps.mstart[b + 1]):
            core.s.clumps.mbody[s] = b
    core.s.clumps.nbody = nb
    core.s.clumps.nmem = nm
    find_members(&core.s)


cdef object _copy_d(const double* p, long long k):
    a = np.empty(k, dtype=float)
    if k:
        memcpy(cnp.PyArray_DATA(a), p, k * sizeof(double))
    return a


cdef object _copy_i(const int* p, long long k):
    a = np.empty(k, dtype=np.int32)
    if k:
        memcpy(cnp.PyArray_DATA(a), p, k * sizeof(int))
    return a


cdef object _copy_l(const int64_t* p, long long k):
    a = np.empty(k, dtype=np.int64)
    if k:
        memcpy(cnp.PyArray_DATA(a), p, k * sizeof(int64_t))
    return a


cdef object _copy_b(const uint8_t* p, long long k):
    a = np.empty(k, dtype=np.uint8)
    if k:
        memcpy(cnp.PyArray_DATA(a), p, k)
    return a


cdef void _put_d(double* p, a, long long k) except *:
    a = np.ascontiguousarray(a, dtype=float).reshape(-1)
    if a.shape[0] != k:
        raise ValueError(f"expected {k} values, got {a.shape[0]}")
    if a.shape[0]:
        memcpy(p, cnp.PyArray_DATA(a), a.shape[0] * sizeof(double))


cdef void _put_i(int* p, a, long long k) except *:
    a = np.ascontiguousarray(a, dtype=np.int32).reshape(-1)
    if a.shape[0] != k:
        raise ValueError(f"expected {k} values, got {a.shape[0]}")
    if a.shape[0]:
        memcpy(p, cnp.PyArray_DATA(a), a.shape[0] * sizeof(int))
