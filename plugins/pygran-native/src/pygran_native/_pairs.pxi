# The pair loop: forces of a particle's listed pairs and wall elements, per block.

cdef inline int row_work(int listed, int touching, int walls) noexcept nogil:
    """Work of a row of the pair loop, in units of a listed pair that is apart."""
    return WROW + listed + WTOUCH * (touching + walls)


cdef struct Sink:
    # Where a block of the pair loop adds forces on a partner row j: the row's own f and t for
    # its own rows (j < own), else the block's halo (see Halo): near rows from entry near + j,
    # far rows from entry far + j.
    double* f
    double* t
    double* halo
    long long near, far
    int own, near_end


cdef inline Sink block_sink(const State* c, int b) noexcept nogil:
    cdef const Halo* hb = &c.lists.halos[b]
    cdef Sink s
    s.f = c.particles.f
    s.t = c.particles.t
    s.halo = c.lists.halo
    s.own = c.schedule.pb[b + 1]
    s.near_end = hb.near_end
    s.near = hb.near_off - s.own
    s.far = hb.far_off - hb.far_lo
    return s


cdef inline double* partner_row(const Sink* s, int j, int* hmax, double** torque) noexcept nogil:
    """Where the force on partner row j goes (3 values), and its torque (``torque``; ``hmax``:
    the last near halo row)."""
    cdef double* p
    if j < s.own:
        torque[0] = &s.t[3 * j]
        return &s.f[3 * j]
    if j <= s.near_end:
        if j > hmax[0]:
            hmax[0] = j
        p = &s.halo[(s.near + j) * 6]
    else:
        p = &s.halo[(s.far + j) * 6]
    torque[0] = p + 3
    return p


cdef inline int finish_row(const State* c, int i, int b, const double* fi, int touching) noexcept nogil:
    """Add row i's pair sums ``fi`` and its walls' forces to its f and t; returns its work. A
    row without contacts or walls adds nothing: its sums are +0.0, and f and t never hold -0.0
    in the pair loop (they start at +0.0 and only add and subtract), so adding them would change
    no bit."""
    cdef int q, walls = c.lists.wl_start[i + 1] - c.lists.wl_start[i]
    cdef double F[3]
    cdef double T[3]
    if touching or walls:
        for q in range(3):   # walls into other arrays: fi can live in registers while pairs add up
            F[q] = 0.0
            T[q] = 0.0
        if walls:
            wall_row(c, i, F, T, &c.walls.sacc[<long long>SACC * c.walls.nslots * b])
        for q in range(3):
            c.particles.f[3 * i + q] += fi[q] + F[q]
            c.particles.t[3 * i + q] += fi[3 + q] + T[q]
    return row_work(c.lists.nb_start[i + 1] - c.lists.nb_start[i], touching, walls)


