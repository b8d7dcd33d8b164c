# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""The core's optional compiled kernels; each caller has a numpy path with the same results.

- ``histogram`` and ``pair_keys``: the cell-list sweep of ``pygran_core.analysis._neighbors``
  (same rows, runs and image shifts, same arithmetic, so the same counts and pairs), one
  point per iteration on OpenMP threads. Build with ``-ffp-contract=off`` so that
  ``dx*dx + dy*dy + dz*dz`` is never fused and matches numpy bit for bit.
- ``cell_order``: the stable counting sort of points by cell.
- ``parse_table``: the atom block of a text dump, decimal numbers correctly rounded (exact
  fast path, else ``strtod_l`` in the C locale), or None for anything it does not accept.
- ``cg_points`` and ``cg_segments``: the Cartesian deposits of
  ``pygran_core.analysis.coarse_grain`` (particles, and contact lines with their exact line
  integrals), one particle or contact per iteration on OpenMP threads.
"""

import numpy as np

from cython.parallel cimport parallel, prange, threadid
from libc.math cimport sqrt
from libc.stdint cimport int64_t, uint8_t, uint64_t
from libc.stdlib cimport free, malloc
from libc.string cimport memcpy
cimport openmp

cdef extern from *:
    """
    #include <locale.h>
    #include <stdlib.h>
    #if defined(__APPLE__)
    #include <xlocale.h>
    #endif
    static locale_t pg_c_locale(void) {
        static locale_t c = (locale_t)0;
        if (!c) c = newlocale(LC_ALL_MASK, "C", (locale_t)0);
        return c;
    }
    """
    ctypedef void* locale_t
    locale_t pg_c_locale() nogil
    double strtod_l(const char* text, char** end, locale_t locale) nogil


# -- the cell-list sweep ----------------------------------------------------------------------

cdef struct Sweep:
    const double* x
    const double* y
    const double* z
    const int64_t* cx
    const int64_t* cy
    const int64_t* cz
    const int64_t* start
    const int64_t* rows  # (nrows, 3): dy, dz, k
    Py_ssize_t nrows
    int64_t nx, ny, nz
    double lx, ly, lz
    double reach2
    int64_t npoints


cdef struct Run:
    int64_t first, stop
    double sx, sy, sz


cdef Py_ssize_t _runs(const Sweep* s, Py_ssize_t i, Run* out) noexcept nogil:
    """The runs of sorted point ``i``, as ``_neighbors._runs`` yields them."""
    cdef Py_ssize_t r, n = 0
    cdef int64_t dy, dz, k, ry, rz, image, base, lo, hi
    cdef int64_t cx = s.cx[i], cy = s.cy[i], cz = s.cz[i]
    cdef double sy, sz
    cdef bint own
    for r in range(s.nrows):
        dy, dz, k = s.rows[3 * r], s.rows[3 * r + 1], s.rows[3 * r + 2]
        own = dy == 0 and dz == 0
        ry, rz, sy, sz = cy + dy, cz + dz, 0.0, 0.0
        if ry < 0 or ry >= s.ny:  # rows reach less than one period beyond a face
            if s.ly == 0:
                continue
            image = -1 if ry < 0 else 1
            ry -= image * s.ny
            sy = image * s.ly
        if rz < 0 or rz >= s.nz:
            if s.lz == 0:
                continue
            image = -1 if rz < 0 else 1
            rz -= image * s.nz
            sz = image * s.lz
        base = s.nx * (ry + s.ny * rz)
        lo = cx - k if cx - k > 0 else 0
        hi = cx + k if cx + k < s.nx - 1 else s.nx - 1
        out[n].first = i + 1 if own else s.start[base + lo]
        out[n].stop = s.start[base + hi + 1]
        out[n].sx, out[n].sy, out[n].sz = 0.0, sy, sz
        n += 1
        if s.lx > 0:
            if cx + k >= s.nx:
                out[n].first, out[n].stop = s.start[base], s.start[base + cx + k - s.nx + 1]
                out[n].sx, out[n].sy, out[n].sz = s.lx, sy, sz
                n += 1
            if not own and cx - k < 0:
                out[n].first, out[n].stop = s.start[base + cx - k + s.nx], s.start[base + s.nx]
                out[n].sx, out[n].sy, out[n].sz = -s.lx, sy, sz
                n += 1
    return n


cdef Sweep _sweep(cells, const double[:, ::1] x, const int64_t[:, ::1] cell, const int64_t[::1] start,
                  const int64_t[:, ::1] rows):
    cdef Sweep s
    s.x, s.y, s.z = &x[0, 0], &x[1, 0], &x[2, 0]
    s.cx, s.cy, s.cz = &cell[0, 0], &cell[1, 0], &cell[2, 0]
    s.start = &start[0]
    s.rows = &rows[0, 0]
    s.nrows = rows.shape[0]
    s.nx, s.ny, s.nz = cells.shape[0], cells.shape[1], cells.shape[2]
    s.lx, s.ly, s.lz = cells.lengths[0], cells.lengths[1], cells.lengths[2]
    s.reach2 = cells.reach * cells.reach
    s.npoints = len(cells.order)
    return s


def _arrays(cells):
    n = len(cells.order)
    x = np.ascontiguousarray(cells.x, dtype=np.float64).reshape(3, n)
    cell = np.ascontiguousarray(cells.cell, dtype=np.int64).reshape(3, n)
    start = np.ascontiguousarray(cells.start, dtype=np.int64)
    rows = np.ascontiguousarray(np.array(cells.rows, dtype=np.int64).reshape(-1, 3))
    if n == 0:  # memoryviews need an element to point at
        x, cell = np.zeros((3, 1)), np.zeros((3, 1), dtype=np.int64)
    return n, x, cell, start, rows


def histogram(cells, const double[::1] squared, reference):
    """Ordered pairs (i, j), i != j, per bin ``squared[k] < d² <= squared[k + 1]``, counting
    only reference points ``i`` (``reference``: bool per sorted point; all when None)."""
    n, x, cell, start, rows = _arrays(cells)
    cdef const double[:, ::1] xv = x
    cdef const int64_t[:, ::1] cv = cell
    cdef const int64_t[::1] sv = start
    cdef const int64_t[:, ::1] rv = rows
    cdef Sweep s = _sweep(cells, xv, cv, sv, rv)
    cdef Py_ssize_t nbins = squared.shape[0] - 1, pad = 8  # pad: threads' rows on their own cache lines
    cdef double scale = nbins / sqrt(squared[nbins])
    ref = np.ones(max(n, 1), dtype=np.uint8) if reference is None else np.asarray(reference, dtype=np.uint8)
    cdef const uint8_t[::1] w = ref
    counts = np.zeros((openmp.omp_get_max_threads(), nbins + 1 + pad), dtype=np.int64)
    cdef int64_t[:, ::1] c = counts
    cdef Py_ssize_t i, j, r, nruns, b, npoints = n
    cdef Run* runs = NULL
    cdef double xi, yi, zi, dx, dy, dz, d2
    cdef const double* sq = &squared[0]
    with nogil, parallel():
        runs = <Run*> malloc((3 * s.nrows + 1) * sizeof(Run))
        for i in prange(npoints, schedule="dynamic", chunksize=1024):
            nruns = _runs(&s, i, runs)
            xi, yi, zi = s.x[i], s.y[i], s.z[i]
            for r in range(nruns):
                for j in range(runs[r].first, runs[r].stop):
                    dx = (s.x[j] - xi) + runs[r].sx
                    dy = (s.y[j] - yi) + runs[r].sy
                    dz = (s.z[j] - zi) + runs[r].sz
                    d2 = dx * dx + dy * dy + dz * dz
                    if d2 > s.reach2:
                        continue
                    b = <Py_ssize_t> (sqrt(d2) * scale)
                    if b > nbins - 1:
                        b = nbins - 1
                    if d2 <= sq[b]:  # the estimate is at most one bin off either way
                        b = b - 1
                    if d2 > sq[b + 1]:
                        b = b + 1
                    c[threadid(), b + 1] += w[i] + w[j]  # b = -1: coincident points
        free(runs)
    return counts[:, 1 : nbins + 1].sum(axis=0)


cdef Py_ssize_t _close(const Sweep* s, Py_ssize_t i, Run* runs, const int64_t* order, int64_t* keys) noexcept nogil:
    """How many pair images point ``i`` meets within reach; unless ``keys`` is NULL, each is
    written there as ``min * N + max`` of the two original indices."""
    cdef Py_ssize_t r, j, found = 0, nruns = _runs(s, i, runs)
    cdef double xi = s.x[i], yi = s.y[i], zi = s.z[i], dx, dy, dz
    cdef int64_t a = order[i], b
    for r in range(nruns):
        for j in range(runs[r].first, runs[r].stop):
            dx = (s.x[j] - xi) + runs[r].sx
            dy = (s.y[j] - yi) + runs[r].sy
            dz = (s.z[j] - zi) + runs[r].sz
            if dx * dx + dy * dy + dz * dz <= s.reach2:
                if keys != NULL:
                    b = order[j]
                    keys[found] = a * s.npoints + b if a < b else b * s.npoints + a
                found += 1
    return found


def pair_keys(cells):
    """``min(i, j) * N + max(i, j)`` (original indices) of every pair image at most ``reach``
    apart, in no particular order."""
    n, x, cell, start, rows = _arrays(cells)
    cdef const double[:, ::1] xv = x
    cdef const int64_t[:, ::1] cv = cell
    cdef const int64_t[::1] sv = start
    cdef const int64_t[:, ::1] rv = rows
    cdef Sweep s = _sweep(cells, xv, cv, sv, rv)
    order = np.ascontiguousarray(cells.order, dtype=np.int64) if n else np.zeros(1, dtype=np.int64)
    cdef const int64_t[::1] ov = order
    cdef const int64_t* op = &ov[0]
    offsets = np.zeros(n + 1, dtype=np.int64)
    cdef int64_t[::1] o = offsets
    cdef Py_ssize_t i, npoints = n
    cdef Run* runs = NULL
    with nogil, parallel():  # count each point's pairs ...
        runs = <Run*> malloc((3 * s.nrows + 1) * sizeof(Run))
        for i in prange(npoints, schedule="dynamic", chunksize=1024):
            o[i + 1] = _close(&s, i, runs, op, NULL)
        free(runs)
    np.cumsum(offsets, out=offsets)
    keys = np.empty(max(offsets[n], 1), dtype=np.int64)
    cdef int64_t[::1] kv = keys
    cdef int64_t* kp = &kv[0]
    with nogil, parallel():  # ... then write them at their offsets
        runs = <Run*> malloc((3 * s.nrows + 1) * sizeof(Run))
        for i in prange(npoints, schedule="dynamic", chunksize=1024):
            _close(&s, i, runs, op, kp + o[i])
        free(runs)
    return keys[: offsets[n]]


def cell_order(const int64_t[::1] cell, const int64_t[::1] start):
    """The stable order that sorts points by ``cell`` (a counting sort; ``start`` as in
    ``CellList.start``): the same as ``numpy.argsort(cell, kind="stable")``."""
    order = np.empty(cell.shape[0], dtype=np.intp)
    cdef Py_ssize_t[::1] out = order
    cdef Py_ssize_t i, n = cell.shape[0]
    cdef int64_t* fill = <int64_t*> malloc((start.shape[0] + 1) * sizeof(int64_t))
    if fill == NULL:
        raise MemoryError()
    memcpy(fill, &start[0], start.shape[0] * sizeof(int64_t))
    with nogil:
        for i in range(n):
            out[fill[cell[i]]] = i
            fill[cell[i]] += 1
    free(fill)
    return order


# -- text dumps -------------------------------------------------------------------------------

cdef double[23] _POWERS = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12,
                           1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22]


cdef const uint8_t* _number(const uint8_t* p, const uint8_t* end, double* value) noexcept nogil:
    """Reads ``[+-]digits[.digits][(e|E)[+-]digits]`` (digits on at least one side of the point)
    at ``p`` into the nearest double; returns where it stopped, or NULL if there was no number.
    Exact when the digits fit in 2^53 and the power of ten in 1e22 (one correctly rounded
    operation), else ``strtod_l`` in the C locale."""
    cdef bint negative = False, exact = True, exponent_negative = False
    cdef uint64_t mantissa = 0
    cdef int significant = 0, digits = 0, d
    cdef int64_t power = 0, exponent = 0
    cdef char text[64]
    cdef const uint8_t* body
    if p < end and (p[0] == 43 or p[0] == 45):  # + -
        negative = p[0] == 45
        p += 1
    body = p
    while p < end and p[0] == 48:  # leading zeros
        digits += 1
        p += 1
    while p < end and <uint8_t> (p[0] - 48) < 10:
        d = p[0] - 48
        if significant < 19:
            mantissa = mantissa * 10 + d
            significant += 1
        else:
            power += 1
            exact = exact and d == 0
        digits += 1
        p += 1
    if p < end and p[0] == 46:  # .
        p += 1
        if significant == 0:
            while p < end and p[0] == 48:
                digits += 1
                power -= 1
                p += 1
        while p < end and <uint8_t> (p[0] - 48) < 10:
            d = p[0] - 48
            if significant < 19:
                mantissa = mantissa * 10 + d
                significant += 1
                power -= 1
            else:
                exact = exact and d == 0
            digits += 1
            p += 1
    if digits == 0:
        return NULL
    if p < end and (p[0] == 101 or p[0] == 69):  # e E
        p += 1
        if p < end and (p[0] == 43 or p[0] == 45):
            exponent_negative = p[0] == 45
            p += 1
        if p == end or <uint8_t> (p[0] - 48) >= 10:
            return NULL
        while p < end and <uint8_t> (p[0] - 48) < 10:
            if exponent < 100000:
                exponent = exponent * 10 + (p[0] - 48)
            p += 1
        power += -exponent if exponent_negative else exponent
    if exact and mantissa == 0:
        value[0] = 0.0
    elif exact and mantissa <= (1ULL << 53) and -22 <= power <= 22:
        value[0] = mantissa * _POWERS[power] if power >= 0 else mantissa / _POWERS[-power]
    elif p - body < 64:
        memcpy(text, body, p - body)
        text[p - body] = 0
        value[0] = strtod_l(text, NULL, pg_c_locale())
    else:
        return NULL
    if negative:
        value[0] = -value[0]
    return p


def parse_table(const uint8_t[::1] text, Py_ssize_t ncols, Py_ssize_t nrows):
    """The rows of whitespace-separated numbers in ``text`` as a (rows, ncols) float64 array
    (columns contiguous), at most ``nrows`` rows; blank lines are skipped. None when a line
    has another number of fields, a field is not a plain decimal number (nan, inf, hex ...),
    a line ends in a lone carriage return or there are more rows: the caller then parses with
    numpy.loadtxt, which gives the same values or says what is wrong."""
    cdef Py_ssize_t size = text.shape[0], row = 0, column
    # a row takes at least 2 * ncols - 1 bytes: a header's atom count cannot inflate the table
    table = np.empty((ncols, max(min(nrows, size // (2 * ncols - 1) + 1), 1)))
    cdef double[:, ::1] out = table
    cdef Py_ssize_t stride = out.shape[1]
    cdef const uint8_t* p = &text[0] if size else NULL
    cdef const uint8_t* end = p + size
    cdef double* cell = &out[0, 0]
    cdef bint bad = False
    with nogil:
        while p < end and not bad:
            column = 0
            while True:
                while p < end and (p[0] == 32 or p[0] == 9):
                    p += 1
                if p == end or p[0] == 10:
                    break
                if p[0] == 13:  # \r\n ends a line like \n
                    bad = p + 1 == end or p[1] != 10
                    p += 1
                    break
                if column == ncols or row == nrows or row == stride:
                    bad = True
                    break
                p = _number(p, end, cell + column * stride + row)
                if p == NULL or (p < end and p[0] != 32 and p[0] != 9 and p[0] != 10 and p[0] != 13):
                    bad = True
                    break
                column += 1
            if not bad and column:
                bad = column != ncols
                row += 1
            if p != NULL and p < end:
                p += 1
    if bad:
        return None
    return table[:, :row].T


# -- coarse-graining --------------------------------------------------------------------------
# The Cartesian deposits of pygran_core.analysis.coarse_grain (_points_numpy, _segments_numpy):
# the same stencils, 1D kernel weights, quadrature nodes and normalisation in the same
# arithmetic, one particle or contact per iteration on OpenMP threads, each thread into its own
# copy of the grid. A kernel is a product of 1D kernels, so a point's weights are the outer
# product of three short vectors; a contact line is a weighted sum of such points (its
# quadrature nodes), accumulated in a local stencil, normalised, then added to the grid.

from libc.math cimport ceil, exp, fabs, floor
from libc.stdlib cimport realloc
from libc.string cimport memset

cdef extern from *:
    """
    #define pg_prefetch(p) __builtin_prefetch(p)
    /* out[j] += w * v[j], j < q; unrolled for the usual q (10 point sums, 9 stress components) */
    static inline void pg_add(double* restrict out, double w, const double* restrict v, Py_ssize_t q) {
        if (q == 9) {
            for (int j = 0; j < 9; j++) out[j] += w * v[j];
        } else if (q == 10) {
            for (int j = 0; j < 10; j++) out[j] += w * v[j];
        } else {
            for (Py_ssize_t j = 0; j < q; j++) out[j] += w * v[j];
        }
    }
    """
    void pg_prefetch(const void* p) noexcept nogil
    void pg_add(double* out, double w, const double* v, Py_ssize_t q) noexcept nogil

#: How many items ahead the deposits prefetch their (randomly ordered) input rows.
cdef int _AHEAD = 8


cdef struct Lattice:
    int ndim
    int64_t axis[3]
    double lower[3]
    double h[3]
    int64_t n[3]
    int64_t stride[3]
    bint wrap[3]
    int kernel
    double w, c
    double gauss  # -1 / (2 w²)
    double inverse_c  # 1 / c


cdef inline double _profile(const Lattice* g, double u) noexcept nogil:
    """The 1D kernel (unnormalised), as ``Kernel.profile``."""
    cdef double t
    u = fabs(u)
    if not u < g.c:
        return 0.0
    if g.kernel == 0:
        return exp((u * u) * g.gauss)
    if g.kernel == 1:
        t = u * g.inverse_c
        return (1 + 3 * t) * ((1 - t) * (1 - t) * (1 - t))
    return 1.0


cdef inline int64_t _cell(const Lattice* g, int d, int64_t k) noexcept nogil:
    """The offset in the grid of lattice index ``k`` along dimension ``d`` (wrapped where
    periodic), or -1 outside the grid."""
    if g.wrap[d]:
        if k < 0 or k >= g.n[d]:
            k = k % g.n[d]
            if k < 0:
                k += g.n[d]
    elif k < 0 or k >= g.n[d]:
        return -1
    return k * g.stride[d]


cdef Lattice _lattice(const int64_t[::1] axes, const double[::1] lower, const double[::1] spacing,
                      const int64_t[::1] n, const uint8_t[::1] wrap, int kernel, double width, double cutoff):
    cdef Lattice g
    cdef int d
    g.ndim = axes.shape[0]
    for d in range(3):
        g.axis[d], g.lower[d], g.h[d], g.n[d], g.wrap[d] = 0, 0.0, 1.0, 1, False
    for d in range(g.ndim):
        g.axis[d], g.lower[d], g.h[d], g.n[d], g.wrap[d] = axes[d], lower[d], spacing[d], n[d], wrap[d] != 0
    g.stride[2] = 1
    g.stride[1] = g.n[2]
    g.stride[0] = g.n[1] * g.n[2]
    g.kernel, g.w, g.c = kernel, width, cutoff
    g.gauss, g.inverse_c = -0.5 / (width * width), 1 / cutoff
    return g


cdef struct Scratch:  # one thread's buffers (C arrays written in a prange would be shared)
    int64_t axis_capacity, stencil_capacity, cuts_capacity
    double* offset  # per axis: cell centre minus the line's start, at each stencil index
    int64_t* index  # per axis: the grid offset of each stencil index, -1 outside
    double* weight  # per axis: the 1D weights of the current point
    double* stencil  # the line's weights on its stencil
    double* cuts  # the ends of the line's quadrature pieces
    double a[3]  # the current point, or line start
    double b[3]  # the current line's branch vector


cdef Scratch* _scratch() noexcept nogil:
    cdef Scratch* s = <Scratch*> malloc(sizeof(Scratch))
    memset(s, 0, sizeof(Scratch))
    return s


cdef void _release(Scratch* s) noexcept nogil:
    free(s.offset)
    free(s.index)
    free(s.weight)
    free(s.stencil)
    free(s.cuts)
    free(s)


cdef void _reserve(Scratch* s, int64_t axis, int64_t stencil, int64_t cuts) noexcept nogil:
    if axis > s.axis_capacity:
        s.axis_capacity = 2 * axis
        s.offset = <double*> realloc(s.offset, 3 * s.axis_capacity * sizeof(double))
        s.index = <int64_t*> realloc(s.index, 3 * s.axis_capacity * sizeof(int64_t))
        s.weight = <double*> realloc(s.weight, 3 * s.axis_capacity * sizeof(double))
    if stencil > s.stencil_capacity:
        s.stencil_capacity = 2 * stencil
        s.stencil = <double*> realloc(s.stencil, s.stencil_capacity * sizeof(double))
    if cuts > s.cuts_capacity:
        s.cuts_capacity = 2 * cuts
        s.cuts = <double*> realloc(s.cuts, s.cuts_capacity * sizeof(double))


cdef void _point(const Lattice* g, Scratch* s, const int64_t* count, const double* x, double* out,
                 const double* value, Py_ssize_t q) noexcept nogil:
    """Add ``value`` times the point's weights at ``x`` (normalised along each axis) to ``out``."""
    cdef int64_t K = s.axis_capacity, low, k, k0, k1, k2, c01
    cdef int64_t first[3]
    cdef int64_t last[3]
    cdef double total, w0, w01, wt
    cdef double* weight = s.weight
    cdef int64_t* index = s.index
    cdef int d
    for d in range(3):
        first[d], last[d] = 0, 0
        if d >= g.ndim:
            weight[d * K], index[d * K] = 1.0, 0
            continue
        low = <int64_t> floor((x[d] - g.lower[d]) / g.h[d] - 0.5 - g.c / g.h[d])
        total = 0.0
        for k in range(count[d]):
            weight[d * K + k] = _profile(g, (g.lower[d] + ((low + k) + 0.5) * g.h[d]) - x[d])
            total = total + weight[d * K + k]
            index[d * K + k] = _cell(g, d, low + k)
        first[d], last[d] = count[d], -1
        for k in range(count[d]):
            weight[d * K + k] = weight[d * K + k] / total
            if weight[d * K + k] != 0:
                if k < first[d]:
                    first[d] = k
                last[d] = k
    for k0 in range(first[0], last[0] + 1):
        if index[k0] < 0:
            continue
        w0 = weight[k0]
        for k1 in range(first[1], last[1] + 1):
            if index[K + k1] < 0:
                continue
            w01 = w0 * weight[K + k1]
            c01 = index[k0] + index[K + k1]
            for k2 in range(first[2], last[2] + 1):
                wt = w01 * weight[2 * K + k2]
                if index[2 * K + k2] < 0 or wt == 0:
                    continue
                pg_add(&out[(c01 + index[2 * K + k2]) * q], wt, value, q)


