# Checkpoints: a Core's State as numpy arrays and back (Core.get_state, Core.set_state),
# and the copies between C arrays and numpy.

cdef dict state_of(Core core):
    """Everything the time-step loop depends on, as numpy arrays (storage order)."""
    cdef int n = core.s.n, ne = core.s.ne, nb = core.s.nbody, nm = core.s.nmem
    cdef long long npair = core.s.nb_start[n], nwall = core.s.wl_start[n]
    state = {
        "x": _copy_d(core.s.x, 3 * n), "v": _copy_d(core.s.v, 3 * n), "w": _copy_d(core.s.w, 3 * n),
        "f": _copy_d(core.s.f, 3 * n), "t": _copy_d(core.s.t, 3 * n), "x0": _copy_d(core.s.x0, 3 * n),
        "r": _copy_d(core.s.r, n), "m": _copy_d(core.s.m, n), "type": _copy_i(core.s.type, n),
        "id": _copy_l(core.s.pid, n),
        "nb_start": _copy_i(core.s.nb_start, n + 1), "nb_j": _copy_i(core.s.nb_j, npair),
        "nb_s": _copy_b(core.s.nb_s, npair), "nb_h": _copy_d(core.s.nb_h, npair * core.s.hs),
        "wl_start": _copy_i(core.s.wl_start, n + 1), "wl_e": _copy_i(core.s.wl_e, nwall),
        "wl_h": _copy_d(core.s.wl_h, nwall * (core.s.hs + 1)),
        "ekind": _copy_i(core.s.ekind, ne), "etype": _copy_i(core.s.etype, ne),
        "ewall": _copy_i(core.s.ewall, ne), "evid": _copy_i(core.s.evid, 3 * ne),
        "emoving": _copy_i(core.s.emoving, ne), "egeo": _copy_d(core.s.egeo, 9 * ne),
        "eref": _copy_d(core.s.eref, 9 * ne), "ebuilt": _copy_d(core.s.ebuilt, 9 * ne),
        "emot": _copy_d(core.s.emot, NMOT * ne), "visc": _copy_d(core.s.visc, core.s.ntypes),
        "slots": _copy_d(core.s.slots, NSLOT * core.s.nslots),
        "vib": _copy_d(core.s.vib, NVIB * core.s.nvib),
        "scalars": np.array([core.s.time, core.s.t_base, core.s.dt_base, core.s.lost_speed], dtype=float),
        "lost": np.array([core.s.lost_at[k] for k in range(7)], dtype=np.int64),
        "counters": np.array([core.s.step, core.s.lost, core.s.rebuilds, core.s.dirty, core.s.step_base],
                             dtype=np.int64),
        "bounds": _copy_i(core.s.pb, core.s.nblocks + 1),
    }
    if nb == 0:   # a state of spheres only is what it was before there were clumps
        return state
    state["mem"] = _copy_i(core.s.mem, n)
    for key, value in core.bodies().items():
        state[f"body_{key}"] = value.reshape(-1)
    state["body_start"] = _copy_i(core.s.mstart, nb + 1)
    state["member_offset"] = _copy_d(core.s.md, 3 * nm)
    state["member_shift"] = _copy_d(core.s.mimg, 3 * nm)
    return state


