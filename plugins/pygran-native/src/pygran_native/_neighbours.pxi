# Neighbour search: cells, the half neighbour list and the wall list, with contact
# histories carried over from the previous lists.

# --- per-row work of the parallel loops ---------------------------------------------------
cdef inline void zero_hist(double* h, int hs) noexcept nogil:
    cdef int k
    for k in range(hs):
        if h[k] != 0.0:
            memset(h, 0, hs * sizeof(double))
            return


cdef inline int cell_id(const int* nc, const int* ax, const int* cc) noexcept nogil:
    """Index of the cell of coordinates cc. Axis ax[0] varies slowest: a block of consecutive
    cells, such as a thread's, is a slab across the axis with the most cells (the smallest
    interface between threads, and in a bed each slab has the bed's full height)."""
    return (cc[ax[0]] * nc[ax[1]] + cc[ax[1]]) * nc[ax[2]] + cc[ax[2]]


cdef inline int locate(const double* p, const double* lo, const double* cs, const int* nc, const int* ax,
                       int* cc) noexcept nogil:
    """Cell coordinates cc (clamped to the grid) and index of point p."""
    cdef int d
    for d in range(3):
        cc[d] = <int>floor((p[d] - lo[d]) / cs[d])
        if cc[d] < 0:
            cc[d] = 0
        elif cc[d] >= nc[d]:
            cc[d] = nc[d] - 1
    return cell_id(nc, ax, cc)


cdef uint8_t carry_pair(const Ctx* c, int a, int b, double* h) noexcept nogil:
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


cdef int scan_pairs(const Ctx* c, int i, bint fill) noexcept nogil:
    """Partners j > i within r_i + r_j + skin: counted, or written from ``nb_start[i]``."""
    cdef int d0, d1, d2, j, code, cid, cnt = 0, pos, wrap
    cdef int cc[3]
    cdef int nb[3]
    cdef int s[3]
    cdef double dx, dy, dz, rc
    cdef const double* xi = &c.x[3 * i]
    cdef const double* sv
    locate(xi, c.lo, c.cs, c.nc, c.ax, cc)
    pos = c.nb_start[i] if fill else 0
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
                cid = cell_id(c.nc, c.ax, nb)
                code = 9 * (s[0] + 1) + 3 * (s[1] + 1) + s[2] + 1
                sv = &c.shiftv[3 * code]
                j = c.cell_start[cid]
                if j <= i:
                    j = i + 1
                wrap = WRAP if s[c.ax[0]] != 0 else 0
                while j < c.cell_start[cid + 1]:
                    dx = xi[0] - c.x[3 * j] + sv[0]
                    dy = xi[1] - c.x[3 * j + 1] + sv[1]
                    dz = xi[2] - c.x[3 * j + 2] + sv[2]
                    rc = c.r[i] + c.r[j] + c.skin
                    if dx * dx + dy * dy + dz * dz < rc * rc:
                        if fill:
                            c.nb_j[pos + cnt] = j
                            c.nb_s[pos + cnt] = (<uint8_t>(code | wrap)
                                                 | carry_pair(c, i, j, &c.nb_h[(pos + cnt) * c.hs]))
                        cnt += 1
                    j += 1
    return cnt


cdef int scan_walls(const Ctx* c, int i, bint fill) noexcept nogil:
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
