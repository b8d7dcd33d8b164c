# Neighbour search: the rebuild (wrap, drop lost particles, sort by cell, permute), the half
# neighbour list and the wall list, with contact histories carried over from the previous lists.

cdef inline void zero_hist(double* h, int hs) noexcept nogil:
    cdef int k
    for k in range(hs):
        if h[k] != 0.0:
            memset(h, 0, hs * sizeof(double))
            return


cdef uint8_t carry_pair(const State* c, int a, int b, double* h) noexcept nogil:
    """History of new pair (a, b) from the previous list (old indices through ``perm``).

    Returns the previous touching flag (``TOUCH`` or 0).
    """
    cdef int oa = c.perm[a], ob = c.perm[b], lo = oa, hi = ob, k, q
    cdef double sign = 1.0
    if ob < oa:
        lo = ob
        hi = oa
        sign = -1.0
    for k in range(c.ob_start[lo], c.ob_start[lo + 1]):
        if c.ob_j[k] == hi:
            for q in range(3):
                h[q] = sign * c.ob_h[k * c.hs + q]
            for q in range(3, c.hs):
                h[q] = c.ob_h[k * c.hs + q]
            if c.roff:   # the rolling spring torque, too, is i's for the other orientation
                for q in range(c.roff, c.roff + 3):
                    h[q] *= sign
            return c.ob_s[k] & TOUCH
    memset(h, 0, c.hs * sizeof(double))
    return 0


cdef int grow_found(Found* out) noexcept nogil:
    """Double ``out``'s capacity (at least 4096 pairs); -1 when out of memory."""
    cdef long long cap = max(2 * out.cap, 4096)
    cdef void* a = grow(out.j, cap * sizeof(int))
    if a == NULL:
        return -1
    out.j = <int*>a
    a = grow(out.s, cap * sizeof(uint8_t))
    if a == NULL:
        return -1
    out.s = <uint8_t*>a
    out.cap = cap
    return 0


cdef inline int scan_cell(const State* c, int i, int cid, int code, int wrap, int body, Found* out,
                          long long pos, int cnt) noexcept nogil:
    """Append i's partners j > i in cell cid (seen through periodic image ``code``) to ``out``
    after its ``cnt`` first (see scan_pairs); the new count, or -1 when out of memory."""
    cdef int j = c.cell_start[cid]
    cdef double dx, dy, dz, rc
    cdef const double* xi = &c.x[3 * i]
    cdef const double* sv = &c.shiftv[3 * code]
    if j <= i:
        j = i + 1
    while j < c.cell_start[cid + 1]:
        dx = xi[0] - c.x[3 * j] + sv[0]
        dy = xi[1] - c.x[3 * j + 1] + sv[1]
        dz = xi[2] - c.x[3 * j + 2] + sv[2]
        rc = c.r[i] + c.r[j] + c.skin
        if dx * dx + dy * dy + dz * dz < rc * rc and not (
                body >= 0 and c.mem[j] >= 0 and c.mbody[c.mem[j]] == body):
            if pos + cnt == out.cap and grow_found(out) < 0:
                return -1
            out.j[pos + cnt] = j
            out.s[pos + cnt] = <uint8_t>(code | wrap)
            cnt += 1
        j += 1
    return cnt