cdef int pair_row(const State* c, int i, int b, int* hmax) noexcept nogil:
    """Forces of particle i's half-list contacts and walls; returns the row's work.

    Block ``b`` owns the rows up to ``pb[b + 1]``: forces on them are added into their ``f``
    and ``t``, forces on later rows to the block's halo buffers in ``halo`` (see Halo; ``hmax``:
    the last row it wrote to the near one).
    """
    # locals: the flag store through uint8_t* may alias anything, including *c
    cdef const double* x = c.particles.x
    cdef const double* v = c.particles.v
    cdef const double* w = c.particles.w
    cdef const double* r = c.particles.r
    cdef const double* m = c.particles.m
    cdef const int* typ = c.particles.type
    cdef const int* nb_j = c.lists.nb_j
    cdef uint8_t* nb_s = c.lists.nb_s
    cdef const int* nb_c = c.lists.nb_c
    cdef const double* ct_h = c.contacts.h
    cdef const double* shiftv = &c.shiftv[0]
    cdef const Coef* coef = c.coef + c.particles.type[i] * c.ntypes
    cdef Sink sink = block_sink(c, b)
    cdef int hs = c.hs, model = c.model, rolling = c.rolling, roff = c.roff, update = c.update
    cdef int k, j, q, res, slot, kend = c.lists.nb_start[i + 1]
    cdef int touching = 0
    cdef double dt = c.dt
    cdef double d[3]
    cdef double n[3]
    cdef double vr[3]
    cdef double rw[3]
    cdef double wrel[3]
    cdef double F[3]
    cdef double Ft[3]
    cdef double Mr[3]
    cdef double cx[3]
    cdef double fi[6]
    cdef double xi[3]
    cdef double vi[3]
    cdef double wi[3]
    cdef double fresh[MAXHS]   # the history of a pair not in contact before (see Contacts)
    cdef double cri, crj, delta, dist2, inv, rs, Rs, ms, ri = r[i], mi = m[i], rj, mj, den, Ii = mi * ri * ri, Ir = 0.0
    cdef double* h
    cdef double* rec
    cdef double* bj
    cdef double* tj
    cdef const double* sv
    for q in range(3):
        xi[q] = x[3 * i + q]
        vi[q] = v[3 * i + q]
        wi[q] = w[3 * i + q]
    for q in range(6):
        fi[q] = 0.0
    for k in range(c.lists.nb_start[i], kend):
        j = nb_j[k]
        sv = &shiftv[3 * (nb_s[k] & IMAGE)]
        for q in range(3):
            d[q] = xi[q] - x[3 * j + q] + sv[q]
        dist2 = dot3(d, d)
        rj = r[j]
        rs = ri + rj
        slot = nb_c[k]
        if dist2 >= rs * rs and not (model == THORNTON_NING and slot >= 0
                                     and ct_h[<long long>slot * hs + H_DMAX] > 0.0):   # apart (adhesion stretches)
            if nb_s[k] & TOUCH:
                forget_pair(c, b, k)
            continue
        inv = 1.0 / sqrt(dist2)
        mj = m[j]
        delta = rs - dist2 * inv
        cri = ri - 0.5 * delta   # levers to the contact point (LIGGGHTS' surface model)
        crj = rj - 0.5 * delta
        for q in range(3):
            n[q] = d[q] * inv
            vr[q] = vi[q] - v[3 * j + q]
            rw[q] = cri * wi[q] + crj * w[3 * j + q]
            wrel[q] = wi[q] - w[3 * j + q]
        den = 1.0 / (rs * (mi + mj))
        Rs = ri * rj * (mi + mj) * den
        ms = mi * mj * rs * den
        if rolling == EPSD:   # 1.4 (m_i r_i^2)(m_j r_j^2) / (m_i r_i^2 + m_j r_j^2), as LIGGGHTS
            Ir = 1.4 * Ii * mj * rj * rj / (Ii + mj * rj * rj)
        if slot >= 0:
            h = slot_history(c, slot)
        else:
            memset(fresh, 0, hs * sizeof(double))
            h = fresh
        res = contact_force(model, rolling, roff, &coef[typ[j]], delta, Rs, ms, Ir, n, vr, rw,
                            wrel, h, dt, update, F, Ft, Mr)
        if res == NO_CONTACT:
            forget_pair(c, b, k)
            continue
        if slot < 0:
            slot = new_contact(c, b, k, h)
        rec = record_of(c, b, slot)
        if res != IN_CONTACT:   # Thornton-Ning's memory: no force now (see Core.contact_forces)
            if rec != NULL and nb_s[k] & TOUCH:
                memset(rec, 0, 3 * sizeof(double))
            continue
        nb_s[k] |= TOUCH
        touching += 1
        cross3(n, Ft, cx)
        bj = partner_row(&sink, j, hmax, &tj)
        if rec != NULL:
            for q in range(3):
                rec[q] = F[q]
        for q in range(3):
            fi[q] += F[q]
            fi[3 + q] += Mr[q] - cri * cx[q]
            bj[q] -= F[q]
            tj[q] -= Mr[q] + crj * cx[q]
    return finish_row(c, i, b, fi, touching)


