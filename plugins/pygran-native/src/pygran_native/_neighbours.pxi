# Neighbour search: the rebuild (wrap, drop lost particles, sort by cell, permute), the half
# neighbour list and the wall list, with contact histories carried over from the previous lists.

cdef inline void zero_hist(double* h, int hs) noexcept nogil:
    cdef int k
    for k in range(hs):
        if h[k] != 0.0:
            memset(h, 0, hs * sizeof(double))
            return


cdef uint8_t carry_pair(const State* c, int a, int b, int* slot) noexcept nogil:
    """The contact slot of new pair (a, b) in the previous list (old indices through ``perm``),
    -1 if none; its history turned to the new orientation. Returns the previous
    touching flag (``TOUCH`` or 0)."""
    cdef int oa = c.particles.perm[a], ob = c.particles.perm[b], lo = oa, hi = ob, k, q
    cdef double* h
    if ob < oa:
        lo = ob
        hi = oa
    for k in range(c.lists.ob_start[lo], c.lists.ob_start[lo + 1]):
        if c.lists.ob_j[k] == hi:
            slot[0] = c.lists.ob_c[k]
            if slot[0] >= 0:
                if ob < oa:   # the shear, and the rolling spring torque, are i's: j's is the opposite
                    h = slot_history(c, slot[0])
                    for q in range(3):
                        h[q] = -h[q]
                    if c.roff:
                        for q in range(c.roff, c.roff + 3):
                            h[q] = -h[q]
            return c.lists.ob_s[k] & TOUCH
    slot[0] = -1
    return 0