cdef void restore(Core core, state) except *:
    """Restore :meth:`get_state` output (the contact model must be set already). The entries
    must be consistent (see ``solver._checked_state``); every copy checks its length."""
    cdef int n = state["r"].shape[0], ne = state["ekind"].shape[0], i
    cdef long long npair = state["nb_j"].shape[0], nwall = state["wl_e"].shape[0]
    core.reserve(n)
    if reserve_pairs(&core.s, npair) < 0 or reserve_walls(&core.s, nwall) < 0:
        raise MemoryError()
    core.s.n = 0
    core.s.ne = 0
    core.s.forces_valid = 0
    kinds = np.ascontiguousarray(state["ekind"], dtype=np.int32)
    core.add_elements(kinds, np.ascontiguousarray(state["etype"], dtype=np.int32),
                      np.ascontiguousarray(state["ewall"], dtype=np.int32),
                      np.ascontiguousarray(state["egeo"], dtype=float).reshape(ne, 9),
                      np.ascontiguousarray(state["evid"], dtype=np.int32).reshape(ne, 3))
    _put_d(core.s.eref, state["eref"], 9 * ne)
    _put_d(core.s.ebuilt, state["ebuilt"], 9 * ne)
    _put_d(core.s.emot, state["emot"], NMOT * ne)
    _put_i(core.s.emoving, state["emoving"], ne)
    core.set_slots(np.ascontiguousarray(state["slots"], dtype=float).reshape(-1, NSLOT))
    core.set_vibrations(np.ascontiguousarray(state["vib"], dtype=float).reshape(-1, NVIB))
    for name, ptr, k in (("x", <size_t>core.s.x, 3 * n), ("v", <size_t>core.s.v, 3 * n),
                         ("w", <size_t>core.s.w, 3 * n), ("f", <size_t>core.s.f, 3 * n),
                         ("t", <size_t>core.s.t, 3 * n), ("x0", <size_t>core.s.x0, 3 * n),
                         ("r", <size_t>core.s.r, n), ("m", <size_t>core.s.m, n),
                         ("nb_h", <size_t>core.s.nb_h, npair * core.s.hs),
                         ("wl_h", <size_t>core.s.wl_h, nwall * (core.s.hs + 1))):
        _put_d(<double*><size_t>ptr, state[name], k)
    for name, ptr, k in (("type", <size_t>core.s.type, n), ("nb_start", <size_t>core.s.nb_start, n + 1),
                         ("nb_j", <size_t>core.s.nb_j, npair),
                         ("wl_start", <size_t>core.s.wl_start, n + 1),
                         ("wl_e", <size_t>core.s.wl_e, nwall)):
        _put_i(<int*><size_t>ptr, state[name], k)
    ids = np.ascontiguousarray(state["id"], dtype=np.int64)
    nbs = np.ascontiguousarray(state["nb_s"], dtype=np.uint8)
    if ids.shape[0] != n or nbs.shape[0] != npair:
        raise ValueError("id, nb_s: one per particle and per listed pair")
    if n:
        memcpy(core.s.pid, cnp.PyArray_DATA(ids), n * sizeof(int64_t))
    if npair:
        memcpy(core.s.nb_s, cnp.PyArray_DATA(nbs), npair)
    core.set_viscous(np.ascontiguousarray(state["visc"], dtype=float))
    core.s.n = n
    restore_bodies(core, state)
    core.s.time, core.s.t_base, core.s.dt_base, core.s.lost_speed = (float(k) for k in state["scalars"])
    for i in range(7):
        core.s.lost_at[i] = state["lost"][i]
    core.s.step, core.s.lost, core.s.rebuilds, core.s.dirty, core.s.step_base = (
        int(k) for k in state["counters"])
    if state["bounds"].shape[0] == core.s.nblocks + 1:
        _put_i(core.s.pb, state["bounds"], core.s.nblocks + 1)
    else:   # another thread count: sums in another order anyway
        for i in range(n):
            core.s.work[i] = estimated_work(&core.s, i)
        balance(&core.s)
    for i in range(n):
        find_partners(&core.s, i)
    prefix_last(&core.s)
    core.s.sub_build = 1
    core.s.travel = INFINITY   # not saved: drifts measure until the next rebuild
    core.s.measure = 1


cdef void restore_bodies(Core core, state) except *:
    """The clumps of a :meth:`get_state` output (after the particles; none without "mem")."""
    cdef int nb, nm, b, s
    cdef int64_t[::1] bid
    if "mem" not in state:
        core.s.nbody = core.s.nmem = 0
        for s in range(core.s.n):
            core.s.mem[s] = -1
        return
    nb = state["body_m"].shape[0]
    nm = state["member_offset"].shape[0] // 3
    bid = np.ascontiguousarray(state["body_id"], dtype=np.int64)
    if bid.shape[0] != nb:
        raise ValueError("body_id: one per body")
    core.reserve_bodies(nb, nm)
    core.s.nbody = 0
    for name, ptr, k in (("body_x", <size_t>core.s.bx, 3 * nb), ("body_v", <size_t>core.s.bv, 3 * nb),
                         ("body_q", <size_t>core.s.bq, 4 * nb), ("body_p", <size_t>core.s.bp, 3 * nb),
                         ("body_m", <size_t>core.s.bm, nb), ("body_inertia", <size_t>core.s.bI, 3 * nb),
                         ("body_f", <size_t>core.s.bf, 3 * nb), ("body_t", <size_t>core.s.bt, 3 * nb),
                         ("member_offset", <size_t>core.s.md, 3 * nm),
                         ("member_shift", <size_t>core.s.mimg, 3 * nm)):
        _put_d(<double*><size_t>ptr, state[name], k)
    _put_i(core.s.btype, state["body_type"], nb)
    _put_i(core.s.mstart, state["body_start"], nb + 1)
    _put_i(core.s.mem, state["mem"], core.s.n)
    for b in range(nb):
        core.s.bid[b] = bid[b]
        core.s.bdd[b] = 0.0
        for s in range(core.s.mstart[b], core.s.mstart[b + 1]):
            core.s.mbody[s] = b
    core.s.nbody = nb
    core.s.nmem = nm
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