cdef int wall_contact(const State* c, int i, int e, double* h, double delta, const double* n,
                      const double* q, double* F, double* T, double* sa, double* fc) noexcept nogil:
    """Force of wall element e on particle i (contact point q, NULL for a fixed primitive).

    Returns the :func:`contact_force` result; clears the history on NO_CONTACT. In contact, the
    force is added to F (its torque to T) and put in ``fc``; the force on a stress mesh's
    element is added, reversed, to the block's sums ``sa`` (see Slot).
    """
    cdef double vr[3]
    cdef double rw[3]
    cdef double vw[3]
    cdef double Fc[3]
    cdef double Ft[3]
    cdef double Mr[3]
    cdef double cx[3]
    cdef double rel[3]
    cdef const double* sl = NULL
    cdef int k, res, slot = slot_of(c, e) if q != NULL else -1
    cdef double ri = c.particles.r[i], cr = ri - 0.5 * delta   # cr: the lever to the contact point, as LIGGGHTS has it
    if slot >= 0:
        sl = &c.walls.slots[NSLOT * slot]
    wall_velocity(c, e, q, sl, vw)
    for k in range(3):
        vr[k] = c.particles.v[3 * i + k] - vw[k]
        rw[k] = cr * c.particles.w[3 * i + k]
    res = contact_force(c.model, c.rolling, c.roff, &c.coef[c.particles.type[i] * c.ntypes + c.walls.etype[e]], delta, ri,
                        c.particles.m[i], 1.4 * c.particles.m[i] * ri * ri, n, vr, rw, &c.particles.w[3 * i], h, c.dt, c.update, Fc, Ft, Mr)
    if res == NO_CONTACT:
        zero_hist(h, c.whs)
    if res != IN_CONTACT:
        return res
    cross3(n, Ft, cx)
    for k in range(3):
        F[k] += Fc[k]
        T[k] += Mr[k] - cr * cx[k]
        fc[k] = Fc[k]
    if sl != NULL:   # LIGGGHTS: the reversed force, and its torque about com at the contact point
        sa = &sa[SACC * slot]
        for k in range(3):
            rel[k] = q[k] - sl[S_XCM + k]
            Fc[k] = -Fc[k]
        cross3(rel, Fc, cx)
        for k in range(3):
            sa[A_FORCE + k] += Fc[k]
            sa[A_TORQUE + k] += cx[k]
        sa[A_CONTACTS] += 1.0
    return IN_CONTACT