cdef int grow_found(Found* out) noexcept nogil:
    """Grow ``out``'s capacity by a quarter (to 4096 pairs at least), into buffers of its own
    when it was borrowed; -1 when out of memory."""
    cdef long long cap = max(out.cap + out.cap // 4, 4096)
    cdef void* a
    cdef void* b
    if out.borrowed:
        a = grow(NULL, cap * sizeof(int))
        b = grow(NULL, cap * sizeof(uint8_t))
        if a == NULL or b == NULL:
            release(a)
            release(b)
            return -1
        memcpy(a, out.j, out.cap * sizeof(int))
        memcpy(b, out.s, out.cap * sizeof(uint8_t))
        out.borrowed = 0
    else:
        a = grow(out.j, cap * sizeof(int))
        if a == NULL:
            return -1
        out.j = <int*>a
        b = grow(out.s, cap * sizeof(uint8_t))
        if b == NULL:
            return -1
    out.j = <int*>a
    out.s = <uint8_t*>b
    out.cap = cap
    return 0


cdef void release_found(Found* out) noexcept nogil:
    """Drop a block's found pairs' buffers (none of its own when borrowed)."""
    if not out.borrowed:
        release(out.j)
        release(out.s)
    out.j = NULL
    out.s = NULL
    out.cap = 0
    out.borrowed = 0


cdef void lend_found(State* sim) noexcept nogil:
    """With the batched path, before the count: each block's found pairs go to its share of the
    sublist's arrays (partners to sb_k, codes to the bytes of sb_i), which the first pass after
    the rebuild makes anew, instead of buffers of their own (a block whose pairs outgrow its
    share copies them to buffers of its own, freed after the fill, see grow_found). Without it
    (no sublist), the blocks keep their buffers from rebuild to rebuild."""
    cdef int b, nb = sim.schedule.nblocks
    cdef long long share = sim.lists.sbk_cap // nb
    if not sim.batched:
        return
    for b in range(nb):
        release_found(&sim.lists.found[b])
        if share:
            sim.lists.found[b].j = sim.lists.sb_k + b * share
            sim.lists.found[b].s = <uint8_t*>(sim.lists.sb_i + b * share)
            sim.lists.found[b].cap = share
            sim.lists.found[b].borrowed = 1


cdef inline int scan_cell(const State* c, int i, int cid, int code, int wrap, int body, Found* out,
                          long long pos, int cnt) noexcept nogil:
    """Append i's partners j > i in cell cid (seen through periodic image ``code``) to ``out``
    after its ``cnt`` first (see scan_pairs); the new count, or -1 when out of memory."""
    cdef int j = c.lists.cell_start[cid]
    cdef double dx, dy, dz, rc
    cdef const double* xi = &c.particles.x[3 * i]
    cdef const double* sv = &c.shiftv[3 * code]
    if j <= i:
        j = i + 1
    while j < c.lists.cell_start[cid + 1]:
        dx = xi[0] - c.particles.x[3 * j] + sv[0]
        dy = xi[1] - c.particles.x[3 * j + 1] + sv[1]
        dz = xi[2] - c.particles.x[3 * j + 2] + sv[2]
        rc = c.particles.r[i] + c.particles.r[j] + c.skin
        if dx * dx + dy * dy + dz * dz < rc * rc and c.particles.r[j] <= c.lists.rsplit and \
                not same_body(c, body, j):
            cnt = add_found(out, pos, cnt, j, code | wrap)
            if cnt < 0:
                return -1
        j += 1
    return cnt


cdef inline bint same_body(const State* c, int body, int j) noexcept nogil:
    """Whether sphere j belongs to clump ``body`` (-1: none)."""
    return body >= 0 and c.particles.mem[j] >= 0 and c.clumps.mbody[c.particles.mem[j]] == body


cdef inline int body_of(const State* c, int i) noexcept nogil:
    return c.clumps.mbody[c.particles.mem[i]] if c.clumps.nbody and c.particles.mem[i] >= 0 else -1


cdef inline int add_found(Found* out, long long pos, int cnt, int j, int code) noexcept nogil:
    """Append partner j (image code and flags ``code``) to ``out`` after its ``cnt`` first from
    ``pos``; the new count, or -1 when out of memory."""
    if pos + cnt == out.cap and grow_found(out) < 0:
        return -1
    out.j[pos + cnt] = j
    out.s[pos + cnt] = <uint8_t>code
    return cnt + 1


cdef int add_extra(State* sim, int i, int j, int code) noexcept nogil:
    """Append the pair of small row i and big row j > i to the extras; -1 when out of memory."""
    cdef void* p
    if sim.lists.nextra == sim.lists.extra_cap:
        p = grow(sim.lists.extra, (sim.lists.extra_cap + sim.lists.extra_cap // 2 + 256) * sizeof(Extra))
        if p == NULL:
            return -1
        sim.lists.extra = <Extra*>p
        sim.lists.extra_cap += sim.lists.extra_cap // 2 + 256
    sim.lists.extra[sim.lists.nextra].i = i
    sim.lists.extra[sim.lists.nextra].j = j
    sim.lists.extra[sim.lists.nextra].s = <uint8_t>code
    sim.lists.nextra += 1
    return 0


cdef inline bint cell_exists(const State* c, int d, int a) noexcept nogil:
    """Whether cell coordinate a along axis d is in the grid or, on a periodic axis, an image."""
    return c.per[d] or 0 <= a < c.lists.nc[d]


cdef inline void wrap_cell(const State* c, int d, int a, int* nb, int* s) noexcept nogil:
    """Cell coordinate a (at most one grid beyond the edge) along axis d, wrapped (nb[d]) with
    its image's sign (s[d]: 1 below the grid, -1 above), as scan_pairs."""
    s[d] = 0
    nb[d] = a
    if a < 0:
        s[d] = 1
        nb[d] = a + c.lists.nc[d]
    elif a >= c.lists.nc[d]:
        s[d] = -1
        nb[d] = a - c.lists.nc[d]


cdef int scan_box(State* c, int i, bint before, Found* out, long long pos, int cnt) noexcept nogil:
    """Big row i's small partners within r_i + r_j + skin, from the cells within its reach
    (wrapped at most once, see box_fits): those after it, appended to ``out`` as scan_cell does
    (the new count), or with ``before`` those before it, appended to the extras as pairs of
    their rows (0). -1 when out of memory."""
    cdef int d, k, a0, a1, a2, j, cid, code, wrap, body = body_of(c, i)
    cdef int cc[3]
    cdef int lo[3]
    cdef int hi[3]
    cdef int nb[3]
    cdef int s[3]
    cdef double reach = c.particles.r[i] + c.lists.rsplit + c.skin, dx, dy, dz, rc
    cdef const double* xi = &c.particles.x[3 * i]
    cdef const double* sv
    locate(xi, c.lo, c.lists.cs, c.lists.nc, c.lists.ax, cc)
    for d in range(3):
        k = <int>ceil(reach / c.lists.cs[d])
        lo[d] = cc[d] - k
        hi[d] = cc[d] + k
        if not c.per[d]:
            lo[d] = max(lo[d], 0)
            hi[d] = min(hi[d], c.lists.nc[d] - 1)
    for a2 in range(lo[2], hi[2] + 1):
        wrap_cell(c, 2, a2, nb, s)
        for a1 in range(lo[1], hi[1] + 1):
            wrap_cell(c, 1, a1, nb, s)
            for a0 in range(lo[0], hi[0] + 1):
                wrap_cell(c, 0, a0, nb, s)
                code = 9 * (s[0] + 1) + 3 * (s[1] + 1) + s[2] + 1
                wrap = WRAP if s[c.lists.ax[0]] != 0 else 0
                sv = &c.shiftv[3 * code]
                cid = cell_id(c.lists.nc, c.lists.ax, nb)
                for j in range(c.lists.cell_start[cid], c.lists.cell_start[cid + 1]):
                    if j == i or (j < i) != before or c.particles.r[j] > c.lists.rsplit:
                        continue
                    dx = xi[0] - c.particles.x[3 * j] + sv[0]
                    dy = xi[1] - c.particles.x[3 * j + 1] + sv[1]
                    dz = xi[2] - c.particles.x[3 * j + 2] + sv[2]
                    rc = c.particles.r[i] + c.particles.r[j] + c.skin
                    if dx * dx + dy * dy + dz * dz >= rc * rc or same_body(c, body, j):
                        continue
                    if before:   # row j sees i through the opposite image
                        if add_extra(c, j, i, (26 - code) | wrap) < 0:
                            return -1
                    else:
                        cnt = add_found(out, pos, cnt, j, code | wrap)
                        if cnt < 0:
                            return -1
    return cnt


cdef int scan_big(State* c, int i, Found* out, long long pos) noexcept nogil:
    """Big row i's partners after it: the small ones (scan_box), then the big ones, each
    tried at its nearest periodic image; how many, or -1 when out of memory."""
    cdef int q, d, j, code, cnt, body = body_of(c, i)
    cdef int s[3]
    cdef double dd[3]
    cdef double rc
    cnt = scan_box(c, i, False, out, pos, 0)
    for q in range(c.lists.nbig):
        j = c.lists.big[q]
        if cnt < 0 or j <= i:
            continue
        for d in range(3):
            dd[d] = c.particles.x[3 * i + d] - c.particles.x[3 * j + d]
            s[d] = 0
            if c.per[d] and dd[d] > 0.5 * c.L[d]:
                s[d] = -1
            elif c.per[d] and dd[d] < -0.5 * c.L[d]:
                s[d] = 1
            dd[d] += s[d] * c.L[d]
        rc = c.particles.r[i] + c.particles.r[j] + c.skin
        if dd[0] * dd[0] + dd[1] * dd[1] + dd[2] * dd[2] < rc * rc and not same_body(c, body, j):
            code = 9 * (s[0] + 1) + 3 * (s[1] + 1) + s[2] + 1
            cnt = add_found(out, pos, cnt, j, code | (WRAP if s[c.lists.ax[0]] != 0 else 0))
    return cnt


cdef int by_rows(const void* a, const void* b) noexcept nogil:
    cdef const Extra* x = <const Extra*>a
    cdef const Extra* y = <const Extra*>b
    if x.i != y.i:
        return -1 if x.i < y.i else 1
    return -1 if x.j < y.j else (1 if x.j > y.j else 0)


cdef int find_big(State* sim) noexcept nogil:
    """The big rows (``Lists.big``) and, sorted by row, the extras; -1 when out of memory."""
    cdef int i, q
    cdef void* p
    sim.lists.nbig = 0
    sim.lists.nextra = 0
    if sim.lists.rsplit >= INFINITY:
        return 0
    for i in range(sim.particles.n):
        if sim.particles.r[i] > sim.lists.rsplit:
            if sim.lists.nbig == sim.lists.big_cap:
                p = grow(sim.lists.big, (2 * sim.lists.big_cap + 16) * sizeof(int))
                if p == NULL:
                    return -1
                sim.lists.big = <int*>p
                sim.lists.big_cap = 2 * sim.lists.big_cap + 16
            sim.lists.big[sim.lists.nbig] = i
            sim.lists.nbig += 1
    for q in range(sim.lists.nbig):
        if scan_box(sim, sim.lists.big[q], True, NULL, 0, 0) < 0:
            return -1
    qsort(sim.lists.extra, sim.lists.nextra, sizeof(Extra), by_rows)
    return 0


cdef int scan_pairs(const State* c, int i, Found* out, long long pos) noexcept nogil:
    """Small partners j > i within r_i + r_j + skin (big ones come from the extras, see find_big),
    but for spheres of i's clump: written to ``out``
    from ``pos`` (see Found); how many, or -1 when out of memory. The cells around i's are
    searched in the order of the loops below; rows are sorted by cell, so cells before i's hold
    no j > i: inside the grid (no image, no edge) only the cells ``c.lists.up`` after it are searched."""
    cdef int d0, d1, d2, k, cid, cnt = 0
    cdef int body = body_of(c, i)
    cdef int cc[3]
    cdef int nb[3]
    cdef int s[3]
    cid = locate(&c.particles.x[3 * i], c.lo, c.lists.cs, c.lists.nc, c.lists.ax, cc)
    if (0 < cc[0] < c.lists.nc[0] - 1) and (0 < cc[1] < c.lists.nc[1] - 1) and (0 < cc[2] < c.lists.nc[2] - 1):
        for k in range(14):
            cnt = scan_cell(c, i, cid + c.lists.up[k], 13, 0, body, out, pos, cnt)
            if cnt < 0:
                return -1
        return cnt
    for d2 in range(-1, 2):
        if not cell_exists(c, 2, cc[2] + d2):
            continue
        wrap_cell(c, 2, cc[2] + d2, nb, s)
        for d1 in range(-1, 2):
            if not cell_exists(c, 1, cc[1] + d1):
                continue
            wrap_cell(c, 1, cc[1] + d1, nb, s)
            for d0 in range(-1, 2):
                if not cell_exists(c, 0, cc[0] + d0):
                    continue
                wrap_cell(c, 0, cc[0] + d0, nb, s)
                cnt = scan_cell(c, i, cell_id(c.lists.nc, c.lists.ax, nb), 9 * (s[0] + 1) + 3 * (s[1] + 1) + s[2] + 1,
                                WRAP if s[c.lists.ax[0]] != 0 else 0, body, out, pos, cnt)
                if cnt < 0:
                    return -1
    return cnt


cdef int scan_walls(const State* c, int i, bint fill) noexcept nogil:
    """Wall elements within r_i + skin of particle i: counted, or written from ``wl_start[i]``."""
    cdef int e, k, q, cid, feat, cnt = 0, pos, oi
    cdef int cc[3]
    cdef double gap, reach = c.particles.r[i] + c.skin, d2
    cdef double nrm[3]
    cdef double p[3]
    cdef const double* xi = &c.particles.x[3 * i]
    cdef const double* g
    pos = c.lists.wl_start[i] if fill else 0
    oi = c.particles.perm[i]
    for e in range(c.walls.ne):
        if c.walls.ekind[e] == TRIANGLE:
            continue
        gap = primitive_gap(c.walls.ekind[e], &c.walls.egeo[9 * e], xi, nrm)
        if c.walls.ekind[e] == PLANE:
            gap = fabs(gap)
        if gap < reach:
            if fill:
                c.lists.wl_e[pos + cnt] = e
            cnt += 1
    cid = locate(xi, c.lo, c.lists.cs, c.lists.nc, c.lists.ax, cc)
    for k in range(c.walls.ctri_start[cid], c.walls.ctri_start[cid + 1]):
        e = c.walls.ctri[k]
        g = &c.walls.egeo[9 * e]
        closest_on_triangle(xi, g, g + 3, g + 6, p, &feat)
        d2 = (xi[0] - p[0]) ** 2 + (xi[1] - p[1]) ** 2 + (xi[2] - p[2]) ** 2
        if d2 < reach * reach:
            if fill:
                c.lists.wl_e[pos + cnt] = e
            cnt += 1
    if fill:
        for k in range(cnt):
            e = c.lists.wl_e[pos + k]
            memset(&c.lists.wl_h[(pos + k) * c.whs], 0, c.whs * sizeof(double))
            for q in range(c.lists.ow_start[oi], c.lists.ow_start[oi + 1]):
                if c.lists.ow_e[q] == e:
                    memcpy(&c.lists.wl_h[(pos + k) * c.whs], &c.lists.ow_h[q * c.whs], c.whs * sizeof(double))
                    break
    return cnt


cdef inline long long room(long long need) noexcept nogil:
    """The capacity a list grows to for ``need`` entries: a thirty-second more (growing again
    costs a realloc at a rebuild, and a list is rebuilt a little longer or shorter each time)."""
    return need + need // 32 + 64


cdef int reserve_sublist(State* sim, long long need) noexcept nogil:
    """Grow the sublist, which only the batched path has, to ``need`` pairs; -1 when out of
    memory."""
    cdef long long cap = room(need)
    cdef void *a
    if not sim.batched or need <= sim.lists.sbk_cap:
        return 0
    a = grow(sim.lists.sb_k, cap * sizeof(int))
    if a == NULL:
        return -1
    sim.lists.sb_k = <int*>a
    a = grow(sim.lists.sb_i, cap * sizeof(int))
    if a == NULL:
        return -1
    sim.lists.sb_i = <int*>a
    sim.lists.sbk_cap = cap
    return 0


cdef int reserve_pairs(State* sim, long long need) noexcept nogil:
    """Grow the current neighbour list to ``need`` pairs; -1 when out of memory."""
    cdef long long cap = room(need)
    cdef void *a
    if need <= sim.lists.nb_cap:
        return 0
    a = grow(sim.lists.nb_j, cap * sizeof(int))
    if a == NULL:
        return -1
    sim.lists.nb_j = <int*>a
    a = grow(sim.lists.nb_s, cap * sizeof(uint8_t))
    if a == NULL:
        return -1
    sim.lists.nb_s = <uint8_t*>a
    a = grow(sim.lists.nb_c, cap * sizeof(int))
    if a == NULL:
        return -1
    sim.lists.nb_c = <int*>a
    sim.lists.nb_cap = cap
    return 0


cdef int reserve_walls(State* sim, long long need) noexcept nogil:
    """Grow the current wall list (and the wall contacts' records) to ``need`` entries; -1 when
    out of memory."""
    cdef long long cap = room(need)
    cdef void *a
    cdef void *b
    if sim.contacts.recording and need > sim.lists.wlf_cap:
        a = grow(sim.lists.wl_f, cap * WLF * sizeof(double))
        if a == NULL:
            return -1
        sim.lists.wl_f = <double*>a
        sim.lists.wlf_cap = cap
    if need <= sim.lists.wl_cap:
        return 0
    a = grow(sim.lists.wl_e, cap * sizeof(int))
    if a == NULL:
        return -1
    sim.lists.wl_e = <int*>a
    b = grow(sim.lists.wl_h, cap * (sim.hs + 1) * sizeof(double))
    if b == NULL:
        return -1
    sim.lists.wl_h = <double*>b
    sim.lists.wl_cap = cap
    return 0


cdef inline int place_particle(State* sim, int i) noexcept nogil:
    """Wrap particle i into the periodic box; its cell, -1 if lost, -2 if removed."""
    cdef int d
    cdef double p
    if sim.particles.type[i] < 0:
        return -2
    for d in range(3):
        p = sim.particles.x[3 * i + d]
        if not isfinite(p):
            return -1
        if sim.per[d]:
            if p < sim.lo[d] or p >= sim.hi[d]:
                p -= sim.L[d] * floor((p - sim.lo[d]) / sim.L[d])
                if p >= sim.hi[d]:
                    p = sim.lo[d]
                sim.particles.x[3 * i + d] = p
        elif p < sim.lo[d] or p > sim.hi[d]:
            return -1
    return cell_of(sim, &sim.particles.x[3 * i])


cdef void count_lost(State* sim, int i) noexcept nogil:
    """Count lost particle i at the face of the box it is furthest beyond (or as non-finite),
    and its speed."""
    cdef int d, place = 6
    cdef double p, beyond = 0.0, speed = 0.0
    for d in range(3):
        if not (isfinite(sim.particles.x[3 * i + d]) and isfinite(sim.particles.v[3 * i + d])):
            sim.lost_at[6] += 1
            return
        speed += sim.particles.v[3 * i + d] * sim.particles.v[3 * i + d]
    for d in range(3):
        p = sim.particles.x[3 * i + d]
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
    for e in range(sim.walls.ne):
        if sim.walls.emoving[e]:
            return True
    return False


cdef void permute(State* sim, int n) noexcept nogil:
    """Reorder the particle arrays by ``perm`` in three parallel passes. f, t and x0 are
    recomputed after a rebuild, so they serve as scratch: x, v and w are gathered into them
    and swapped with them; r, m, type, pid (and with clumps mem) are gathered into the old x
    and v, then copied back while x0 becomes a copy of x (see rebuild_rows); the fill clears f
    and t for the pair loop."""
    cdef double* p
    parallel_rows(sim, P_GATHER, n)
    p = sim.particles.x; sim.particles.x = sim.particles.f; sim.particles.f = p
    p = sim.particles.v; sim.particles.v = sim.particles.t; sim.particles.t = p
    p = sim.particles.w; sim.particles.w = sim.particles.x0; sim.particles.x0 = p
    parallel_rows(sim, P_GATHER_SCALARS, n)
    parallel_rows(sim, P_COPY_BACK, n)


cdef void rebuild_rows(State* sim, int phase, int lo, int hi, int b) noexcept nogil:
    """Rows [lo, hi), block b, of a parallel pass of the rebuild (and bodies [lo, hi) of a body
    loop, which the team hands out as rows too)."""
    cdef int i, d, n = sim.schedule.rows, j, cnt
    cdef long long k, x, pos = 0, kept = 0, breaks = 0, last = -2
    cdef Found* found = &sim.lists.found[b]
    cdef int* perm = sim.particles.perm
    cdef double* sr = sim.particles.f
    cdef double* sm = sim.particles.f + n
    cdef int* st = <int*>(sim.particles.f + 2 * n)
    cdef int* sb = st + n
    cdef int64_t* sp = <int64_t*>sim.particles.t
    if phase == P_BODIES or phase == P_BODY_DRIFT:
        body_rows(sim, phase, lo, hi)
    elif phase == P_PLACE:
        for i in range(lo, hi):
            sim.particles.cell[i] = place_particle(sim, i)
    elif phase == P_GATHER:   # into f, t, x0 (swapped with x, v, w afterwards)
        for i in range(lo, hi):
            for d in range(3):
                sim.particles.f[3 * i + d] = sim.particles.x[3 * perm[i] + d]
                sim.particles.t[3 * i + d] = sim.particles.v[3 * perm[i] + d]
                sim.particles.x0[3 * i + d] = sim.particles.w[3 * perm[i] + d]
    elif phase == P_GATHER_SCALARS:
        for i in range(lo, hi):
            sr[i] = sim.particles.r[perm[i]]
            sm[i] = sim.particles.m[perm[i]]
            st[i] = sim.particles.type[perm[i]]
            sp[i] = sim.particles.pid[perm[i]]
            if sim.clumps.nbody:
                sb[i] = sim.particles.mem[perm[i]]
    elif phase == P_COPY_BACK:
        for i in range(lo, hi):
            sim.particles.r[i] = sr[i]
            sim.particles.m[i] = sm[i]
            sim.particles.type[i] = st[i]
            sim.particles.pid[i] = sp[i]
            if sim.clumps.nbody:
                sim.particles.mem[i] = sb[i]
            for d in range(3):
                sim.particles.x0[3 * i + d] = sim.particles.x[3 * i + d]
    elif phase == P_COUNT:   # the pairs go to the block's Found, the fill copies them
        found.failed = 0
        x = 0
        for i in range(lo, hi):
            if sim.particles.r[i] > sim.lists.rsplit:
                cnt = scan_big(sim, i, found, pos)
            else:
                cnt = scan_pairs(sim, i, found, pos)
                while x < sim.lists.nextra and sim.lists.extra[x].i < i:
                    x += 1
                while cnt >= 0 and x < sim.lists.nextra and sim.lists.extra[x].i == i:
                    cnt = add_found(found, pos, cnt, sim.lists.extra[x].j, sim.lists.extra[x].s)
                    x += 1
            if cnt < 0:
                found.failed = 1
                cnt = 0
            pos += cnt
            sim.lists.nb_start[i + 1] = cnt
            sim.lists.wl_start[i + 1] = scan_walls(sim, i, False)
    elif phase == P_FILL:   # also marks the kept slots in the contact table's free list
        pos = sim.lists.nb_start[lo]
        for i in range(lo, hi):
            for k in range(sim.lists.nb_start[i], sim.lists.nb_start[i + 1]):
                j = found.j[k - pos]
                sim.lists.nb_j[k] = j
                sim.lists.nb_s[k] = found.s[k - pos] | carry_pair(sim, i, j, &sim.lists.nb_c[k])
                if sim.lists.nb_c[k] >= 0:
                    sim.contacts.free[sim.lists.nb_c[k]] = 1
                    kept += 1
                    breaks += sim.lists.nb_c[k] != last + 1
                    last = sim.lists.nb_c[k]
            scan_walls(sim, i, True)
            sim.schedule.work[i] = estimated_work(sim, i)
            find_partners(sim, i)
            clear_forces(sim, i)
        found.kept = kept   # once: the blocks' Found share cache lines
        found.breaks = breaks


cdef inline void find_partners(State* sim, int i) noexcept nogil:
    """Row i's largest near partner (``last``, -1: none) and its smallest and largest far
    partner (``flo``, ``fhi``; INT_MAX and -1: none), see Halo."""
    cdef int k, j
    sim.lists.last[i] = -1
    sim.lists.flo[i] = INT_MAX
    sim.lists.fhi[i] = -1
    for k in range(sim.lists.nb_start[i], sim.lists.nb_start[i + 1]):
        j = sim.lists.nb_j[k]
        if sim.lists.nb_s[k] & WRAP:
            sim.lists.flo[i] = min(sim.lists.flo[i], j)
            sim.lists.fhi[i] = max(sim.lists.fhi[i], j)
        elif j > sim.lists.last[i]:
            sim.lists.last[i] = j


cdef void prefix_last(State* sim) noexcept nogil:
    """``last``: from each row's largest near partner to the largest of the rows up to it;
    ``nfar`` after the last row with a far partner."""
    cdef int i
    sim.lists.nfar = 0
    for i in range(sim.particles.n):
        if i > 0 and sim.lists.last[i - 1] > sim.lists.last[i]:
            sim.lists.last[i] = sim.lists.last[i - 1]
        if sim.lists.fhi[i] >= 0:
            sim.lists.nfar = i + 1


cdef int rebuild(State* sim) noexcept nogil:
    """Wrap, drop lost particles (a clump whole), sort into cells, rebuild both lists carrying
    histories."""
    cdef int i, d, n = sim.particles.n, nnew, dead = 0
    cdef long long lost = 0
    cdef double rmax = 0.0, rmin = INFINITY
    cdef int *ip
    cdef uint8_t *bp
    cdef double *dp
    cdef long long cap
    cdef double t0 = pg_now(), t1
    for i in range(n):
        rmax = max(rmax, sim.particles.r[i])
        rmin = min(rmin, sim.particles.r[i])
    sim.lists.rsplit = split_radius(sim, rmin, rmax)
    if setup_cells(sim, sim.lists.rsplit) < 0:
        return -1
    if sim.lists.rsplit < rmax and not box_fits(sim, rmax):
        sim.lists.rsplit = rmax
        if setup_cells(sim, rmax) < 0:
            return -1
    if sim.lists.rsplit >= rmax:
        sim.lists.rsplit = INFINITY
    if sim.walls.binned_dirty or sim.walls.binned_reach != rmax + sim.skin or any_moving(sim) \
            or sim.walls.binned_nc[0] != sim.lists.nc[0] or sim.walls.binned_nc[1] != sim.lists.nc[1] or sim.walls.binned_nc[2] != sim.lists.nc[2]:
        if bin_triangles(sim, rmax + sim.skin) < 0:
            return -1
        sim.walls.binned_dirty = 0
        sim.walls.binned_reach = rmax + sim.skin
        for d in range(3):
            sim.walls.binned_nc[d] = sim.lists.nc[d]
    t1 = lap(sim, T_CELLS, t0)
    # wrap periodic coordinates, mark particles outside a fixed boundary (or removed) lost
    if sim.clumps.nbody:
        place_bodies(sim)
    parallel_rows(sim, P_PLACE, n)
    if sim.clumps.nbody:
        dead = mark_dead_bodies(sim, &lost)
    for i in range(n):
        if sim.particles.cell[i] < 0:
            if sim.particles.cell[i] == -1:
                lost += 1
                count_lost(sim, i)
            sim.particles.cell[i] = sim.lists.ncells
    sim.lost += lost
    # counting sort by cell (lost ones in the sentinel cell ncells)
    memset(sim.lists.cell_start, 0, (sim.lists.ncells + 2) * sizeof(int))
    for i in range(n):
        sim.lists.cell_start[sim.particles.cell[i] + 1] += 1
    for i in range(sim.lists.ncells + 1):
        sim.lists.cell_start[i + 1] += sim.lists.cell_start[i]
    for i in range(n):
        sim.particles.perm[sim.lists.cell_start[sim.particles.cell[i]]] = i
        sim.lists.cell_start[sim.particles.cell[i]] += 1
    for i in range(sim.lists.ncells + 1, 0, -1):
        sim.lists.cell_start[i] = sim.lists.cell_start[i - 1]
    sim.lists.cell_start[0] = 0
    nnew = sim.lists.cell_start[sim.lists.ncells]
    t1 = lap(sim, T_SORT, t1)
    permute(sim, nnew)
    sim.particles.n = nnew
    if sim.clumps.nbody:
        if dead and drop_bodies(sim, nnew) < 0:
            return -1
        find_members(sim)
    t1 = lap(sim, T_PERMUTE, t1)
    # the current lists become the previous ones
    ip = sim.lists.ob_start; sim.lists.ob_start = sim.lists.nb_start; sim.lists.nb_start = ip
    ip = sim.lists.ob_j; sim.lists.ob_j = sim.lists.nb_j; sim.lists.nb_j = ip
    bp = sim.lists.ob_s; sim.lists.ob_s = sim.lists.nb_s; sim.lists.nb_s = bp
    ip = sim.lists.ob_c; sim.lists.ob_c = sim.lists.nb_c; sim.lists.nb_c = ip
    cap = sim.lists.ob_cap; sim.lists.ob_cap = sim.lists.nb_cap; sim.lists.nb_cap = cap
    ip = sim.lists.ow_start; sim.lists.ow_start = sim.lists.wl_start; sim.lists.wl_start = ip
    ip = sim.lists.ow_e; sim.lists.ow_e = sim.lists.wl_e; sim.lists.wl_e = ip
    dp = sim.lists.ow_h; sim.lists.ow_h = sim.lists.wl_h; sim.lists.wl_h = dp
    cap = sim.lists.ow_cap; sim.lists.ow_cap = sim.lists.wl_cap; sim.lists.wl_cap = cap
    if find_big(sim) < 0:
        return -1
    lend_found(sim)
    parallel_rows(sim, P_COUNT, nnew)
    for i in range(sim.schedule.nblocks):
        if sim.lists.found[i].failed:
            return -1
    sim.lists.nb_start[0] = 0
    sim.lists.wl_start[0] = 0
    for i in range(nnew):
        sim.lists.nb_start[i + 1] += sim.lists.nb_start[i]
        sim.lists.wl_start[i + 1] += sim.lists.wl_start[i]
    if reserve_pairs(sim, sim.lists.nb_start[nnew]) < 0 or reserve_walls(sim, sim.lists.wl_start[nnew]) < 0:
        return -1
    t1 = lap(sim, T_COUNT, t1)
    memset(sim.contacts.free, 0, sim.contacts.n * sizeof(int))
    parallel_rows(sim, P_FILL, nnew)
    if sim.batched:   # the found pairs are copied: the sublist's arrays are free for it
        for i in range(sim.schedule.nblocks):
            release_found(&sim.lists.found[i])
    if renew_slots(sim, sim.lists.nb_start[nnew]) < 0 or reserve_sublist(sim, sim.lists.nb_start[nnew]) < 0:
        return -1
    prefix_last(sim)
    for i in range(9 * sim.walls.ne):
        sim.walls.ebuilt[i] = sim.walls.egeo[i]
    balance(sim)
    lap(sim, T_FILL, t1)
    lap(sim, T_REBUILD, t0)
    sim.rebuilds += 1
    sim.lists.sub_build = 1
    sim.travel = 0.0
    sim.since = 0
    return 0


cdef inline bint in_contact(State* sim, int k) noexcept nogil:
    return sim.lists.nb_s[k] & TOUCH and (sim.model != THORNTON_NING or pair_history(sim, k, NO_HISTORY)[H_DMAX] > 0.0)