def cg_points(const int64_t[::1] axes, const double[::1] lower, const double[::1] spacing,
              const int64_t[::1] n, const uint8_t[::1] wrap, int kernel, double width, double cutoff,
              const double[:, ::1] positions, const double[:, ::1] values, const int64_t[::1] order):
    """Sum over points (taken in ``order``) of ``values`` (N, q) times their kernel weights at
    the cell centres, normalised to 1 over the lattice: (cells, q)."""
    cdef Lattice g = _lattice(axes, lower, spacing, n, wrap, kernel, width, cutoff)
    cdef Py_ssize_t ncells = 1, q = values.shape[1], npoints = order.shape[0], i
    cdef int d, threads = openmp.omp_get_max_threads()
    cdef int64_t count[3]
    cdef int64_t kmax = 1, p
    for d in range(3):
        count[d] = 1
    for d in range(g.ndim):
        ncells *= g.n[d]
        count[d] = <int64_t> floor(2 * g.c / g.h[d]) + 2
        kmax = max(kmax, count[d])
    grids = np.zeros((threads, ncells, q))
    cdef double[:, :, ::1] out = grids
    cdef Scratch* s = NULL
    with nogil, parallel():
        s = _scratch()
        _reserve(s, kmax, 0, 0)
        for i in prange(npoints, schedule="static"):
            if i + _AHEAD < npoints:
                p = order[i + _AHEAD]
                pg_prefetch(&positions[p, 0])
                pg_prefetch(&values[p, 0])
                pg_prefetch(&values[p, q - 1])
            p = order[i]
            for d in range(g.ndim):
                s.a[d] = positions[p, g.axis[d]]
            _point(&g, s, count, s.a, &out[threadid(), 0, 0], &values[p, 0], q)
        _release(s)
    return grids.sum(axis=0)