cdef void wall_row(const State* c, int i, double* F, double* T, double* sa) noexcept nogil:
    """Wall forces on particle i; mesh contacts without double counting. Each entry's record
    in ``wl_f`` (WLF values) says whether it is a contact and, if so, gives its force and its
    contact point on the wall (a triangle's closest point, a primitive's foot point).

    Candidates are the triangles whose closest point is within reach, classified as
    face, edge or vertex contacts, taken faces first, each kind nearest first. A face contact
    is dropped when an accepted one has the same contact point (to 1e-9 of the radius: a
    centre right above the edge two coplanar triangles share, which rounding may put inside
    both); an edge or vertex contact when an accepted contact's triangle has that edge or
    vertex, or lies in the plane of this one's triangle with this contact point on it (a
    flat surface is touched once however many of its triangles the sphere reaches; a shared
    edge or vertex of a convex surface counts once; concave corners give one contact per face).
    """
    cdef int k, e, a, b, nc = 0, nacc = 0, reg, u, w2, ok, res, hs = c.hs
    cdef int ck[MAXCAND]
    cdef int creg[MAXCAND]
    cdef int cfeat[MAXCAND]
    cdef int acc[MAXCAND]
    cdef uint8_t done[MAXCAND]
    cdef double cq[3 * MAXCAND]
    cdef double cd2[MAXCAND]
    cdef double gap, d2, dist, side = 1.0
    cdef double nrm[3]
    cdef double* h
    cdef double* rec
    cdef double scratch[WLF]   # the records of a pass that does not record (see State.record)
    cdef const double* g
    cdef const double* xi = &c.particles.x[3 * i]
    cdef double ri = c.particles.r[i]
    for k in range(c.lists.wl_start[i], c.lists.wl_start[i + 1]):
        e = c.lists.wl_e[k]
        h = &c.lists.wl_h[<long long>k * c.whs]
        rec = &c.lists.wl_f[<long long>k * WLF] if c.record else scratch
        rec[6] = 0.0
        g = &c.walls.egeo[9 * e]
        if c.walls.ekind[e] != TRIANGLE:
            gap = primitive_gap(c.walls.ekind[e], g, xi, nrm)
            if c.walls.ekind[e] == PLANE:   # the contact's side, or the centre's for a new contact
                side = h[hs] if h[hs] != 0.0 else (1.0 if gap >= 0.0 else -1.0)
                gap *= side
                for a in range(3):
                    nrm[a] *= side
            if gap < -ri:   # behind the wall: passed through it
                zero_hist(h, c.whs)
                continue
            res = wall_contact(c, i, e, h, ri - gap, nrm, NULL, F, T, sa, rec)
            if res != NO_CONTACT and c.walls.ekind[e] == PLANE and c.update:
                h[hs] = side
            if res == IN_CONTACT:
                for a in range(3):
                    rec[3 + a] = xi[a] - gap * nrm[a]
                rec[6] = 1.0
            continue
        creg[nc] = closest_on_triangle(xi, g, g + 3, g + 6, &cq[3 * nc], &cfeat[nc])
        d2 = (xi[0] - cq[3 * nc]) ** 2 + (xi[1] - cq[3 * nc + 1]) ** 2 + (xi[2] - cq[3 * nc + 2]) ** 2
        if (d2 >= ri * ri and not (c.model == THORNTON_NING and h[H_DMAX] > 0.0)) or d2 == 0.0 or nc == MAXCAND:
            zero_hist(h, c.whs)
            continue
        cd2[nc] = d2
        ck[nc] = k
        nc += 1
    memset(done, 0, MAXCAND)
    for reg in range(3):
        while True:   # the nearest candidate of this kind not taken yet
            a = -1
            for b in range(nc):
                if creg[b] == reg and not done[b] and (a < 0 or cd2[b] < cd2[a]):
                    a = b
            if a < 0:
                break
            done[a] = 1
            k = ck[a]
            e = c.lists.wl_e[k]
            h = &c.lists.wl_h[<long long>k * c.whs]
            ok = 1
            if reg == FACE:
                for b in range(nacc):
                    d2 = ((cq[3 * a] - cq[3 * acc[b]]) ** 2 + (cq[3 * a + 1] - cq[3 * acc[b] + 1]) ** 2
                          + (cq[3 * a + 2] - cq[3 * acc[b] + 2]) ** 2)
                    if d2 <= 1e-18 * ri * ri:
                        ok = 0
                        break
            else:
                u = c.walls.evid[3 * e + cfeat[a]]
                w2 = c.walls.evid[3 * e + (cfeat[a] + 1) % 3]
                for b in range(nacc):
                    if has_vertex(&c.walls.evid[3 * c.lists.wl_e[ck[acc[b]]]], u) and (
                            reg == VERTEX or has_vertex(&c.walls.evid[3 * c.lists.wl_e[ck[acc[b]]]], w2)) \
                            or coplanar(&c.walls.egeo[9 * e], &c.walls.egeo[9 * c.lists.wl_e[ck[acc[b]]]], &cq[3 * a], 1e-9 * ri):
                        ok = 0
                        break
            if not ok:
                zero_hist(h, c.whs)
                continue
            dist = sqrt(cd2[a])
            for b in range(3):
                nrm[b] = (xi[b] - cq[3 * a + b]) / dist
            rec = &c.lists.wl_f[<long long>k * WLF] if c.record else scratch
            if wall_contact(c, i, e, h, ri - dist, nrm, &cq[3 * a], F, T, sa, rec) == IN_CONTACT:
                acc[nacc] = a
                nacc += 1
                memcpy(&rec[3], &cq[3 * a], 3 * sizeof(double))
                rec[6] = 1.0


