# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled kernels pygran-core uses when this package is installed (it has numpy fallbacks).

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
# The Cartesian deposits of pygran_core.analysis.coarse_grain (_points_numpy, _segments_numpy,
# segment_integral): the same stencils, kernels and line integrals in the same arithmetic, one
# particle or contact per iteration on OpenMP threads, each thread into its own copy of the grid.

from libc.math cimport erf, erfc, exp, fabs, floor, sqrt
from libc.stdlib cimport realloc

_LEGENDRE7 = np.polynomial.legendre.leggauss(7)
_LEGENDRE8 = np.polynomial.legendre.leggauss(8)
cdef double _GL7X[7]
cdef double _GL7W[7]
cdef double _GL8X[8]
cdef double _GL8W[8]
for _q in range(7):
    _GL7X[_q], _GL7W[_q] = _LEGENDRE7[0][_q], _LEGENDRE7[1][_q]
for _q in range(8):
    _GL8X[_q], _GL8W[_q] = _LEGENDRE8[0][_q], _LEGENDRE8[1][_q]


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


cdef inline double _profile(const Lattice* g, double u) noexcept nogil:
    """The 1D kernel (unnormalised), as ``Kernel.profile``."""
    cdef double t
    u = fabs(u)
    if not u < g.c:
        return 0.0
    if g.kernel == 0:
        t = u / g.w
        return exp(-0.5 * (t * t))
    if g.kernel == 1:
        t = u / g.c
        return (1 + 3 * t) * ((1 - t) * (1 - t) * (1 - t))
    return 1.0


cdef inline bint _cell(const Lattice* g, int d, int64_t k, int64_t* index) noexcept nogil:
    """Lattice index ``k`` along dimension ``d`` wrapped or checked: False outside the grid."""
    if g.wrap[d]:
        k = k % g.n[d]
        if k < 0:
            k += g.n[d]
    elif k < 0 or k >= g.n[d]:
        return False
    index[0] = k * g.stride[d]
    return True


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
    if g.ndim == 2:
        g.stride[0], g.stride[1], g.stride[2] = g.n[1], 1, 0
    elif g.ndim == 1:
        g.stride[0], g.stride[1], g.stride[2] = 1, 0, 0
    g.kernel, g.w, g.c = kernel, width, cutoff
    return g


def cg_points(const int64_t[::1] axes, const double[::1] lower, const double[::1] spacing,
              const int64_t[::1] n, const uint8_t[::1] wrap, int kernel, double width, double cutoff,
              const double[:, ::1] positions, const double[:, ::1] values):
    """Sum over points of ``values`` (N, q) times their kernel weights at the cell centres,
    normalised to 1 over the lattice: (cells, q)."""
    cdef Lattice g = _lattice(axes, lower, spacing, n, wrap, kernel, width, cutoff)
    cdef Py_ssize_t ncells = 1, q = values.shape[1], npoints = positions.shape[0], i, j
    cdef int d, threads = openmp.omp_get_max_threads()
    cdef int64_t count[3]
    cdef int64_t kmax = 1
    for d in range(g.ndim):
        ncells *= g.n[d]
        count[d] = <int64_t> floor(2 * g.c / g.h[d]) + 2
        kmax = max(kmax, count[d])
    for d in range(g.ndim, 3):
        count[d] = 1
    grids = np.zeros((threads, ncells, q))
    cdef double[:, :, ::1] out = grids
    cdef double* weight = NULL
    cdef int64_t* index = NULL
    cdef bint* valid = NULL
    cdef int64_t low, k, o0, o1, o2, at
    cdef double x, total, w0, w01, wt
    cdef double* o
    with nogil, parallel():
        weight = <double*> malloc(3 * kmax * sizeof(double))
        index = <int64_t*> malloc(3 * kmax * sizeof(int64_t))
        valid = <bint*> malloc(3 * kmax * sizeof(bint))
        for i in prange(npoints, schedule="static"):
            for d in range(3):
                if d >= g.ndim:
                    weight[d * kmax], index[d * kmax], valid[d * kmax] = 1.0, 0, True
                    continue
                x = positions[i, g.axis[d]]
                low = <int64_t> floor((x - g.lower[d]) / g.h[d] - 0.5 - g.c / g.h[d])
                total = 0.0
                for k in range(count[d]):
                    weight[d * kmax + k] = _profile(&g, (g.lower[d] + ((low + k) + 0.5) * g.h[d]) - x)
                    total = total + weight[d * kmax + k]
                    valid[d * kmax + k] = _cell(&g, d, low + k, &index[d * kmax + k])
                for k in range(count[d]):
                    weight[d * kmax + k] = weight[d * kmax + k] / total
            o = &out[threadid(), 0, 0]
            for o0 in range(count[0]):
                if not valid[o0]:
                    continue
                w0 = weight[o0]
                for o1 in range(count[1]):
                    if not valid[kmax + o1]:
                        continue
                    w01 = w0 * weight[kmax + o1]
                    for o2 in range(count[2]):
                        wt = w01 * weight[2 * kmax + o2]
                        if not valid[2 * kmax + o2] or wt == 0:
                            continue
                        at = (index[o0] + index[kmax + o1] + index[2 * kmax + o2]) * q
                        for j in range(q):
                            o[at + j] += wt * values[i, j]
        free(weight)
        free(index)
        free(valid)
    return grids.sum(axis=0)