cdef int scan_pairs(const State* c, int i, Found* out, long long pos) noexcept nogil:
    """Partners j > i within r_i + r_j + skin, but for spheres of i's clump: written to ``out``
    from ``pos`` (see Found); how many, or -1 when out of memory. The cells around i's are
    searched in the order of the loops below; rows are sorted by cell, so cells before i's hold
    no j > i: inside the grid (no image, no edge) only the cells ``c.up`` after it are searched."""
    cdef int d0, d1, d2, k, cid, cnt = 0
    cdef int body = c.mbody[c.mem[i]] if c.nbody and c.mem[i] >= 0 else -1
    cdef int cc[3]
    cdef int nb[3]
    cdef int s[3]
    cid = locate(&c.x[3 * i], c.lo, c.cs, c.nc, c.ax, cc)
    if (0 < cc[0] < c.nc[0] - 1) and (0 < cc[1] < c.nc[1] - 1) and (0 < cc[2] < c.nc[2] - 1):
        for k in range(14):
            cnt = scan_cell(c, i, cid + c.up[k], 13, 0, body, out, pos, cnt)
            if cnt < 0:
                return -1
        return cnt
    for d2 in range(-1, 2):
        nb[2] = cc[2] + d2
        s[2] = 0
        if nb[2] < 0 or nb[2] >= c.nc[2]:
            if not c.per[2]:
                continue
            s[2] = 1 if nb[2] < 0 else -1
            nb[2] += s[2] * c.nc[2]
        for d1 in range(-1, 2):
            nb[1] = cc[1] + d1
            s[1] = 0
            if nb[1] < 0 or nb[1] >= c.nc[1]:
                if not c.per[1]:
                    continue
                s[1] = 1 if nb[1] < 0 else -1
                nb[1] += s[1] * c.nc[1]
            for d0 in range(-1, 2):
                nb[0] = cc[0] + d0
                s[0] = 0
                if nb[0] < 0 or nb[0] >= c.nc[0]:
                    if not c.per[0]:
                        continue
                    s[0] = 1 if nb[0] < 0 else -1
                    nb[0] += s[0] * c.nc[0]
                cnt = scan_cell(c, i, cell_id(c.nc, c.ax, nb), 9 * (s[0] + 1) + 3 * (s[1] + 1) + s[2] + 1,
                                WRAP if s[c.ax[0]] != 0 else 0, body, out, pos, cnt)
                if cnt < 0:
                    return -1
    return cnt


cdef int scan_walls(const State* c, int i, bint fill) noexcept nogil:
    """Wall elements within r_i + skin of particle i: counted, or written from ``wl_start[i]``."""
    cdef int e, k, q, cid, feat, cnt = 0, pos, oi
    cdef int cc[3]
    cdef double gap, reach = c.r[i] + c.skin, d2
    cdef double nrm[3]
    cdef double p[3]
    cdef const double* xi = &c.x[3 * i]
    cdef const double* g
    pos = c.wl_start[i] if fill else 0
    oi = c.perm[i]
    for e in range(c.ne):
        if c.ekind[e] == TRIANGLE:
            continue
        gap = primitive_gap(c.ekind[e], &c.egeo[9 * e], xi, nrm)
        if c.ekind[e] == PLANE:
            gap = fabs(gap)
        if gap < reach:
            if fill:
                c.wl_e[pos + cnt] = e
            cnt += 1
    cid = locate(xi, c.lo, c.cs, c.nc, c.ax, cc)
    for k in range(c.ctri_start[cid], c.ctri_start[cid + 1]):
        e = c.ctri[k]
        g = &c.egeo[9 * e]
        closest_on_triangle(xi, g, g + 3, g + 6, p, &feat)
        d2 = (xi[0] - p[0]) ** 2 + (xi[1] - p[1]) ** 2 + (xi[2] - p[2]) ** 2
        if d2 < reach * reach:
            if fill:
                c.wl_e[pos + cnt] = e
            cnt += 1
    if fill:
        for k in range(cnt):
            e = c.wl_e[pos + k]
            memset(&c.wl_h[(pos + k) * c.whs], 0, c.whs * sizeof(double))
            for q in range(c.ow_start[oi], c.ow_start[oi + 1]):
                if c.ow_e[q] == e:
                    memcpy(&c.wl_h[(pos + k) * c.whs], &c.ow_h[q * c.whs], c.whs * sizeof(double))
                    break
    return cnt


cdef int reserve_pairs(State* sim, long long need) noexcept nogil:
    """Grow the current neighbour list (and the pair forces) to ``need`` pairs; -1 when out of
    memory."""
    cdef long long cap
    cdef void *a
    cdef void *b
    cdef void *c
    if need > sim.nbf_cap:
        cap = need + need // 10 + 64
        a = grow(sim.nb_f, cap * 3 * sizeof(double))
        if a == NULL:
            return -1
        sim.nb_f = <double*>a
        sim.nbf_cap = cap
    if need > sim.sbk_cap:
        cap = need + need // 10 + 64
        a = grow(sim.sb_k, cap * sizeof(int))
        if a == NULL:
            return -1
        sim.sb_k = <int*>a
        a = grow(sim.sb_i, cap * sizeof(int))
        if a == NULL:
            return -1
        sim.sb_i = <int*>a
        sim.sbk_cap = cap
    if need <= sim.nb_cap:
        return 0
    cap = need + need // 10 + 64
    a = grow(sim.nb_j, cap * sizeof(int))
    if a == NULL:
        return -1
    sim.nb_j = <int*>a
    b = grow(sim.nb_s, cap * sizeof(uint8_t))
    if b == NULL:
        return -1
    sim.nb_s = <uint8_t*>b
    c = grow(sim.nb_h, cap * sim.hs * sizeof(double))
    if c == NULL:
        return -1
    sim.nb_h = <double*>c
    sim.nb_cap = cap
    return 0