cdef struct Gather:
    # What the gather (gather_row, gather_sublists) reads of the state, copied once per block
    # into batched_rows' frame. Read through State*, it was loaded again for every row, since a
    # store through the flag bytes (nb_s) may alias the state; the copy made the settle
    # scenario's settling phase about 4 % faster at N = 20,000.
    const double* x
    const double* v
    const double* w
    const double* r
    const double* m
    const int* type
    const int* nb_start
    const int* nb_j
    const uint8_t* nb_s
    const int* nb_c
    const double* ct_h
    int* sb_k
    int* sb_i
    int* sb_n
    int* sb_at
    const double* shiftv
    const Coef* coef
    int ntypes, hs
    int block          # the pair block
    double margin


cdef inline Gather gather_state(const State* c, int b) noexcept nogil:
    """The state as the gather reads it, for pair block b of one pass of the pair loop."""
    cdef Gather g
    g.x = c.particles.x
    g.v = c.particles.v
    g.w = c.particles.w
    g.r = c.particles.r
    g.m = c.particles.m
    g.type = c.particles.type
    g.nb_start = c.lists.nb_start
    g.nb_j = c.lists.nb_j
    g.nb_s = c.lists.nb_s
    g.nb_c = c.lists.nb_c
    g.ct_h = c.contacts.h
    g.sb_k = c.lists.sb_k
    g.sb_i = c.lists.sb_i
    g.sb_n = c.lists.sb_n
    g.sb_at = c.lists.sb_at
    g.shiftv = &c.shiftv[0]
    g.coef = c.coef
    g.ntypes = c.ntypes
    g.hs = c.hs
    g.block = b
    g.margin = SUB_SKIN * c.skin
    return g


cdef inline void fill_entries(const Gather* g, pg_pair_batch* bt, int first, int n, const int* slots,
                              const int* partners, const int* rows, int row0) noexcept nogil:
    """Entries first..n-1 of the batch, whose distances gather_row or gather_sublists wrote:
    the rest of what pg_hertz_batch reads (entry t's row is row0 + ``rows[t]``, its contact
    slot ``slots[t]``)."""
    cdef int t, q, i, j
    cdef const double* h
    cdef const Coef* cf
    for t in range(first, n):
        i = row0 + rows[t]
        j = partners[t]
        h = &g.ct_h[<long long>slots[t] * g.hs] if slots[t] >= 0 else NO_HISTORY
        for q in range(3):
            bt.vr[q * PG_BATCH + t] = g.v[3 * i + q] - g.v[3 * j + q]
            bt.wi[q * PG_BATCH + t] = g.w[3 * i + q]
            bt.wj[q * PG_BATCH + t] = g.w[3 * j + q]
            bt.xi[q * PG_BATCH + t] = h[H_SHEAR + q]
        bt.ri[t] = g.r[i]
        bt.mi[t] = g.m[i]
        bt.mj[t] = g.m[j]
        if g.ntypes == 1:   # pg_hertz_batch takes them once
            continue
        cf = &g.coef[g.type[i] * g.ntypes + g.type[j]]
        bt.E[t] = cf.E
        bt.G[t] = cf.G
        bt.mu[t] = cf.mu
        bt.damp[t] = cf.damp
        bt.tdamp[t] = cf.tdamp
        bt.coh[t] = cf.coh
        bt.limit[t] = cf.limit