cdef inline double _legendre(const Lattice* g, const double* d, const double* b, double s0, double s1,
                             const double* nodes, const double* weights, int m) noexcept nogil:
    """Gauss-Legendre with ``m`` nodes of the kernel product along the segment, on [s0, s1]."""
    cdef double half = 0.5 * (s1 - s0), mid = 0.5 * (s1 + s0), total = 0.0, s, value, u, r2
    cdef int q, e
    for q in range(m):
        s = mid + half * nodes[q]
        value = weights[q] * half
        if g.kernel == 0:  # inside the clipped support the Gaussians multiply to one exponential
            r2 = 0.0
            for e in range(g.ndim):
                u = (d[e] + s * b[e]) / g.w
                r2 = r2 + u * u
            value = value * exp(-0.5 * r2)
        else:
            for e in range(g.ndim):
                value = value * _profile(g, d[e] + s * b[e])
        total = total + value
    return total


cdef inline double _erf_difference(double a, double b) noexcept nogil:
    if a > 0 and b > 0:
        return erfc(fabs(a)) - erfc(fabs(b))
    if a < 0 and b < 0:
        return erfc(fabs(b)) - erfc(fabs(a))
    return erf(b) - erf(a)


cdef double _segment(const Lattice* g, const double* d, const double* b) noexcept nogil:
    """``segment_integral`` of coarse_grain: the kernel product integrated along ``d + s b``."""
    cdef double s0 = 0.0, s1 = 1.0, lo, hi, t, length, a2 = 0.0, dot = 0.0, dd = 0.0, root, scale, perp
    cdef double cuts[5]
    cdef int e, m = 2, p, r
    for e in range(g.ndim):
        if b[e] == 0:
            if not fabs(d[e]) < g.c:
                return 0.0
            continue
        lo = (-g.c - d[e]) / b[e]
        hi = (g.c - d[e]) / b[e]
        if lo > hi:
            lo, hi = hi, lo
        s0 = s0 if s0 > lo else lo
        s1 = s1 if s1 < hi else hi
    length = s1 - s0
    if not length > 0:
        return 0.0
    if g.kernel == 2:
        return length
    if g.kernel == 1:
        cuts[0], cuts[1] = s0, s1
        for e in range(g.ndim):
            if b[e] != 0:
                t = -d[e] / b[e]
                if s0 < t < s1:
                    cuts[m] = t
                    m += 1
        for p in range(1, m):  # insertion sort of at most five
            t = cuts[p]
            r = p - 1
            while r >= 0 and cuts[r] > t:
                cuts[r + 1] = cuts[r]
                r -= 1
            cuts[r + 1] = t
        t = 0.0
        for p in range(m - 1):
            t = t + _legendre(g, d, b, cuts[p], cuts[p + 1], _GL7X, _GL7W, 7)
        return t
    for e in range(g.ndim):
        a2 = a2 + b[e] * b[e]
    root = sqrt(a2)
    if root * length <= 1e-3 * g.w:
        return _legendre(g, d, b, s0, s1, _GL8X, _GL8W, 8)
    for e in range(g.ndim):
        dot = dot + d[e] * b[e]
        dd = dd + d[e] * d[e]
    dot = dot / a2
    perp = dd - dot * dot * a2
    if perp < 0:
        perp = 0.0
    scale = root / (sqrt(2.0) * g.w)
    return exp(-0.5 * perp / (g.w * g.w)) * (sqrt(3.141592653589793) / (2 * scale)) * _erf_difference(
        (s0 + dot) * scale, (s1 + dot) * scale)


