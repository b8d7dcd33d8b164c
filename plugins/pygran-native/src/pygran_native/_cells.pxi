# The cell grid: cells of side >= 2 r + skin in slabs across the axis with the most cells,
# where r is the largest radius but for a few big particles (see split_radius), and the
# triangles within reach of each cell.

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


cdef double split_radius(const State* sim, double rmin, double rmax) noexcept nogil:
    """The radius the cells fit (``Lists.rsplit``): rmax, unless some particles are over twice
    the smallest and at most BIG_MAX of them, and an eighth of all, are; then the largest of the
    others. Cells sized by a 10 mm ball in a bed of 1 mm beads hold a thousand beads each, so
    the search of every bead would try a hundred times the pairs it needs (LAMMPS' ``neighbor
    multi`` and LIGGGHTS' bins by the largest cutoff are the two ends of this choice)."""
    cdef int i, count = 0
    cdef double small = rmin
    if rmax <= 2.0 * rmin:
        return rmax
    for i in range(sim.particles.n):
        if sim.particles.r[i] > 2.0 * rmin:
            count += 1
        elif sim.particles.r[i] > small:
            small = sim.particles.r[i]
    if count > BIG_MAX or 8 * count > sim.particles.n:
        return rmax
    return small


cdef bint box_fits(const State* sim, double rmax) noexcept nogil:
    """Whether the cells a big particle searches (see box_range) wrap at most once around
    each periodic axis, so that none is searched twice."""
    cdef int d, k
    for d in range(3):
        k = <int>ceil((rmax + sim.lists.rsplit + sim.skin) / sim.lists.cs[d])
        if sim.per[d] and 2 * k + 1 > sim.lists.nc[d]:
            return False
    return True


cdef int setup_cells(State* sim, double rmax) noexcept nogil:
    """Cell grid of side >= 2 rmax + skin over the box; -1 when out of memory."""
    cdef double cut, size
    cdef int d, k
    cdef int cc[3]
    cdef long long total
    cdef void* p
    cut = 2.0 * rmax + sim.skin
    size = cut
    while True:
        total = 1
        for d in range(3):
            sim.lists.nc[d] = <int>floor(sim.L[d] / size)
            if sim.lists.nc[d] < 1:
                sim.lists.nc[d] = 1
            sim.lists.cs[d] = sim.L[d] / sim.lists.nc[d]
            total *= sim.lists.nc[d]
        if total <= 4 * <long long>sim.particles.n + 4096:
            break
        size *= 1.26
    sim.lists.ncells = <int>total
    # axes by decreasing cell count (ties: z before y before x)
    sim.lists.ax[0], sim.lists.ax[1], sim.lists.ax[2] = 2, 1, 0
    for d in range(2):
        for k in range(2 - d):
            if sim.lists.nc[sim.lists.ax[k + 1]] > sim.lists.nc[sim.lists.ax[k]]:
                sim.lists.ax[k], sim.lists.ax[k + 1] = sim.lists.ax[k + 1], sim.lists.ax[k]
    k = 0   # (exactly 14 with 3 cells or more along each axis, which scan_pairs needs to use them)
    for d in range(27):   # the order of scan_pairs' loops: offsets d0 (x), d1 (y), d2 (z) = -1, 0, 1
        cc[0], cc[1], cc[2] = d % 3 - 1, d // 3 % 3 - 1, d // 9 - 1
        if k < 14 and cell_id(sim.lists.nc, sim.lists.ax, cc) >= 0:
            sim.lists.up[k] = cell_id(sim.lists.nc, sim.lists.ax, cc)
            k += 1
    if sim.lists.ncells + 2 > sim.lists.cell_cap:
        p = grow(sim.lists.cell_start, (sim.lists.ncells + 2) * sizeof(int))
        if p == NULL:
            return -1
        sim.lists.cell_start = <int*>p
        p = grow(sim.walls.ctri_start, (sim.lists.ncells + 2) * sizeof(int))
        if p == NULL:
            return -1
        sim.walls.ctri_start = <int*>p
        sim.lists.cell_cap = sim.lists.ncells + 2
    return 0


cdef inline int cell_of(State* sim, const double* p) noexcept nogil:
    cdef int cc[3]
    return locate(p, sim.lo, sim.lists.cs, sim.lists.nc, sim.lists.ax, cc)