cdef inline int gather_entry(const State* c, const Gather* g, int k, int i, const double* xi, double ri,
                             pg_pair_batch* bt, int n, int* keys, int* slots, int* partners,
                             double* dist2) noexcept nogil:
    """Listed pair k of row i (at ``xi``, radius ``ri``) written to entry n of the batch (its
    distance and partner's radius, ``keys``, ``slots``, ``partners``), and its squared distance
    to ``dist2``; clears it if it came apart. Returns whether it is within reach (then entry n
    is kept). No branch on the reach test, whose outcome the CPU cannot predict."""
    cdef int q, j = g.nb_j[k], within, touched, slot
    cdef double rj = g.r[j]
    cdef double d[3]
    cdef const double* sv = &g.shiftv[3 * (g.nb_s[k] & IMAGE)]
    for q in range(3):
        d[q] = xi[q] - g.x[3 * j + q] + sv[q]
        bt.d[q * PG_BATCH + n] = d[q]
    dist2[0] = dot3(d, d)
    bt.dist2[n] = dist2[0]
    bt.rj[n] = rj
    keys[n] = k
    partners[n] = j
    within = not (dist2[0] >= (ri + rj) * (ri + rj))   # NaN: within, as pair_row has it
    slot = slots[n] = g.nb_c[k]   # its history, which fill_entries reads after the batch's gather
    pg_prefetch(&g.ct_h[<long long>(slot if slot > 0 else 0) * g.hs])
    touched = (g.nb_s[k] & TOUCH) != 0
    if touched > within:   # one rarely taken branch: apart now, touching before
        forget_pair(c, g.block, k)
    return within


cdef int gather_row(const State* c, const Gather* g, int i, int row0, int* at, pg_pair_batch* bt, int n,
                    int* keys, int* slots, int* partners, int* rows) noexcept nogil:
    """Append particle i's listed pairs within reach to the batch from entry n (their indices
    in ``keys``, contact slots in ``slots``, partners in ``partners``, i - row0 in ``rows``) and
    make its sublist (State.sb_k) from entry ``at[0]``, which it advances; clears the pairs that
    came apart. Returns the new entry count."""
    cdef int k, q, within, first = n, kept = 0, pos = at[0]
    cdef double ri = g.r[i], dist2, reach
    cdef double xi[3]
    for q in range(3):
        xi[q] = g.x[3 * i + q]
    for k in range(g.nb_start[i], g.nb_start[i + 1]):
        rows[n] = i - row0
        within = gather_entry(c, g, k, i, xi, ri, bt, n, keys, slots, partners, &dist2)
        reach = ri + bt.rj[n] + g.margin
        n += within
        g.sb_k[pos + kept] = k
        g.sb_i[pos + kept] = i
        kept += not (dist2 >= reach * reach)
    g.sb_at[i] = pos
    g.sb_n[i] = kept
    at[0] = pos + kept
    fill_entries(g, bt, first, n, slots, partners, rows, row0)
    return n


cdef int gather_sublists(const State* c, const Gather* g, int e0, int e1, int row0, pg_pair_batch* bt,
                         int* keys, int* slots, int* partners, int* rows) noexcept nogil:
    """The pairs within reach among sublist entries e0..e1-1 (the sublists of a run of rows
    from row0, see State.sb_k) written to the batch from entry 0, as gather_row writes them;
    ``rows``: each entry's row less row0. Returns the entry count. One loop over the run's
    entries, not one per row: a row's sublist length is as unpredictable as its contacts."""
    cdef int e, i, k, q, n = 0
    cdef double dist2
    cdef double xi[3]
    for e in range(e0, e1):
        k = g.sb_k[e]
        i = g.sb_i[e]
        for q in range(3):
            xi[q] = g.x[3 * i + q]
        rows[n] = i - row0
        n += gather_entry(c, g, k, i, xi, g.r[i], bt, n, keys, slots, partners, &dist2)
    fill_entries(g, bt, 0, n, slots, partners, rows, row0)
    return n