cdef struct Buffer:  # one thread's scratch space (C arrays written in a prange would be shared)
    double* weight
    int64_t* cells
    int64_t capacity
    int64_t low[3]
    int64_t count[3]
    int64_t k[3]
    double d0[3]
    double dv[3]
    double bv[3]


cdef inline void _grow(Buffer* buf, int64_t size) noexcept nogil:
    if size > buf.capacity:
        buf.capacity = 2 * size
        buf.weight = <double*> realloc(buf.weight, buf.capacity * sizeof(double))
        buf.cells = <int64_t*> realloc(buf.cells, buf.capacity * sizeof(int64_t))


def cg_segments(const int64_t[::1] axes, const double[::1] lower, const double[::1] spacing,
                const int64_t[::1] n, const uint8_t[::1] wrap, int kernel, double width, double cutoff,
                const double[:, ::1] start, const double[:, ::1] branch, const double[:, ::1] values):
    """Sum over segments ``start -> start - branch`` of ``values`` (M, q) times the kernel
    integrated along them at the cell centres, normalised to 1 over the lattice: (cells, q)."""
    cdef Lattice g = _lattice(axes, lower, spacing, n, wrap, kernel, width, cutoff)
    cdef Py_ssize_t ncells = 1, q = values.shape[1], nseg = start.shape[0], i, j
    cdef int d, threads = openmp.omp_get_max_threads()
    for d in range(g.ndim):
        ncells *= g.n[d]
    grids = np.zeros((threads, ncells, q))
    cdef double[:, :, ::1] out = grids
    cdef Buffer* buf = NULL
    cdef double* weight
    cdef int64_t* cells
    cdef int64_t size, p, at, part
    cdef double a0, a1, total, wt
    cdef double* o
    cdef bint inside
    with nogil, parallel():
        buf = <Buffer*> malloc(sizeof(Buffer))
        buf.weight, buf.cells, buf.capacity = NULL, NULL, 0
        for i in prange(nseg, schedule="dynamic", chunksize=256):
            size = 1
            for d in range(3):
                buf.low[d], buf.count[d], buf.d0[d], buf.bv[d] = 0, 1, 0.0, 0.0
            for d in range(g.ndim):
                a0 = start[i, g.axis[d]]
                a1 = a0 - branch[i, g.axis[d]]
                buf.low[d] = <int64_t> floor(((a0 if a0 < a1 else a1) - g.lower[d] - g.c) / g.h[d] - 0.5)
                buf.count[d] = <int64_t> floor((fabs(branch[i, g.axis[d]]) + 2 * g.c) / g.h[d]) + 2
                buf.bv[d] = branch[i, g.axis[d]]
                buf.d0[d] = a0
                size = size * buf.count[d]
            _grow(buf, size)
            weight, cells = buf.weight, buf.cells
            total = 0.0
            for p in range(size):
                buf.k[2] = p % buf.count[2]
                buf.k[1] = (p // buf.count[2]) % buf.count[1]
                buf.k[0] = p // (buf.count[2] * buf.count[1])
                inside = True
                cells[p] = 0
                for d in range(g.ndim):
                    buf.dv[d] = (g.lower[d] + ((buf.low[d] + buf.k[d]) + 0.5) * g.h[d]) - buf.d0[d]
                    if _cell(&g, d, buf.low[d] + buf.k[d], &part):
                        cells[p] += part
                    else:
                        inside = False
                weight[p] = _segment(&g, buf.dv, buf.bv)
                total = total + weight[p]
                if not inside:
                    cells[p] = -1
            if not total > 0:
                continue
            o = &out[threadid(), 0, 0]
            for p in range(size):
                if cells[p] < 0 or weight[p] == 0:
                    continue
                wt = weight[p] / total
                at = cells[p] * q
                for j in range(q):
                    o[at + j] += wt * values[i, j]
        free(buf.weight)
        free(buf.cells)
        free(buf)
    return grids.sum(axis=0)