cdef void tri_cells(State* sim, int e, double reach, int* lo3, int* hi3) noexcept nogil:
    """Range of cells within ``reach`` of triangle e's bounding box."""
    cdef double mn, mx, val
    cdef int a, d
    for d in range(3):
        mn = sim.walls.egeo[9 * e + d]
        mx = mn
        for a in range(1, 3):
            val = sim.walls.egeo[9 * e + 3 * a + d]
            if val < mn:
                mn = val
            if val > mx:
                mx = val
        lo3[d] = <int>floor((mn - reach - sim.lo[d]) / sim.lists.cs[d])
        hi3[d] = <int>floor((mx + reach - sim.lo[d]) / sim.lists.cs[d])
        if lo3[d] < 0:
            lo3[d] = 0
        if hi3[d] >= sim.lists.nc[d]:
            hi3[d] = sim.lists.nc[d] - 1


cdef inline bint tri_near_cell(State* sim, int e, int a, int b, int c, double reach) noexcept nogil:
    """Whether cell (a, b, c) comes within ``reach`` of triangle e's plane."""
    cdef double half, ln
    cdef double u[3]
    cdef double v[3]
    cdef double nrm[3]
    cdef double ctr[3]
    cdef const double* g = &sim.walls.egeo[9 * e]
    cdef int d
    for d in range(3):
        u[d] = g[3 + d] - g[d]
        v[d] = g[6 + d] - g[d]
    cross3(u, v, nrm)
    ln = sqrt(dot3(nrm, nrm))
    ctr[0] = sim.lo[0] + (a + 0.5) * sim.lists.cs[0] - g[0]
    ctr[1] = sim.lo[1] + (b + 0.5) * sim.lists.cs[1] - g[1]
    ctr[2] = sim.lo[2] + (c + 0.5) * sim.lists.cs[2] - g[2]
    half = 0.5 * sqrt(sim.lists.cs[0] * sim.lists.cs[0] + sim.lists.cs[1] * sim.lists.cs[1] + sim.lists.cs[2] * sim.lists.cs[2])
    return fabs(dot3(nrm, ctr)) <= (reach + half) * ln


cdef int bin_triangles(State* sim, double reach) noexcept nogil:
    """CSR (``ctri_start``, ``ctri``) of the triangles within ``reach`` of each cell.

    A triangle goes to the cells of its bounding box (grown by ``reach``) that come
    within ``reach`` of its plane. Uses ``cell_start`` as fill cursor: call before the
    particles are binned.
    """
    cdef int e, a, b, c, cc
    cdef int lo3[3]
    cdef int hi3[3]
    cdef int abc[3]
    cdef long long total
    cdef void* p
    memset(sim.walls.ctri_start, 0, (sim.lists.ncells + 1) * sizeof(int))
    for e in range(sim.walls.ne):
        if sim.walls.ekind[e] == TRIANGLE:
            tri_cells(sim, e, reach, lo3, hi3)
            for c in range(lo3[2], hi3[2] + 1):
                for b in range(lo3[1], hi3[1] + 1):
                    for a in range(lo3[0], hi3[0] + 1):
                        if tri_near_cell(sim, e, a, b, c, reach):
                            abc[0] = a
                            abc[1] = b
                            abc[2] = c
                            sim.walls.ctri_start[cell_id(sim.lists.nc, sim.lists.ax, abc) + 1] += 1
    for c in range(sim.lists.ncells):
        sim.walls.ctri_start[c + 1] += sim.walls.ctri_start[c]
    total = sim.walls.ctri_start[sim.lists.ncells]
    if total + 1 > sim.walls.ctri_cap:
        p = grow(sim.walls.ctri, (total + 1) * sizeof(int))
        if p == NULL:
            return -1
        sim.walls.ctri = <int*>p
        sim.walls.ctri_cap = total + 1
    memcpy(sim.lists.cell_start, sim.walls.ctri_start, (sim.lists.ncells + 1) * sizeof(int))
    for e in range(sim.walls.ne):
        if sim.walls.ekind[e] == TRIANGLE:
            tri_cells(sim, e, reach, lo3, hi3)
            for c in range(lo3[2], hi3[2] + 1):
                for b in range(lo3[1], hi3[1] + 1):
                    for a in range(lo3[0], hi3[0] + 1):
                        if tri_near_cell(sim, e, a, b, c, reach):
                            abc[0] = a
                            abc[1] = b
                            abc[2] = c
                            cc = cell_id(sim.lists.nc, sim.lists.ax, abc)
                            sim.walls.ctri[sim.lists.cell_start[cc]] = e
                            sim.lists.cell_start[cc] += 1
    return 0