cdef long long add_rows(const State* c, int b, const pg_pair_batch* bt, const int* keys, const int* slots,
                        const int* ends, int first, int nrows, int* hmax) noexcept nogil:
    """Add up the batch's forces for rows first..first+nrows-1 (row r's entries end at
    ``ends[r]``), in pair_row's order, with their walls; returns their work."""
    cdef Sink sink = block_sink(c, b)
    cdef int r, i, t = 0, k, q, touching, slot
    cdef long long total = 0
    cdef double fi[6]
    cdef double fresh[MAXHS]   # the history of a pair not in contact before (see Contacts)
    cdef double* h
    cdef double* rec
    cdef double* bj
    cdef double* tj
    for r in range(nrows):
        i = first + r
        touching = 0
        for q in range(6):
            fi[q] = 0.0
        while t < ends[r]:
            k = keys[t]
            if bt.touch[t] == 0.0:
                forget_pair(c, b, k)
                t += 1
                continue
            slot = slots[t]
            if slot >= 0:
                h = slot_history(c, slot)
            else:
                memset(fresh, 0, c.hs * sizeof(double))
                h = fresh
            for q in range(3):
                h[H_SHEAR + q] = bt.xi[q * PG_BATCH + t]
            h[H_FN] = bt.fn[t]
            if slot < 0:
                slot = new_contact(c, b, k, h)
            c.lists.nb_s[k] |= TOUCH
            touching += 1
            bj = partner_row(&sink, c.lists.nb_j[k], hmax, &tj)
            rec = record_of(c, b, slot)
            if rec != NULL:
                for q in range(3):
                    rec[q] = bt.F[q * PG_BATCH + t]
            for q in range(3):
                fi[q] += bt.F[q * PG_BATCH + t]
                fi[3 + q] += bt.Ti[q * PG_BATCH + t]
                bj[q] -= bt.F[q * PG_BATCH + t]
                tj[q] -= bt.Tj[q * PG_BATCH + t]
            t += 1
        c.schedule.work[i] = finish_row(c, i, b, fi, touching)
        total += c.schedule.work[i]
    return total


cdef inline long long flush_rows(const State* c, int b, pg_pair_batch* bt, const int* keys, const int* slots,
                                 const int* rows, int* ends, int n, int first, int nrows, const double* cf,
                                 int* hmax) noexcept nogil:
    """The forces of the batch's n entries, added up for its nrows rows from ``first`` (entry t
    belongs to row first + ``rows[t]``; ``ends`` is scratch). Returns the rows' work."""
    cdef int r, t
    for r in range(nrows):
        ends[r] = 0
    for t in range(n):
        ends[rows[t]] += 1
    for r in range(1, nrows):
        ends[r] += ends[r - 1]
    pg_hertz_batch(bt, n, c.dt, c.update, cf)
    return add_rows(c, b, bt, keys, slots, ends, first, nrows, hmax)