cdef int reserve_walls(State* sim, long long need) noexcept nogil:
    """Grow the current wall list (and the wall contacts' records) to ``need`` entries; -1 when
    out of memory."""
    cdef long long cap
    cdef void *a
    cdef void *b
    if need > sim.wlf_cap:
        cap = need + need // 10 + 64
        a = grow(sim.wl_f, cap * WLF * sizeof(double))
        if a == NULL:
            return -1
        sim.wl_f = <double*>a
        sim.wlf_cap = cap
    if need <= sim.wl_cap:
        return 0
    cap = need + need // 10 + 64
    a = grow(sim.wl_e, cap * sizeof(int))
    if a == NULL:
        return -1
    sim.wl_e = <int*>a
    b = grow(sim.wl_h, cap * (sim.hs + 1) * sizeof(double))
    if b == NULL:
        return -1
    sim.wl_h = <double*>b
    sim.wl_cap = cap
    return 0


cdef inline int place_particle(State* sim, int i) noexcept nogil:
    """Wrap particle i into the periodic box; its cell, -1 if lost, -2 if removed."""
    cdef int d
    cdef double p
    if sim.type[i] < 0:
        return -2
    for d in range(3):
        p = sim.x[3 * i + d]
        if not isfinite(p):
            return -1
        if sim.per[d]:
            if p < sim.lo[d] or p >= sim.hi[d]:
                p -= sim.L[d] * floor((p - sim.lo[d]) / sim.L[d])
                if p >= sim.hi[d]:
                    p = sim.lo[d]
                sim.x[3 * i + d] = p
        elif p < sim.lo[d] or p > sim.hi[d]:
            return -1
    return cell_of(sim, &sim.x[3 * i])


cdef void count_lost(State* sim, int i) noexcept nogil:
    """Count lost particle i at the face of the box it is furthest beyond (or as non-finite),
    and its speed."""
    cdef int d, place = 6
    cdef double p, beyond = 0.0, speed = 0.0
    for d in range(3):
        if not (isfinite(sim.x[3 * i + d]) and isfinite(sim.v[3 * i + d])):
            sim.lost_at[6] += 1
            return
        speed += sim.v[3 * i + d] * sim.v[3 * i + d]
    for d in range(3):
        p = sim.x[3 * i + d]
        if sim.per[d]:
            continue
        if sim.lo[d] - p > beyond:
            beyond = sim.lo[d] - p
            place = 2 * d
        elif p - sim.hi[d] > beyond:
            beyond = p - sim.hi[d]
            place = 2 * d + 1
    sim.lost_at[place] += 1
    if sqrt(speed) > sim.lost_speed:
        sim.lost_speed = sqrt(speed)


cdef bint any_moving(State* sim) noexcept nogil:
    cdef int e
    for e in range(sim.ne):
        if sim.emoving[e]:
            return True
    return False


cdef void permute(State* sim, int n) noexcept nogil:
    """Reorder the particle arrays by ``perm`` in three parallel passes. f, t and x0 are
    recomputed after a rebuild, so they serve as scratch: x, v and w are gathered into them
    and swapped with them; r, m, type, pid (and with clumps mem) are gathered into the old x
    and v, then copied back while x0 becomes a copy of x (see rebuild_rows)."""
    cdef double* p
    parallel_rows(sim, P_GATHER, n)
    p = sim.x; sim.x = sim.f; sim.f = p
    p = sim.v; sim.v = sim.t; sim.t = p
    p = sim.w; sim.w = sim.x0; sim.x0 = p
    parallel_rows(sim, P_GATHER_SCALARS, n)
    parallel_rows(sim, P_COPY_BACK, n)