cdef void _line(const Lattice* g, Scratch* s, const double* start, const double* branch, const double* nodes,
                const double* weights, int m, double piece, double* out, const double* value,
                Py_ssize_t q) noexcept nogil:
    """Add ``value`` times the line's weights to ``out``: the kernel along ``start - t branch``,
    ``t`` in [0, 1], integrated by ``m``-point Gauss-Legendre on pieces between the points where
    the line enters or leaves a cell's support, at most ``piece`` long; normalised to 1."""
    cdef int64_t low[3]
    cdef int64_t count[3]
    cdef int64_t first[3]
    cdef int64_t last[3]
    cdef int64_t lo[3]
    cdef int64_t hi[3]
    cdef int64_t K = 1, size = 1, pieces, ncuts = 0, k, k0, k1, k2, row, c01, r
    cdef double length2 = 0.0, end, t, t0, t1, half, mid, wq, w0, w01, total, inverse
    cdef double* offset
    cdef double* weight
    cdef double* stencil
    cdef double* cuts
    cdef int64_t* index
    cdef int d, e, sign
    cdef bint empty
    for d in range(3):
        low[d], count[d] = 0, 1
        if d < g.ndim:
            end = start[d] - branch[d]
            low[d] = <int64_t> floor(((start[d] if start[d] < end else end) - g.lower[d] - g.c) / g.h[d] - 0.5)
            count[d] = <int64_t> floor((fabs(branch[d]) + 2 * g.c) / g.h[d]) + 2
            length2 = length2 + branch[d] * branch[d]
        size = size * count[d]
        K = max(K, count[d])
    pieces = max(<int64_t> ceil(sqrt(length2) / piece), 1)
    _reserve(s, K, size, pieces + 1 + 2 * (count[0] + count[1] + count[2]))
    offset, index, weight, stencil, cuts = s.offset, s.index, s.weight, s.stencil, s.cuts
    K = s.axis_capacity
    for d in range(3):
        for k in range(count[d]):
            if d < g.ndim:
                offset[d * K + k] = (g.lower[d] + ((low[d] + k) + 0.5) * g.h[d]) - start[d]
                index[d * K + k] = _cell(g, d, low[d] + k)
            else:
                offset[d * K + k], index[d * K + k] = 0.0, 0
    # the pieces: [0, 1] cut into equal parts and where |offset + t branch| = c along an axis
    for k in range(pieces + 1):
        cuts[ncuts] = (<double> k) / pieces
        ncuts += 1
    for d in range(g.ndim):
        if branch[d] != 0:
            inverse = 1 / branch[d]
            for k in range(count[d]):
                for sign in range(2):
                    t = ((g.c if sign else -g.c) - offset[d * K + k]) * inverse
                    if 0 < t < 1:
                        cuts[ncuts] = t
                        ncuts += 1
    for k in range(1, ncuts):  # insertion sort (a few cuts, most of them in order)
        t = cuts[k]
        r = k - 1
        while r >= 0 and cuts[r] > t:
            cuts[r + 1] = cuts[r]
            r -= 1
        cuts[r + 1] = t
    memset(stencil, 0, size * sizeof(double))
    for d in range(3):
        first[d], last[d] = count[d], -1
    for e in range(ncuts - 1):
        t0, t1 = cuts[e], cuts[e + 1]
        if not t1 > t0:
            continue
        half, mid = 0.5 * (t1 - t0), 0.5 * (t1 + t0)
        for r in range(m):
            t = mid + half * nodes[r]
            wq = half * weights[r]
            empty = False
            for d in range(3):
                if d >= g.ndim:
                    weight[d * K], lo[d], hi[d] = 1.0, 0, 0
                    continue
                lo[d], hi[d] = count[d], -1
                for k in range(count[d]):
                    weight[d * K + k] = _profile(g, offset[d * K + k] + t * branch[d])
                    if weight[d * K + k] != 0:
                        if k < lo[d]:
                            lo[d] = k
                        hi[d] = k
                if hi[d] < 0:
                    empty = True
                    break
            if empty:
                continue
            for d in range(3):
                first[d] = min(first[d], lo[d])
                last[d] = max(last[d], hi[d])
            for k0 in range(lo[0], hi[0] + 1):
                w0 = wq * weight[k0]
                for k1 in range(lo[1], hi[1] + 1):
                    w01 = w0 * weight[K + k1]
                    row = (k0 * count[1] + k1) * count[2]
                    for k2 in range(lo[2], hi[2] + 1):
                        stencil[row + k2] += w01 * weight[2 * K + k2]
    total = 0.0
    for k0 in range(first[0], last[0] + 1):
        for k1 in range(first[1], last[1] + 1):
            row = (k0 * count[1] + k1) * count[2]
            for k2 in range(first[2], last[2] + 1):
                total = total + stencil[row + k2]
    if not total > 0:
        return
    for k0 in range(first[0], last[0] + 1):
        if index[k0] < 0:
            continue
        for k1 in range(first[1], last[1] + 1):
            if index[K + k1] < 0:
                continue
            c01 = index[k0] + index[K + k1]
            row = (k0 * count[1] + k1) * count[2]
            for k2 in range(first[2], last[2] + 1):
                if index[2 * K + k2] < 0 or stencil[row + k2] == 0:
                    continue
                pg_add(&out[(c01 + index[2 * K + k2]) * q], stencil[row + k2] / total, value, q)