cdef long long batched_rows(const State* c, int b, int* hmax) noexcept nogil:
    """Block b's rows of the pair loop on the batched path (State.batched, pair_batch.h): the
    pairs within reach of a run of rows gathered into a batch (see gather_sublists, and
    gather_row at a pass that makes the sublists), their forces computed together, then added
    up row by row as pair_row adds them; a row with more listed pairs than a batch holds goes
    through pair_row. Returns the rows' work."""
    cdef pg_pair_batch bt
    cdef int keys[PG_BATCH]
    cdef int slots[PG_BATCH]
    cdef int partners[PG_BATCH]
    cdef int rows[PG_BATCH]
    cdef int ends[PG_BATCH]
    cdef int i, n = 0, nrows = 0, first = c.schedule.pb[b], listed, gathered, at = c.lists.nb_start[c.schedule.pb[b]], e0 = 0, e1 = 0
    cdef int build = c.lists.sub_build, entries
    cdef long long total = 0
    cdef double one[7]   # the pair values when there is one type
    cdef double* cf = NULL
    cdef Gather g = gather_state(c, b)   # see Gather
    if c.ntypes == 1:
        one[:] = [c.coef.E, c.coef.G, c.coef.mu, c.coef.damp, c.coef.tdamp, c.coef.coh, c.coef.limit]
        cf = one
    for i in range(c.schedule.pb[b], c.schedule.pb[b + 1]):
        listed = c.lists.nb_start[i + 1] - c.lists.nb_start[i]
        gathered = listed if build or listed > PG_BATCH else c.lists.sb_n[i]
        entries = n if build else e1 - e0   # the batch's so far: without build, its run's sublists
        # a full batch, or a row whose sublist does not follow the run's (the blocks of the
        # pass that made them ended there)
        if (entries + gathered > PG_BATCH or nrows == PG_BATCH
                or not build and gathered and e1 > e0 and c.lists.sb_at[i] != e1):
            if not build:
                n = gather_sublists(c, &g, e0, e1, first, &bt, keys, slots, partners, rows)
            total += flush_rows(c, b, &bt, keys, slots, rows, ends, n, first, nrows, cf, hmax)
            first = i
            n = nrows = e0 = e1 = 0
        if listed > PG_BATCH:
            c.schedule.work[i] = pair_row(c, i, b, hmax)
            total += c.schedule.work[i]
            first = i + 1
            continue
        if build:
            n = gather_row(c, &g, i, first, &at, &bt, n, keys, slots, partners, rows)
        elif gathered:
            if e1 == e0:
                e0 = c.lists.sb_at[i]
            e1 = c.lists.sb_at[i] + gathered
        nrows += 1
    if not build:
        n = gather_sublists(c, &g, e0, e1, first, &bt, keys, slots, partners, rows)
    return total + flush_rows(c, b, &bt, keys, slots, rows, ends, n, first, nrows, cf, hmax)


cdef void pair_block(const State* c, int b) noexcept nogil:
    """Block b's rows of the pair loop; records their work and the last row of its halo."""
    cdef int i, hmax = -1
    cdef long long total = 0
    if c.walls.nslots:
        memset(&c.walls.sacc[<long long>SACC * c.walls.nslots * b], 0, SACC * c.walls.nslots * sizeof(double))
    if c.batched:
        total = batched_rows(c, b, &hmax)
    else:
        for i in range(c.schedule.pb[b], c.schedule.pb[b + 1]):
            c.schedule.work[i] = pair_row(c, i, b, &hmax)
            total += c.schedule.work[i]
    c.schedule.tstat[PAD * b] = total
    c.schedule.tstat[PAD * b + 1] = hmax


cdef int place_halos(State* sim) noexcept nogil:
    """The pair blocks' halos (see Halo) for the current bounds, their last rows written
    (``tstat``) -1 until the blocks run; -1 when out of memory."""
    cdef int b, i, start, end
    cdef long long total = 0
    cdef Halo* h
    cdef void* p
    sim.lists.nfarblocks = 0
    for b in range(sim.schedule.nblocks):
        sim.schedule.tstat[PAD * b + 1] = -1
        h = &sim.lists.halos[b]
        start = sim.schedule.pb[b]
        end = sim.schedule.pb[b + 1]
        h.near_off = total
        h.near_end = end - 1
        if end > start and end < sim.particles.n and sim.lists.last[end - 1] >= end:
            h.near_end = sim.lists.last[end - 1]
            total += h.near_end - end + 1
        h.far_lo = INT_MAX
        h.far_hi = -1
        for i in range(start, min(end, sim.lists.nfar)):
            if sim.lists.fhi[i] > h.near_end:
                h.far_lo = min(h.far_lo, max(sim.lists.flo[i], h.near_end + 1))
                h.far_hi = max(h.far_hi, sim.lists.fhi[i])
        h.far_off = total
        if h.far_hi >= h.far_lo:
            total += h.far_hi - h.far_lo + 1
        if start < sim.lists.nfar:
            sim.lists.nfarblocks = b + 1
    if total > sim.lists.halo_cap:   # the buffers are all zero between steps: start afresh
        p = calloc(6 * (total + total // 4), sizeof(double))
        if p == NULL:
            return -1
        free(sim.lists.halo)
        sim.lists.halo = <double*>p
        sim.lists.halo_cap = total + total // 4
    return 0