cdef void rebuild_rows(State* sim, int phase, int lo, int hi, int b) noexcept nogil:
    """Rows [lo, hi), block b, of a parallel pass of the rebuild (and bodies [lo, hi) of a body
    loop, which the team hands out as rows too)."""
    cdef int i, d, n = sim.rows, j, cnt
    cdef long long k, pos = 0
    cdef Found* found = &sim.found[b]
    cdef int* perm = sim.perm
    cdef double* sr = sim.f
    cdef double* sm = sim.f + n
    cdef int* st = <int*>(sim.f + 2 * n)
    cdef int* sb = st + n
    cdef int64_t* sp = <int64_t*>sim.t
    if phase == P_BODIES or phase == P_BODY_DRIFT:
        body_rows(sim, phase, lo, hi)
    elif phase == P_PLACE:
        for i in range(lo, hi):
            sim.cell[i] = place_particle(sim, i)
    elif phase == P_GATHER:   # into f, t, x0 (swapped with x, v, w afterwards)
        for i in range(lo, hi):
            for d in range(3):
                sim.f[3 * i + d] = sim.x[3 * perm[i] + d]
                sim.t[3 * i + d] = sim.v[3 * perm[i] + d]
                sim.x0[3 * i + d] = sim.w[3 * perm[i] + d]
    elif phase == P_GATHER_SCALARS:
        for i in range(lo, hi):
            sr[i] = sim.r[perm[i]]
            sm[i] = sim.m[perm[i]]
            st[i] = sim.type[perm[i]]
            sp[i] = sim.pid[perm[i]]
            if sim.nbody:
                sb[i] = sim.mem[perm[i]]
    elif phase == P_COPY_BACK:
        for i in range(lo, hi):
            sim.r[i] = sr[i]
            sim.m[i] = sm[i]
            sim.type[i] = st[i]
            sim.pid[i] = sp[i]
            if sim.nbody:
                sim.mem[i] = sb[i]
            for d in range(3):
                sim.x0[3 * i + d] = sim.x[3 * i + d]
    elif phase == P_COUNT:   # the pairs go to the block's Found, the fill copies them
        found.failed = 0
        for i in range(lo, hi):
            cnt = scan_pairs(sim, i, found, pos)
            if cnt < 0:
                found.failed = 1
                cnt = 0
            pos += cnt
            sim.nb_start[i + 1] = cnt
            sim.wl_start[i + 1] = scan_walls(sim, i, False)
    elif phase == P_FILL:
        pos = sim.nb_start[lo]
        for i in range(lo, hi):
            for k in range(sim.nb_start[i], sim.nb_start[i + 1]):
                j = found.j[k - pos]
                sim.nb_j[k] = j
                sim.nb_s[k] = found.s[k - pos] | carry_pair(sim, i, j, &sim.nb_h[k * sim.hs])
            scan_walls(sim, i, True)
            sim.work[i] = estimated_work(sim, i)
            find_partners(sim, i)


cdef inline void find_partners(State* sim, int i) noexcept nogil:
    """Row i's largest near partner (``last``, -1: none) and its smallest and largest far
    partner (``flo``, ``fhi``; INT_MAX and -1: none), see Halo."""
    cdef int k, j
    sim.last[i] = -1
    sim.flo[i] = INT_MAX
    sim.fhi[i] = -1
    for k in range(sim.nb_start[i], sim.nb_start[i + 1]):
        j = sim.nb_j[k]
        if sim.nb_s[k] & WRAP:
            sim.flo[i] = min(sim.flo[i], j)
            sim.fhi[i] = max(sim.fhi[i], j)
        elif j > sim.last[i]:
            sim.last[i] = j


cdef void prefix_last(State* sim) noexcept nogil:
    """``last``: from each row's largest near partner to the largest of the rows up to it;
    ``nfar`` after the last row with a far partner."""
    cdef int i
    sim.nfar = 0
    for i in range(sim.n):
        if i > 0 and sim.last[i - 1] > sim.last[i]:
            sim.last[i] = sim.last[i - 1]
        if sim.fhi[i] >= 0:
            sim.nfar = i + 1