def cg_segments(const int64_t[::1] axes, const double[::1] lower, const double[::1] spacing,
                const int64_t[::1] n, const uint8_t[::1] wrap, int kernel, double width, double cutoff,
                const double[:, ::1] start, const double[:, ::1] branch, const double[:, ::1] values,
                const int64_t[::1] order, const double[::1] nodes, const double[::1] weights, double piece):
    """Sum over segments ``start -> start - branch`` (taken in ``order``) of ``values`` (M, q)
    times the kernel integrated along them at the cell centres (Gauss-Legendre ``nodes`` and
    ``weights`` on [-1, 1] on pieces at most ``piece`` long, see ``_line``), normalised to 1
    over the lattice: (cells, q)."""
    cdef Lattice g = _lattice(axes, lower, spacing, n, wrap, kernel, width, cutoff)
    cdef Py_ssize_t ncells = 1, q = values.shape[1], nseg = order.shape[0], i
    cdef int d, m = nodes.shape[0], threads = openmp.omp_get_max_threads()
    cdef int64_t p
    for d in range(g.ndim):
        ncells *= g.n[d]
    grids = np.zeros((threads, ncells, q))
    cdef double[:, :, ::1] out = grids
    cdef Scratch* s = NULL
    with nogil, parallel():
        s = _scratch()
        for i in prange(nseg, schedule="dynamic", chunksize=256):
            if i + _AHEAD < nseg:
                p = order[i + _AHEAD]
                pg_prefetch(&start[p, 0])
                pg_prefetch(&branch[p, 0])
                pg_prefetch(&values[p, 0])
                pg_prefetch(&values[p, q - 1])
            p = order[i]
            for d in range(g.ndim):
                s.a[d], s.b[d] = start[p, g.axis[d]], branch[p, g.axis[d]]
            _line(&g, s, s.a, s.b, &nodes[0], &weights[0], m, piece, &out[threadid(), 0, 0], &values[p, 0], q)
        _release(s)
    return grids.sum(axis=0)