cdef int rebuild(State* sim) noexcept nogil:
    """Wrap, drop lost particles (a clump whole), sort into cells, rebuild both lists carrying
    histories."""
    cdef int i, d, n = sim.n, nnew, dead = 0
    cdef long long lost = 0
    cdef double rmax = 0.0
    cdef int *ip
    cdef uint8_t *bp
    cdef double *dp
    cdef long long cap
    cdef double t0 = pg_now(), t1
    for i in range(n):
        if sim.r[i] > rmax:
            rmax = sim.r[i]
    if setup_cells(sim, rmax) < 0:
        return -1
    if sim.binned_dirty or sim.binned_reach != rmax + sim.skin or any_moving(sim) \
            or sim.binned_nc[0] != sim.nc[0] or sim.binned_nc[1] != sim.nc[1] or sim.binned_nc[2] != sim.nc[2]:
        if bin_triangles(sim, rmax + sim.skin) < 0:
            return -1
        sim.binned_dirty = 0
        sim.binned_reach = rmax + sim.skin
        for d in range(3):
            sim.binned_nc[d] = sim.nc[d]
    t1 = lap(sim, T_CELLS, t0)
    # wrap periodic coordinates, mark particles outside a fixed boundary (or removed) lost
    if sim.nbody:
        place_bodies(sim)
    parallel_rows(sim, P_PLACE, n)
    if sim.nbody:
        dead = mark_dead_bodies(sim, &lost)
    for i in range(n):
        if sim.cell[i] < 0:
            if sim.cell[i] == -1:
                lost += 1
                count_lost(sim, i)
            sim.cell[i] = sim.ncells
    sim.lost += lost
    # counting sort by cell (lost ones in the sentinel cell ncells)
    memset(sim.cell_start, 0, (sim.ncells + 2) * sizeof(int))
    for i in range(n):
        sim.cell_start[sim.cell[i] + 1] += 1
    for i in range(sim.ncells + 1):
        sim.cell_start[i + 1] += sim.cell_start[i]
    for i in range(n):
        sim.perm[sim.cell_start[sim.cell[i]]] = i
        sim.cell_start[sim.cell[i]] += 1
    for i in range(sim.ncells + 1, 0, -1):
        sim.cell_start[i] = sim.cell_start[i - 1]
    sim.cell_start[0] = 0
    nnew = sim.cell_start[sim.ncells]
    t1 = lap(sim, T_SORT, t1)
    permute(sim, nnew)
    sim.n = nnew
    if sim.nbody:
        if dead and drop_bodies(sim, nnew) < 0:
            return -1
        find_members(sim)
    t1 = lap(sim, T_PERMUTE, t1)
    # the current lists become the previous ones
    ip = sim.ob_start; sim.ob_start = sim.nb_start; sim.nb_start = ip
    ip = sim.ob_j; sim.ob_j = sim.nb_j; sim.nb_j = ip
    bp = sim.ob_s; sim.ob_s = sim.nb_s; sim.nb_s = bp
    dp = sim.ob_h; sim.ob_h = sim.nb_h; sim.nb_h = dp
    cap = sim.ob_cap; sim.ob_cap = sim.nb_cap; sim.nb_cap = cap
    ip = sim.ow_start; sim.ow_start = sim.wl_start; sim.wl_start = ip
    ip = sim.ow_e; sim.ow_e = sim.wl_e; sim.wl_e = ip
    dp = sim.ow_h; sim.ow_h = sim.wl_h; sim.wl_h = dp
    cap = sim.ow_cap; sim.ow_cap = sim.wl_cap; sim.wl_cap = cap
    parallel_rows(sim, P_COUNT, nnew)
    for i in range(sim.nblocks):
        if sim.found[i].failed:
            return -1
    sim.nb_start[0] = 0
    sim.wl_start[0] = 0
    for i in range(nnew):
        sim.nb_start[i + 1] += sim.nb_start[i]
        sim.wl_start[i + 1] += sim.wl_start[i]
    if reserve_pairs(sim, sim.nb_start[nnew]) < 0 or reserve_walls(sim, sim.wl_start[nnew]) < 0:
        return -1
    t1 = lap(sim, T_COUNT, t1)
    parallel_rows(sim, P_FILL, nnew)
    prefix_last(sim)
    for i in range(9 * sim.ne):
        sim.ebuilt[i] = sim.egeo[i]
    balance(sim)
    lap(sim, T_FILL, t1)
    lap(sim, T_REBUILD, t0)
    sim.rebuilds += 1
    sim.sub_build = 1
    sim.travel = 0.0
    sim.since = 0
    return 0


cdef inline bint in_contact(State* sim, int k) noexcept nogil:
    return sim.nb_s[k] & TOUCH and (sim.model != THORNTON_NING or sim.nb_h[k * sim.hs + H_DMAX] > 0.0)
