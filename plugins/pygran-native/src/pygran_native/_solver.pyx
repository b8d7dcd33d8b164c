# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled core of the native DEM solver: data in C arrays, the time-step loop nogil/threaded.

Layout (struct of arrays, particles stored in cell order, re-sorted at every neighbour
rebuild):

- particles: ``x, v, w, f, t, x0`` (3 per particle), ``r, m``, ``type``, ``pid``;
- half neighbour list (CSR over particles): partner ``nb_j`` (j > i), periodic image
  code ``nb_s`` (0..26, with the flags TOUCH and WRAP) and ``hs`` history values per pair:
  tangential displacement (3), the last normal force, and for Thornton-Ning the largest
  overlap, the unloading curvature radius and the plastic offset;
- wall list (CSR over particles): wall element ``wl_e`` and its ``whs = hs + 1`` history
  values: the contact's ``hs`` values and, for a plane, the side the contact started on
  (``+1`` along the plane's normal, ``-1`` against it, ``0`` while there is no contact);
- wall elements: planes, cylinders and triangles (with mesh topology and rigid motion).

Planes are two-sided: a new contact takes the side of the particle's centre and keeps it
while it lasts, so a deeply plastic contact whose centre sinks past the plane is still
pushed back to where it came from. A contact's history is carried across rebuilds and
re-sorts by looking the pair (or particle and wall element) up in the previous list (a
pair's tangential history changes sign with the pair's orientation).

Threads: the pair loop (pair and wall forces) runs over ``nblocks`` contiguous blocks of the
cell-sorted rows (slabs of the domain): 1 for one thread, BLOCKS per thread otherwise. The
bounds move after every step to where the work the loop counted (listed pairs, touching
pairs, wall entries) splits evenly. Forces on a block's own rows go to a shared buffer,
forces on later rows to the block's halo buffers (see Halo); the particle loop, over the same
blocks, adds them up in block order. The bounds are part of the state and the order of every
sum depends on the blocks only, so results are bitwise reproducible for a given thread count,
whichever thread runs a block.

The threads are the solver's own (team.h), started at the first run and asleep between
runs; the calling thread runs the time-step loop and hands each parallel pass out to the team
as blocks: each thread first takes its own share (the same slab step after step), then the
blocks others have not started. So a thread whose core is taken by another program delays a
pass by at most the block it is in, and threads with nothing to do sleep instead of spinning
(see team.h for why that matters).
"""

from libc.math cimport sqrt, floor, fabs, cos, sin, cbrt, M_PI, isfinite, INFINITY
from libc.stdlib cimport malloc, calloc, realloc, free
from libc.string cimport memcpy, memset
from libc.stdint cimport int64_t, uint8_t
from libc.limits cimport INT_MAX
from posix.time cimport clock_gettime, timespec, CLOCK_THREAD_CPUTIME_ID

cdef extern from "team.h":
    ctypedef struct pg_team:
        pass
    ctypedef void (*pg_task)(void* owner, unsigned int epoch, int phase, int nblocks, int tid) noexcept nogil
    pg_team* pg_create(int nqueues, double spin) noexcept nogil
    int pg_start(pg_team* t, pg_task task, void* owner) noexcept nogil
    void pg_destroy(pg_team* t) noexcept nogil
    double pg_now() noexcept nogil
    unsigned int pg_epoch(pg_team* t) noexcept nogil
    void pg_begin(pg_team* t, int phase, int nblocks) noexcept nogil
    int pg_claim(pg_team* t, unsigned int epoch, int tid) noexcept nogil
    void pg_finished(pg_team* t, int k, int nblocks) noexcept nogil
    void pg_wait_done(pg_team* t, int nblocks) noexcept nogil

import numpy as np
cimport numpy as cnp

cnp.import_array()

include "_defs.pxi"

MAX_THREADS = MAXTHREADS
MOTION_VALUES = NMOT
SLOT_VALUES = NSLOT
VIBRATION_VALUES = NVIB
#: Where :meth:`Core.take_lost` counts lost particles: the faces of the box, then non-finite.
LOST_PLACES = ("x-", "x+", "y-", "y+", "z-", "z+", "non-finite")

TIMERS = ("run", "drift", "walls", "pairs", "particles", "rebuild", "rebuild_cells", "rebuild_sort",
          "rebuild_permute", "rebuild_count", "rebuild_fill", "pairs_span", "particles_span")


include "_state.pxi"
include "_common.pxi"
include "_contact.pxi"
include "_geometry.pxi"
include "_neighbours.pxi"
include "_pairs.pxi"
include "_integrate.pxi"


cdef class Core:
    """Particles, neighbour and wall lists, wall elements and the time-step loop.

    Used through :class:`pygran_native.solver.Solver`, which validates arguments, orders
    outputs by id and builds the contact tables.
    """

    cdef public int n, cap, nthreads, hs, model, rolling, roff, ntypes, dirty
    cdef public double time, skin
    # the clock: time = t_base + (step - step_base) dt_base, re-based when dt changes, so it
    # does not accumulate round-off step by step
    cdef double t_base, dt_base
    cdef long long step_base
    cdef public long long step, lost, rebuilds
    # particles lost since the last take_lost: through each face x-, x+, y-, y+, z-, z+ of the
    # box and non-finite (LOST_PLACES), and the largest speed of those lost through a face
    cdef long long lost_at[7]
    cdef double lost_speed
    cdef double lo[3]
    cdef double hi[3]
    cdef double L[3]
    cdef int per[3]
    cdef double grav[3]
    cdef double shiftv[81]
    # particles
    cdef double *x
    cdef double *v
    cdef double *w
    cdef double *f
    cdef double *t
    cdef double *x0
    cdef double *r
    cdef double *m
    cdef int *type
    cdef int64_t *pid
    cdef double *buf        # forces and torques of the pair loop, cap * 6 (see pair_row)
    cdef double *halo       # the pair blocks' halo buffers, 6 per row (see Halo)
    cdef long long halo_cap
    cdef Halo *halos
    cdef int nfarblocks     # the blocks that can have far halos: those starting before row nfar
    cdef int *last          # the largest near partner (see Halo) of the rows up to i
    cdef int *flo           # row i's smallest and largest far partner (INT_MAX, -1: none)
    cdef int *fhi
    cdef int nfar           # rows after the first nfar have no far partners
    cdef int *perm
    cdef int *cell
    # neighbour list (current and previous)
    cdef int *nb_start
    cdef int *nb_j
    cdef uint8_t *nb_s
    cdef double *nb_h
    cdef long long nb_cap
    cdef int *ob_start
    cdef int *ob_j
    cdef uint8_t *ob_s
    cdef double *ob_h
    cdef long long ob_cap
    # wall list (current and previous)
    cdef int *wl_start
    cdef int *wl_e
    cdef double *wl_h
    cdef long long wl_cap
    cdef int *ow_start
    cdef int *ow_e
    cdef double *ow_h
    cdef long long ow_cap
    # cells
    cdef int nc[3]
    cdef int ax[3]          # axes from the slowest-varying in the cell index, see cell_id
    cdef double cs[3]
    cdef int ncells
    cdef int *cell_start
    cdef int cell_cap
    cdef int *ctri_start
    cdef int *ctri
    cdef long long ctri_cap
    cdef int binned_dirty     # triangles added, removed or set in motion since the last binning
    cdef double binned_reach
    cdef int binned_nc[3]
    # wall elements
    cdef public int ne
    cdef int ecap
    cdef int *ekind
    cdef int *etype
    cdef int *ewall
    cdef int *evid
    cdef int *emoving
    cdef double *egeo       # 9 per element: plane p,n; cylinder axis,c0,c1,R,inside; triangle vertices
    cdef double *eref       # triangle vertices at the motion's start
    cdef double *ebuilt     # triangle vertices at the last rebuild
    cdef double *emot       # NMOT per element, see motion_origin
    cdef public int nslots  # stress meshes (see Slot)
    cdef double *slots      # NSLOT per stress mesh
    cdef double *sacc       # the pair blocks' sums over stress meshes: SACC per mesh per block
    cdef public int nvib    # vibrating meshes (viblin, vibrot)
    cdef double *vib        # NVIB per vibrating mesh, see vibration
    # contact tables
    cdef Coef *coef
    cdef double *visc
    cdef double *tmax       # per thread (PAD apart): largest squared displacement
    cdef int nblocks        # blocks of the pair loop
    cdef int *pb            # rows [pb[b], pb[b + 1]) of the pair loop are block b
    cdef int *work          # work of each row in the last pair loop (see row_work)
    cdef long long *tstat   # per block (PAD apart): work of its rows, last row of its halo
    cdef pg_team *team      # the threads of a run (see pg_team)
    cdef Ctx ctx            # what the team's phases work on
    cdef int rows           # rows of the current row phase
    cdef Tuner tuner        # whether the master runs the phases with the team or alone
    cdef double timers[NTIMERS]
    cdef double *cpu        # per thread (PAD apart): CPU seconds in the pair and particle loops,
                            # in total and in the last step

    def __cinit__(self, lo, hi, periodic, gravity, double skin, int threads):
        cdef int d, a, b, c
        self.nthreads = threads
        self.skin = skin
        for d in range(3):
            self.lo[d] = lo[d]
            self.hi[d] = hi[d]
            self.L[d] = hi[d] - lo[d]
            self.per[d] = 1 if periodic[d] else 0
            self.grav[d] = gravity[d]
        for a in range(3):
            for b in range(3):
                for c in range(3):
                    d = 9 * a + 3 * b + c
                    self.shiftv[3 * d] = (a - 1) * self.L[0]
                    self.shiftv[3 * d + 1] = (b - 1) * self.L[1]
                    self.shiftv[3 * d + 2] = (c - 1) * self.L[2]
        self.hs = 4
        self.model = HERTZ
        self.dirty = 1
        self.nb_start = <int*>calloc(1, sizeof(int))
        self.ob_start = <int*>calloc(1, sizeof(int))
        self.wl_start = <int*>calloc(1, sizeof(int))
        self.ow_start = <int*>calloc(1, sizeof(int))
        if not 1 <= threads <= MAXTHREADS:
            raise ValueError(f"threads: between 1 and {MAXTHREADS}")
        self.nblocks = 1 if threads == 1 else BLOCKS * threads
        self.tmax = <double*>calloc(threads * PAD, sizeof(double))
        self.cpu = <double*>calloc(threads * PAD, sizeof(double))
        self.pb = <int*>calloc(self.nblocks + 1, sizeof(int))
        self.tstat = <long long*>calloc(self.nblocks * PAD, sizeof(long long))
        self.halos = <Halo*>calloc(self.nblocks, sizeof(Halo))
        self.team = pg_create(threads, SPIN)
        self.coef = <Coef*>calloc(1, sizeof(Coef))
        self.visc = <double*>calloc(1, sizeof(double))
        self.ntypes = 1
        if not (self.nb_start and self.ob_start and self.wl_start and self.ow_start and self.tmax and self.pb
                and self.tstat and self.cpu and self.halos and self.team):
            raise MemoryError()

    def __dealloc__(self):
        pg_destroy(self.team)
        for p in (<size_t>self.x, <size_t>self.v, <size_t>self.w, <size_t>self.f, <size_t>self.t,
                  <size_t>self.x0, <size_t>self.r, <size_t>self.m, <size_t>self.type, <size_t>self.pid,
                  <size_t>self.buf, <size_t>self.halo, <size_t>self.halos, <size_t>self.last,
                  <size_t>self.flo, <size_t>self.fhi,
                  <size_t>self.perm, <size_t>self.cell, <size_t>self.nb_start, <size_t>self.nb_j,
                  <size_t>self.nb_s, <size_t>self.nb_h, <size_t>self.ob_start, <size_t>self.ob_j,
                  <size_t>self.ob_s, <size_t>self.ob_h, <size_t>self.wl_start, <size_t>self.wl_e,
                  <size_t>self.wl_h, <size_t>self.ow_start, <size_t>self.ow_e, <size_t>self.ow_h,
                  <size_t>self.cell_start, <size_t>self.ctri_start, <size_t>self.ctri, <size_t>self.ekind,
                  <size_t>self.etype, <size_t>self.ewall, <size_t>self.evid, <size_t>self.emoving,
                  <size_t>self.egeo, <size_t>self.eref, <size_t>self.ebuilt, <size_t>self.emot,
                  <size_t>self.slots, <size_t>self.sacc, <size_t>self.vib,
                  <size_t>self.coef, <size_t>self.visc, <size_t>self.tmax,
                  <size_t>self.pb, <size_t>self.work, <size_t>self.tstat, <size_t>self.cpu):
            free(<void*>p)

    # ------------------------------------------------------------------ memory ----------
    cdef int reserve(self, int need) except -1:
        """Grow every per-particle array to hold ``need`` particles."""
        cdef int cap = self.cap
        cdef size_t c
        if need <= cap:
            return 0
        cap = max(need, 2 * cap, 64)
        c = cap
        self.x = <double*>self._grow(self.x, 3 * c * sizeof(double))
        self.v = <double*>self._grow(self.v, 3 * c * sizeof(double))
        self.w = <double*>self._grow(self.w, 3 * c * sizeof(double))
        self.f = <double*>self._grow(self.f, 3 * c * sizeof(double))
        self.t = <double*>self._grow(self.t, 3 * c * sizeof(double))
        self.x0 = <double*>self._grow(self.x0, 3 * c * sizeof(double))
        self.r = <double*>self._grow(self.r, c * sizeof(double))
        self.m = <double*>self._grow(self.m, c * sizeof(double))
        self.type = <int*>self._grow(self.type, c * sizeof(int))
        self.perm = <int*>self._grow(self.perm, c * sizeof(int))
        self.cell = <int*>self._grow(self.cell, c * sizeof(int))
        self.work = <int*>self._grow(self.work, c * sizeof(int))
        self.pid = <int64_t*>self._grow(self.pid, c * sizeof(int64_t))
        self.nb_start = <int*>self._grow(self.nb_start, (c + 1) * sizeof(int))
        self.ob_start = <int*>self._grow(self.ob_start, (c + 1) * sizeof(int))
        self.wl_start = <int*>self._grow(self.wl_start, (c + 1) * sizeof(int))
        self.ow_start = <int*>self._grow(self.ow_start, (c + 1) * sizeof(int))
        self.last = <int*>self._grow(self.last, c * sizeof(int))
        self.flo = <int*>self._grow(self.flo, c * sizeof(int))
        self.fhi = <int*>self._grow(self.fhi, c * sizeof(int))
        free(self.buf)
        self.buf = <double*>calloc(c * 6, sizeof(double))
        if self.buf == NULL:
            raise MemoryError()
        self.cap = cap
        return 0

    cdef void* _grow(self, void* p, size_t nbytes) except NULL:
        cdef void* q = grow(p, nbytes)
        if q == NULL:
            raise MemoryError()
        return q

    cdef int reserve_pairs(self, long long need) noexcept nogil:
        """Grow the current neighbour list to ``need`` pairs; -1 when out of memory."""
        cdef long long cap
        cdef void *a
        cdef void *b
        cdef void *c
        if need <= self.nb_cap:
            return 0
        cap = need + need // 10 + 64
        a = grow(self.nb_j, cap * sizeof(int))
        if a == NULL:
            return -1
        self.nb_j = <int*>a
        b = grow(self.nb_s, cap * sizeof(uint8_t))
        if b == NULL:
            return -1
        self.nb_s = <uint8_t*>b
        c = grow(self.nb_h, cap * self.hs * sizeof(double))
        if c == NULL:
            return -1
        self.nb_h = <double*>c
        self.nb_cap = cap
        return 0

    cdef int reserve_walls(self, long long need) noexcept nogil:
        cdef long long cap
        cdef void *a
        cdef void *b
        if need <= self.wl_cap:
            return 0
        cap = need + need // 10 + 64
        a = grow(self.wl_e, cap * sizeof(int))
        if a == NULL:
            return -1
        self.wl_e = <int*>a
        b = grow(self.wl_h, cap * (self.hs + 1) * sizeof(double))
        if b == NULL:
            return -1
        self.wl_h = <double*>b
        self.wl_cap = cap
        return 0

    # ------------------------------------------------------------------ set-up ----------
    def set_model(self, int model, int hs, int rolling, bint limit, double[:, ::1] E, double[:, ::1] G,
                  double[:, ::1] mu, double[:, ::1] mur, double[:, ::1] damp, double[:, ::1] coh,
                  double[:, ::1] py, double[:, ::1] rdamp, double vchar):
        """Install the pair tables (ntypes x ntypes) of a contact model and its rolling model
        (CDT, EPSD, EPSD2: those with a spring keep it in the last 3 of the ``hs`` history
        values); ``limit``: LIGGGHTS' limitForce. A new history layout resets histories."""
        cdef int nt = E.shape[0], a, b
        cdef Coef* c = <Coef*>calloc(nt * nt, sizeof(Coef))
        cdef double* vis = <double*>calloc(nt, sizeof(double))
        if c == NULL or vis == NULL:
            free(c)
            free(vis)
            raise MemoryError()
        for a in range(nt):
            for b in range(nt):
                c[a * nt + b].E = E[a, b]
                c[a * nt + b].G = G[a, b]
                c[a * nt + b].mu = mu[a, b]
                c[a * nt + b].mur = mur[a, b]
                c[a * nt + b].damp = damp[a, b]
                c[a * nt + b].tdamp = sqrt(4.0 * G[a, b] / E[a, b])
                c[a * nt + b].coh = coh[a, b]
                c[a * nt + b].py = py[a, b]
                c[a * nt + b].vchar = vchar
                c[a * nt + b].rdamp = rdamp[a, b]
                c[a * nt + b].limit = 1.0 if limit else 0.0
        for a in range(min(nt, self.ntypes)):
            vis[a] = self.visc[a]
        free(self.coef)
        free(self.visc)
        self.coef = c
        self.visc = vis
        self.ntypes = nt
        if hs != self.hs:
            free(self.nb_h)
            free(self.ob_h)
            free(self.wl_h)
            free(self.ow_h)
            self.nb_h = self.ob_h = self.wl_h = self.ow_h = NULL
            self.nb_cap = self.ob_cap = self.wl_cap = self.ow_cap = 0
            memset(self.nb_start, 0, (self.n + 1) * sizeof(int))
            memset(self.wl_start, 0, (self.n + 1) * sizeof(int))
            self.hs = hs
        self.model = model
        self.rolling = rolling
        self.roff = 0 if rolling == CDT else hs - 3
        self.dirty = 1

    def set_viscous(self, double[::1] gamma):
        cdef int a
        for a in range(min(gamma.shape[0], self.ntypes)):
            self.visc[a] = gamma[a]

    def add_particles(self, double[:, ::1] x, double[::1] r, double[::1] m, int[::1] typ,
                      double[:, ::1] v, double[:, ::1] w, int64_t[::1] ids):
        cdef int k = x.shape[0], i, d, base = self.n
        self.reserve(base + k)
        for i in range(k):
            for d in range(3):
                self.x[3 * (base + i) + d] = x[i, d]
                self.x0[3 * (base + i) + d] = x[i, d]
                self.v[3 * (base + i) + d] = v[i, d]
                self.w[3 * (base + i) + d] = w[i, d]
                self.f[3 * (base + i) + d] = 0.0
                self.t[3 * (base + i) + d] = 0.0
            self.r[base + i] = r[i]
            self.m[base + i] = m[i]
            self.type[base + i] = typ[i]
            self.pid[base + i] = ids[i]
            self.nb_start[base + i + 1] = self.nb_start[base]
            self.wl_start[base + i + 1] = self.wl_start[base]
        self.n = base + k
        self.dirty = 1

    def mark_removed(self, cnp.uint8_t[::1] mask):
        """Mark particles (storage order) for removal at the next rebuild."""
        cdef int i
        for i in range(self.n):
            if mask[i]:
                self.type[i] = -1
        self.dirty = 1

    def set_vectors(self, str name, int[::1] index, double[:, ::1] values):
        cdef double* a = self.v if name == "v" else self.w
        cdef int i, d
        for i in range(index.shape[0]):
            for d in range(3):
                a[3 * index[i] + d] = values[i, d]

    def set_radii(self, int[::1] index, double[::1] r, double[::1] m):
        """New radii and masses of particles (storage order); lists are rebuilt at the next run."""
        cdef int i
        for i in range(index.shape[0]):
            self.r[index[i]] = r[i]
            self.m[index[i]] = m[i]
        self.dirty = 1

    def add_elements(self, int[::1] kind, int[::1] etype, int[::1] wall, double[:, ::1] geo, int[:, ::1] vid):
        cdef int k = kind.shape[0], i, d, base = self.ne, cap = max(base + k, 2 * self.ecap, 8)
        if base + k > self.ecap:
            self.ekind = <int*>self._grow(self.ekind, cap * sizeof(int))
            self.etype = <int*>self._grow(self.etype, cap * sizeof(int))
            self.ewall = <int*>self._grow(self.ewall, cap * sizeof(int))
            self.emoving = <int*>self._grow(self.emoving, cap * sizeof(int))
            self.evid = <int*>self._grow(self.evid, 3 * cap * sizeof(int))
            self.egeo = <double*>self._grow(self.egeo, 9 * cap * sizeof(double))
            self.eref = <double*>self._grow(self.eref, 9 * cap * sizeof(double))
            self.ebuilt = <double*>self._grow(self.ebuilt, 9 * cap * sizeof(double))
            self.emot = <double*>self._grow(self.emot, NMOT * cap * sizeof(double))
            self.ecap = cap
        for i in range(k):
            self.ekind[base + i] = kind[i]
            self.etype[base + i] = etype[i]
            self.ewall[base + i] = wall[i]
            self.emoving[base + i] = 0
            for d in range(3):
                self.evid[3 * (base + i) + d] = vid[i, d]
            for d in range(9):
                self.egeo[9 * (base + i) + d] = geo[i, d]
                self.eref[9 * (base + i) + d] = geo[i, d]
                self.ebuilt[9 * (base + i) + d] = geo[i, d]
            for d in range(NMOT):
                self.emot[NMOT * (base + i) + d] = 0.0
        self.ne = base + k
        self.dirty = 1
        self.binned_dirty = 1

    def remove_elements(self, int wall):
        """Drop the elements of one wall; wall-list entries are renumbered, their histories kept."""
        cdef int e, k = 0, i, d
        cdef int* newidx = <int*>malloc((self.ne + 1) * sizeof(int))
        if newidx == NULL:
            raise MemoryError()
        for e in range(self.ne):
            if self.ewall[e] == wall:
                newidx[e] = -1
                continue
            newidx[e] = k
            self.ekind[k] = self.ekind[e]
            self.etype[k] = self.etype[e]
            self.ewall[k] = self.ewall[e]
            self.emoving[k] = self.emoving[e]
            for d in range(3):
                self.evid[3 * k + d] = self.evid[3 * e + d]
            for d in range(9):
                self.egeo[9 * k + d] = self.egeo[9 * e + d]
                self.eref[9 * k + d] = self.eref[9 * e + d]
                self.ebuilt[9 * k + d] = self.ebuilt[9 * e + d]
            for d in range(NMOT):
                self.emot[NMOT * k + d] = self.emot[NMOT * e + d]
            k += 1
        self.ne = k
        k = 0
        for i in range(self.n):
            e = self.wl_start[i]
            self.wl_start[i] = k
            while e < self.wl_start[i + 1]:
                if newidx[self.wl_e[e]] >= 0:
                    self.wl_e[k] = newidx[self.wl_e[e]]
                    for d in range(self.hs + 1):
                        self.wl_h[k * (self.hs + 1) + d] = self.wl_h[e * (self.hs + 1) + d]
                    k += 1
                e += 1
        self.wl_start[self.n] = k
        free(newidx)
        self.dirty = 1
        self.binned_dirty = 1
        self.set_slots(np.array([v for v in self.get_slots() if v[S_WALL] != wall]).reshape(-1, NSLOT))
        self.set_vibrations(np.array([v for v in self.get_vibrations() if v[0] != wall]).reshape(-1, NVIB))

    def set_motion(self, int wall, double[::1] vel, double[::1] omega, double[::1] origin,
                   double[::1] amplitude, double period):
        """Rigid motion of a wall's triangles from now on (see motion_origin); ``period`` 0:
        no wiggle."""
        cdef int e, d
        cdef bint moving = period > 0.0
        for d in range(3):
            moving = moving or vel[d] != 0.0 or omega[d] != 0.0
        for e in range(self.ne):
            if self.ewall[e] != wall or self.ekind[e] != TRIANGLE:
                continue
            for d in range(9):
                self.eref[9 * e + d] = self.egeo[9 * e + d]
            for d in range(3):
                self.emot[NMOT * e + d] = vel[d]
                self.emot[NMOT * e + 3 + d] = omega[d]
                self.emot[NMOT * e + 6 + d] = origin[d]
                self.emot[NMOT * e + 10 + d] = amplitude[d]
            self.emot[NMOT * e + 9] = self.time
            self.emot[NMOT * e + 13] = period
            self.emoving[e] = moving
        self.dirty = 1
        self.binned_dirty = 1

    def get_vibrations(self):
        """The vibrating meshes' values, (nvib, NVIB) (see vibration)."""
        return _copy_d(self.vib, NVIB * self.nvib).reshape(self.nvib, NVIB)

    def set_vibrations(self, double[:, ::1] values):
        """Replace the vibrating meshes' values; their triangles vibrate about their positions
        at the start of their motion (set_motion, with no other motion)."""
        cdef int k = values.shape[0], e, s
        cdef void* q = malloc(max(k, 1) * NVIB * sizeof(double))
        if q == NULL:
            raise MemoryError()
        if k:
            memcpy(q, &values[0, 0], k * NVIB * sizeof(double))
        free(self.vib)
        self.vib = <double*>q
        self.nvib = k
        for s in range(k):
            for e in range(self.ne):
                if self.ewall[e] == <int>self.vib[NVIB * s] and self.ekind[e] == TRIANGLE:
                    self.emoving[e] = 1
        self.dirty = 1
        self.binned_dirty = 1

    def get_slots(self):
        """The stress meshes' values, (nslots, NSLOT) (see Slot)."""
        return _copy_d(self.slots, NSLOT * self.nslots).reshape(self.nslots, NSLOT)

    def set_slots(self, double[:, ::1] values):
        """Replace the stress meshes' values; a servo's triangles move from their positions now
        (their reference), and move with the wall list's rebuilds."""
        cdef int k = values.shape[0], e, s, d
        cdef size_t nbytes = max(k, 1) * NSLOT * sizeof(double)
        cdef void* p = calloc(max(k, 1) * self.nblocks * SACC, sizeof(double))
        cdef void* q = malloc(nbytes)
        if p == NULL or q == NULL:
            free(p)
            free(q)
            raise MemoryError()
        if k:
            memcpy(q, &values[0, 0], k * NSLOT * sizeof(double))
        free(self.sacc)
        free(self.slots)
        self.sacc = <double*>p
        self.slots = <double*>q
        self.nslots = k
        for s in range(k):
            if self.slots[NSLOT * s + S_CONTROL] == 0.0:
                continue
            for e in range(self.ne):
                if self.ewall[e] == <int>self.slots[NSLOT * s + S_WALL] and self.ekind[e] == TRIANGLE \
                        and not self.emoving[e]:
                    for d in range(9):
                        self.eref[9 * e + d] = self.egeo[9 * e + d]
                    self.emoving[e] = 1
        self.dirty = 1
        self.binned_dirty = 1

    # ------------------------------------------------------------------ rebuild ---------
    cdef int setup_cells(self, double rmax) noexcept nogil:
        """Cell grid of side >= 2 rmax + skin over the box; -1 when out of memory."""
        cdef double cut, size
        cdef int d, k
        cdef long long total
        cdef void* p
        cut = 2.0 * rmax + self.skin
        size = cut
        while True:
            total = 1
            for d in range(3):
                self.nc[d] = <int>floor(self.L[d] / size)
                if self.nc[d] < 1:
                    self.nc[d] = 1
                self.cs[d] = self.L[d] / self.nc[d]
                total *= self.nc[d]
            if total <= 4 * <long long>self.n + 4096:
                break
            size *= 1.26
        self.ncells = <int>total
        # axes by decreasing cell count (ties: z before y before x)
        self.ax[0], self.ax[1], self.ax[2] = 2, 1, 0
        for d in range(2):
            for k in range(2 - d):
                if self.nc[self.ax[k + 1]] > self.nc[self.ax[k]]:
                    self.ax[k], self.ax[k + 1] = self.ax[k + 1], self.ax[k]
        if self.ncells + 2 > self.cell_cap:
            p = grow(self.cell_start, (self.ncells + 2) * sizeof(int))
            if p == NULL:
                return -1
            self.cell_start = <int*>p
            p = grow(self.ctri_start, (self.ncells + 2) * sizeof(int))
            if p == NULL:
                return -1
            self.ctri_start = <int*>p
            self.cell_cap = self.ncells + 2
        return 0

    cdef inline int cell_of(self, const double* p) noexcept nogil:
        cdef int cc[3]
        return locate(p, self.lo, self.cs, self.nc, self.ax, cc)

    cdef void tri_cells(self, int e, double reach, int* lo3, int* hi3) noexcept nogil:
        """Range of cells within ``reach`` of triangle e's bounding box."""
        cdef double mn, mx, val
        cdef int a, d
        for d in range(3):
            mn = self.egeo[9 * e + d]
            mx = mn
            for a in range(1, 3):
                val = self.egeo[9 * e + 3 * a + d]
                if val < mn:
                    mn = val
                if val > mx:
                    mx = val
            lo3[d] = <int>floor((mn - reach - self.lo[d]) / self.cs[d])
            hi3[d] = <int>floor((mx + reach - self.lo[d]) / self.cs[d])
            if lo3[d] < 0:
                lo3[d] = 0
            if hi3[d] >= self.nc[d]:
                hi3[d] = self.nc[d] - 1

    cdef inline bint tri_near_cell(self, int e, int a, int b, int c, double reach) noexcept nogil:
        """Whether cell (a, b, c) comes within ``reach`` of triangle e's plane."""
        cdef double half, ln
        cdef double u[3]
        cdef double v[3]
        cdef double nrm[3]
        cdef double ctr[3]
        cdef const double* g = &self.egeo[9 * e]
        cdef int d
        for d in range(3):
            u[d] = g[3 + d] - g[d]
            v[d] = g[6 + d] - g[d]
        cross3(u, v, nrm)
        ln = sqrt(dot3(nrm, nrm))
        ctr[0] = self.lo[0] + (a + 0.5) * self.cs[0] - g[0]
        ctr[1] = self.lo[1] + (b + 0.5) * self.cs[1] - g[1]
        ctr[2] = self.lo[2] + (c + 0.5) * self.cs[2] - g[2]
        half = 0.5 * sqrt(self.cs[0] * self.cs[0] + self.cs[1] * self.cs[1] + self.cs[2] * self.cs[2])
        return fabs(dot3(nrm, ctr)) <= (reach + half) * ln

    cdef int bin_triangles(self, double reach) noexcept nogil:
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
        memset(self.ctri_start, 0, (self.ncells + 1) * sizeof(int))
        for e in range(self.ne):
            if self.ekind[e] == TRIANGLE:
                self.tri_cells(e, reach, lo3, hi3)
                for c in range(lo3[2], hi3[2] + 1):
                    for b in range(lo3[1], hi3[1] + 1):
                        for a in range(lo3[0], hi3[0] + 1):
                            if self.tri_near_cell(e, a, b, c, reach):
                                abc[0] = a
                                abc[1] = b
                                abc[2] = c
                                self.ctri_start[cell_id(self.nc, self.ax, abc) + 1] += 1
        for c in range(self.ncells):
            self.ctri_start[c + 1] += self.ctri_start[c]
        total = self.ctri_start[self.ncells]
        if total + 1 > self.ctri_cap:
            p = grow(self.ctri, (total + 1) * sizeof(int))
            if p == NULL:
                return -1
            self.ctri = <int*>p
            self.ctri_cap = total + 1
        memcpy(self.cell_start, self.ctri_start, (self.ncells + 1) * sizeof(int))
        for e in range(self.ne):
            if self.ekind[e] == TRIANGLE:
                self.tri_cells(e, reach, lo3, hi3)
                for c in range(lo3[2], hi3[2] + 1):
                    for b in range(lo3[1], hi3[1] + 1):
                        for a in range(lo3[0], hi3[0] + 1):
                            if self.tri_near_cell(e, a, b, c, reach):
                                abc[0] = a
                                abc[1] = b
                                abc[2] = c
                                cc = cell_id(self.nc, self.ax, abc)
                                self.ctri[self.cell_start[cc]] = e
                                self.cell_start[cc] += 1
        return 0

    cdef void make_ctx(self, Ctx* c) noexcept nogil:
        cdef int d
        c.n = self.n
        c.cap = self.cap
        c.hs = self.hs
        c.rolling = self.rolling
        c.roff = self.roff
        c.whs = self.hs + 1
        c.model = self.model
        c.nt = self.ntypes
        c.nblocks = self.nblocks
        c.ncells = self.ncells
        for d in range(3):
            c.nc[d] = self.nc[d]
            c.ax[d] = self.ax[d]
            c.cs[d] = self.cs[d]
            c.lo[d] = self.lo[d]
            c.grav[d] = self.grav[d]
        c.skin = self.skin
        c.time = self.time
        c.x = self.x
        c.v = self.v
        c.w = self.w
        c.f = self.f
        c.t = self.t
        c.x0 = self.x0
        c.tmax = self.tmax
        c.r = self.r
        c.m = self.m
        c.type = self.type
        c.buf = self.buf
        c.halo = self.halo
        c.halos = self.halos
        c.nfarblocks = self.nfarblocks
        c.last = self.last
        c.pb = self.pb
        c.work = self.work
        c.tstat = self.tstat
        c.perm = self.perm
        c.cell = self.cell
        c.nb_start = self.nb_start
        c.nb_j = self.nb_j
        c.nb_s = self.nb_s
        c.nb_h = self.nb_h
        c.ob_start = self.ob_start
        c.ob_j = self.ob_j
        c.ob_s = self.ob_s
        c.ob_h = self.ob_h
        c.wl_start = self.wl_start
        c.wl_e = self.wl_e
        c.wl_h = self.wl_h
        c.ow_start = self.ow_start
        c.ow_e = self.ow_e
        c.ow_h = self.ow_h
        c.cell_start = self.cell_start
        c.ctri_start = self.ctri_start
        c.ctri = self.ctri
        c.per = self.per
        c.shiftv = self.shiftv
        c.ne = self.ne
        c.ekind = self.ekind
        c.etype = self.etype
        c.evid = self.evid
        c.emoving = self.emoving
        c.egeo = self.egeo
        c.emot = self.emot
        c.ewall = self.ewall
        c.nslots = self.nslots
        c.slots = self.slots
        c.sacc = self.sacc
        c.nvib = self.nvib
        c.vib = self.vib
        c.coef = self.coef
        c.visc = self.visc
        c.cpu = self.cpu

    cdef void permute(self, int n) noexcept nogil:
        """Reorder the particle arrays by ``perm`` in three parallel passes. f, t and x0 are
        recomputed after a rebuild, so they serve as scratch: x, v and w are gathered into them
        and swapped with them; r, m, type and pid are gathered into the old x and v, then
        copied back while x0 becomes a copy of x (see rebuild_rows)."""
        cdef double* p
        self.parallel_rows(P_GATHER, n)
        p = self.x; self.x = self.f; self.f = p
        p = self.v; self.v = self.t; self.t = p
        p = self.w; self.w = self.x0; self.x0 = p
        self.parallel_rows(P_GATHER_SCALARS, n)
        self.parallel_rows(P_COPY_BACK, n)

    cdef void rebuild_rows(self, int phase, int lo, int hi) noexcept nogil:
        """Rows [lo, hi) of a parallel pass of the rebuild."""
        cdef int i, d, n = self.rows
        cdef int* perm = self.perm
        cdef double* sr = self.f
        cdef double* sm = self.f + n
        cdef int* st = <int*>(self.f + 2 * n)
        cdef int64_t* sp = <int64_t*>self.t
        if phase == P_PLACE:
            for i in range(lo, hi):
                self.cell[i] = self._place(i)
        elif phase == P_GATHER:   # into f, t, x0 (swapped with x, v, w afterwards)
            for i in range(lo, hi):
                for d in range(3):
                    self.f[3 * i + d] = self.x[3 * perm[i] + d]
                    self.t[3 * i + d] = self.v[3 * perm[i] + d]
                    self.x0[3 * i + d] = self.w[3 * perm[i] + d]
        elif phase == P_GATHER_SCALARS:
            for i in range(lo, hi):
                sr[i] = self.r[perm[i]]
                sm[i] = self.m[perm[i]]
                st[i] = self.type[perm[i]]
                sp[i] = self.pid[perm[i]]
        elif phase == P_COPY_BACK:
            for i in range(lo, hi):
                self.r[i] = sr[i]
                self.m[i] = sm[i]
                self.type[i] = st[i]
                self.pid[i] = sp[i]
                for d in range(3):
                    self.x0[3 * i + d] = self.x[3 * i + d]
        elif phase == P_COUNT:
            for i in range(lo, hi):
                self.nb_start[i + 1] = scan_pairs(&self.ctx, i, False)
                self.wl_start[i + 1] = scan_walls(&self.ctx, i, False)
        elif phase == P_FILL:
            for i in range(lo, hi):
                scan_pairs(&self.ctx, i, True)
                scan_walls(&self.ctx, i, True)
                self.work[i] = self.estimated_work(i)
                self.find_partners(i)

    cdef inline void find_partners(self, int i) noexcept nogil:
        """Row i's largest near partner (``last``, -1: none) and its smallest and largest far
        partner (``flo``, ``fhi``; INT_MAX and -1: none), see Halo."""
        cdef int k, j
        self.last[i] = -1
        self.flo[i] = INT_MAX
        self.fhi[i] = -1
        for k in range(self.nb_start[i], self.nb_start[i + 1]):
            j = self.nb_j[k]
            if self.nb_s[k] & WRAP:
                self.flo[i] = min(self.flo[i], j)
                self.fhi[i] = max(self.fhi[i], j)
            elif j > self.last[i]:
                self.last[i] = j

    cdef void prefix_last(self) noexcept nogil:
        """``last``: from each row's largest near partner to the largest of the rows up to it;
        ``nfar`` after the last row with a far partner."""
        cdef int i
        self.nfar = 0
        for i in range(self.n):
            if i > 0 and self.last[i - 1] > self.last[i]:
                self.last[i] = self.last[i - 1]
            if self.fhi[i] >= 0:
                self.nfar = i + 1

    cdef int rebuild(self) noexcept nogil:
        """Wrap, drop lost particles, sort into cells, rebuild both lists carrying histories."""
        cdef int i, d, n = self.n, nnew
        cdef long long lost = 0
        cdef double rmax = 0.0
        cdef int *ip
        cdef uint8_t *bp
        cdef double *dp
        cdef long long cap
        cdef double t0 = pg_now(), t1
        for i in range(n):
            if self.r[i] > rmax:
                rmax = self.r[i]
        if self.setup_cells(rmax) < 0:
            return -1
        if self.binned_dirty or self.binned_reach != rmax + self.skin or self.any_moving() \
                or self.binned_nc[0] != self.nc[0] or self.binned_nc[1] != self.nc[1] or self.binned_nc[2] != self.nc[2]:
            if self.bin_triangles(rmax + self.skin) < 0:
                return -1
            self.binned_dirty = 0
            self.binned_reach = rmax + self.skin
            for d in range(3):
                self.binned_nc[d] = self.nc[d]
        t1 = self.lap(T_CELLS, t0)
        # wrap periodic coordinates, mark particles outside a fixed boundary (or removed) lost
        self.parallel_rows(P_PLACE, n)
        for i in range(n):
            if self.cell[i] < 0:
                if self.cell[i] == -1:
                    lost += 1
                    self.count_lost(i)
                self.cell[i] = self.ncells
        self.lost += lost
        # counting sort by cell (lost ones in the sentinel cell ncells)
        memset(self.cell_start, 0, (self.ncells + 2) * sizeof(int))
        for i in range(n):
            self.cell_start[self.cell[i] + 1] += 1
        for i in range(self.ncells + 1):
            self.cell_start[i + 1] += self.cell_start[i]
        for i in range(n):
            self.perm[self.cell_start[self.cell[i]]] = i
            self.cell_start[self.cell[i]] += 1
        for i in range(self.ncells + 1, 0, -1):
            self.cell_start[i] = self.cell_start[i - 1]
        self.cell_start[0] = 0
        nnew = self.cell_start[self.ncells]
        t1 = self.lap(T_SORT, t1)
        self.permute(nnew)
        t1 = self.lap(T_PERMUTE, t1)
        # the current lists become the previous ones
        ip = self.ob_start; self.ob_start = self.nb_start; self.nb_start = ip
        ip = self.ob_j; self.ob_j = self.nb_j; self.nb_j = ip
        bp = self.ob_s; self.ob_s = self.nb_s; self.nb_s = bp
        dp = self.ob_h; self.ob_h = self.nb_h; self.nb_h = dp
        cap = self.ob_cap; self.ob_cap = self.nb_cap; self.nb_cap = cap
        ip = self.ow_start; self.ow_start = self.wl_start; self.wl_start = ip
        ip = self.ow_e; self.ow_e = self.wl_e; self.wl_e = ip
        dp = self.ow_h; self.ow_h = self.wl_h; self.wl_h = dp
        cap = self.ow_cap; self.ow_cap = self.wl_cap; self.wl_cap = cap
        self.n = nnew
        self.make_ctx(&self.ctx)
        self.parallel_rows(P_COUNT, nnew)
        self.nb_start[0] = 0
        self.wl_start[0] = 0
        for i in range(nnew):
            self.nb_start[i + 1] += self.nb_start[i]
            self.wl_start[i + 1] += self.wl_start[i]
        if self.reserve_pairs(self.nb_start[nnew]) < 0 or self.reserve_walls(self.wl_start[nnew]) < 0:
            return -1
        t1 = self.lap(T_COUNT, t1)
        self.make_ctx(&self.ctx)
        self.parallel_rows(P_FILL, nnew)
        self.prefix_last()
        for i in range(9 * self.ne):
            self.ebuilt[i] = self.egeo[i]
        self.balance()
        self.lap(T_FILL, t1)
        self.lap(T_REBUILD, t0)
        self.rebuilds += 1
        return 0

    cdef void count_lost(self, int i) noexcept nogil:
        """Count lost particle i at the face of the box it is furthest beyond (or as non-finite),
        and its speed."""
        cdef int d, place = 6
        cdef double p, beyond = 0.0, speed = 0.0
        for d in range(3):
            if not (isfinite(self.x[3 * i + d]) and isfinite(self.v[3 * i + d])):
                self.lost_at[6] += 1
                return
            speed += self.v[3 * i + d] * self.v[3 * i + d]
        for d in range(3):
            p = self.x[3 * i + d]
            if self.per[d]:
                continue
            if self.lo[d] - p > beyond:
                beyond = self.lo[d] - p
                place = 2 * d
            elif p - self.hi[d] > beyond:
                beyond = p - self.hi[d]
                place = 2 * d + 1
        self.lost_at[place] += 1
        if sqrt(speed) > self.lost_speed:
            self.lost_speed = sqrt(speed)

    def take_lost(self):
        """Particles lost since the last call, by place (``LOST_PLACES``), and the largest speed
        of those lost through a face (0 if none); resets both."""
        counts = np.array([self.lost_at[k] for k in range(7)], dtype=np.int64)
        speed = self.lost_speed
        memset(self.lost_at, 0, 7 * sizeof(long long))
        self.lost_speed = 0.0
        return counts, speed

    cdef inline double lap(self, int k, double since) noexcept nogil:
        """Add the wall-clock time since ``since`` to timer k; returns now."""
        cdef double now = pg_now()
        self.timers[k] += now - since
        return now

    cdef inline int _place(self, int i) noexcept nogil:
        """Wrap particle i into the periodic box; its cell, -1 if lost, -2 if removed."""
        cdef int d
        cdef double p
        if self.type[i] < 0:
            return -2
        for d in range(3):
            p = self.x[3 * i + d]
            if not isfinite(p):
                return -1
            if self.per[d]:
                if p < self.lo[d] or p >= self.hi[d]:
                    p -= self.L[d] * floor((p - self.lo[d]) / self.L[d])
                    if p >= self.hi[d]:
                        p = self.lo[d]
                    self.x[3 * i + d] = p
            elif p < self.lo[d] or p > self.hi[d]:
                return -1
        return self.cell_of(&self.x[3 * i])

    cdef bint any_moving(self) noexcept nogil:
        cdef int e
        for e in range(self.ne):
            if self.emoving[e]:
                return True
        return False

    cdef double move_walls(self) noexcept nogil:
        """Place moving triangles at the current time (a servo's where its controller has
        taken it); largest vertex move since the rebuild."""
        cdef int e, k, d, last = -1, slot
        cdef double dmax = 0.0, dd, s
        cdef double Rm[9]
        cdef double rel[3]
        cdef double o[3]
        cdef double vo[3]
        cdef double o0[3]
        cdef double* mot
        cdef double* ref
        cdef double* cur
        cdef double* sl
        cdef const double* vb
        cdef double sv, dsv
        memset(o, 0, 3 * sizeof(double))   # set at each wall's first element
        memset(o0, 0, 3 * sizeof(double))
        for e in range(self.ne):
            if not self.emoving[e]:
                continue
            if self.ewall[e] != last:
                last = self.ewall[e]
                slot = -1
                for k in range(self.nslots):
                    if self.slots[NSLOT * k + S_WALL] == last and self.slots[NSLOT * k + S_CONTROL] != 0.0:
                        slot = k
                if slot >= 0:   # a force servo translates by com - com0, a torque servo turns by phi
                    sl = &self.slots[NSLOT * slot]
                    for d in range(3):
                        o[d] = sl[S_XCM + d]
                        o0[d] = sl[S_XCM0 + d]
                    rotation(&sl[S_AXIS], sl[S_PHI] if sl[S_CONTROL] == 2.0 else 0.0, Rm)
                else:
                    mot = &self.emot[NMOT * e]
                    motion_origin(mot, self.time - mot[9], o, vo)
                    rotation(&mot[3], self.time - mot[9], Rm)
                    for d in range(3):
                        o0[d] = mot[6 + d]
                    vb = vibration_of(self.vib, self.nvib, last) if self.nvib else NULL
                    if vb != NULL:   # viblin: the origin moves along the axis; vibrot: turns about it
                        vibration(vb, self.time - mot[9], &sv, &dsv)
                        if vb[1] == 1.0:
                            for d in range(3):
                                o[d] += sv * vb[3 + d]
                        else:
                            rotation(&vb[3], sv, Rm)
            for k in range(3):
                ref = &self.eref[9 * e + 3 * k]
                cur = &self.egeo[9 * e + 3 * k]
                for d in range(3):
                    rel[d] = ref[d] - o0[d]
                dd = 0.0
                for d in range(3):
                    cur[d] = o[d] + Rm[3 * d] * rel[0] + Rm[3 * d + 1] * rel[1] + Rm[3 * d + 2] * rel[2]
                    s = cur[d] - self.ebuilt[9 * e + 3 * k + d]
                    dd += s * s
                if dd > dmax:
                    dmax = dd
        return sqrt(dmax)

    cdef void servo_move(self, double dt) noexcept nogil:
        """The servos' move at the start of a step (LIGGGHTS' initial_integrate): com by
        dt times the velocity, or the angle by dt times the angular velocity along the axis."""
        cdef int s, d
        cdef double* sl
        for s in range(self.nslots):
            sl = &self.slots[NSLOT * s]
            if sl[S_CONTROL] == 1.0:
                for d in range(3):
                    sl[S_XCM + d] += dt * sl[S_VEL + d]
            elif sl[S_CONTROL] == 2.0:
                sl[S_PHI] += dt * dot3(&sl[S_VEL], &sl[S_AXIS])

    cdef void servo_sums(self) noexcept nogil:
        """The particles' force, torque and contacts on each stress mesh: the pair blocks'
        sums, added in block order (the same bits whichever thread ran a block)."""
        cdef int s, b, k
        cdef double* sl
        cdef const double* a
        for s in range(self.nslots):
            sl = &self.slots[NSLOT * s]
            for k in range(7):
                sl[S_FORCE + k] = 0.0
            for b in range(self.nblocks):
                a = &self.sacc[SACC * (self.nslots * b + s)]
                for k in range(7):
                    sl[S_FORCE + k] += a[k]

    cdef void servo_control(self, double dt) noexcept nogil:
        """The servos' new output at the end of a step: LIGGGHTS' final_integrate and limit_vel
        of mesh_module_stress_servo.cpp (its PID law on the force or torque along the axis, the
        piecewise P law of mode auto, the saturation and the integral's anti-windup)."""
        cdef int s, d
        cdef double* sl
        cdef double pv, err, kp, mag, vmag, limit, spinv, low = 0.9, high = 1.0, scale = 0.1
        for s in range(self.nslots):
            sl = &self.slots[NSLOT * s]
            if sl[S_CONTROL] == 0.0:
                continue
            pv = dot3(&sl[S_FORCE if sl[S_CONTROL] == 1.0 else S_TORQUE], &sl[S_AXIS])
            spinv = 1.0 / fabs(sl[S_SP])
            if sl[S_AUTO] != 0.0:
                err = (sl[S_SP] - pv) * spinv
                if sl[S_CONTACTS] == 0.0:   # cruise
                    kp = sl[S_OPMAX]
                elif fabs(err) <= low:
                    kp = scale * sl[S_OPMIN]
                elif fabs(err) >= high:
                    kp = sl[S_OPMIN]
                else:
                    kp = scale * sl[S_OPMIN] + (1.0 - scale) * sl[S_OPMIN] * (fabs(err) - low) / (high - low)
                mag = -kp * err
            else:
                err = sl[S_SP] - pv
                sl[S_SUM] += err * dt
                # the derivative of the force, not of the error (no spike when the set point changes)
                mag = -sl[S_OPMAX] * (err * sl[S_KP] + sl[S_SUM] * sl[S_KI]
                                      - (pv - sl[S_OLDPV]) / dt * sl[S_KD]) * spinv
                sl[S_OLDPV] = pv
            for d in range(3):
                sl[S_VEL + d] = sl[S_AXIS + d] * mag
            vmag = sqrt(dot3(&sl[S_VEL], &sl[S_VEL]))
            limit = sl[S_OPMIN] if sl[S_AUTO] != 0.0 and sl[S_CONTACTS] > 0.0 else sl[S_OPMAX]
            if vmag > limit and vmag != 0.0:
                for d in range(3):
                    sl[S_VEL + d] *= limit / vmag
                if sl[S_KI] > 0.0:   # anti-windup: LIGGGHTS' inverted controller equation
                    mag = dot3(&sl[S_VEL], &sl[S_AXIS])
                    sl[S_SUM] = (-((mag > 0.0) - (mag < 0.0)) * sl[S_SP] - err * sl[S_KP]) / sl[S_KI]

    cdef void servo_start(self, double dt) noexcept nogil:
        """As a run starts (LIGGGHTS' init): mode auto's speed in contact from the smallest
        particle present (a radius of 1e6 m without particles, as LIGGGHTS)."""
        cdef int s, i
        cdef double rmin = 1e6
        for i in range(self.n):
            rmin = min(rmin, self.r[i])
        for s in range(self.nslots):
            self.slots[NSLOT * s + S_OPMIN] = self.slots[NSLOT * s + S_RATIO] * rmin / dt \
                / self.slots[NSLOT * s + S_RPA]

    cdef inline int estimated_work(self, int i) noexcept nogil:
        """Row i's work in the pair loop, counting the pairs that touched at the last step."""
        cdef int k, touching = 0
        for k in range(self.nb_start[i], self.nb_start[i + 1]):
            touching += (self.nb_s[k] & TOUCH) != 0
        return row_work(self.nb_start[i + 1] - self.nb_start[i], touching,
                        self.wl_start[i + 1] - self.wl_start[i])

    cdef void balance(self) noexcept nogil:
        """Split the (cell-sorted) rows of the pair loop into ``nblocks`` blocks of about equal
        ``work``: each a spatial slab, so few neighbours belong to another block."""
        cdef int t, i = 0, n = self.n, T = self.nblocks
        cdef long long total = 0, prefix = 0
        for t in range(n):
            total += self.work[t]
        for t in range(1, T):
            while i < n and prefix < total * t // T:
                prefix += self.work[i]
                i += 1
            self.pb[t] = i
        self.pb[0] = 0
        self.pb[T] = n

    cdef void rebalance(self) noexcept nogil:
        """Move each bound of the pair loop to where the work of the loop just run splits
        evenly (the first row where its prefix reaches ``total t / T``), walking from where the
        bound was: the partition follows contacts as they form, and depends only on the state."""
        cdef int t, b, T = self.nblocks
        cdef long long total = 0, old = 0, prefix, target
        for t in range(T):
            total += self.tstat[PAD * t]
        for t in range(1, T):
            old += self.tstat[PAD * (t - 1)]   # the work before the old bound t
            target = total * t // T
            b = self.pb[t]
            prefix = old
            while b > 0 and prefix - self.work[b - 1] >= target:
                b -= 1
                prefix -= self.work[b]
            while b < self.n and prefix < target:
                prefix += self.work[b]
                b += 1
            self.pb[t] = b

    cdef int forces(self, double dt, bint update, bint kick, bint fuse) noexcept nogil:
        """Forces (pair loop, then per particle), second half kick; ``fuse``: see particle_row.
        -1 when out of memory.

        The pair loop's blocks (see pair_row) fix the order of the sums and depend only on the
        state: results are deterministic for a given thread count, whichever thread runs a
        block. The particle loop takes the same blocks of rows, so a thread that ran a block
        of the pair loop usually sums and integrates the same rows.
        """
        cdef int t, T = self.nthreads
        cdef double t0 = pg_now()
        cdef double span[2]
        span[0] = span[1] = 0.0
        if self.place_halos() < 0:
            return -1
        self.make_ctx(&self.ctx)
        self.ctx.dt = dt
        self.ctx.update = update
        self.ctx.kick = kick
        self.ctx.fuse = fuse
        for t in range(T):
            self.tmax[PAD * t] = 0.0
            self.cpu[PAD * t + 2] = 0.0
            self.cpu[PAD * t + 3] = 0.0
        self.run_phase(P_PAIRS, self.nblocks)
        if self.nslots:
            self.servo_sums()
            if update:
                self.servo_control(dt)
        t0 = self.lap(T_PAIRS, t0)
        self.run_phase(P_PARTICLES, self.nblocks)
        self.rebalance()
        self.lap(T_PARTICLES, t0)
        for t in range(T):   # the busiest thread's CPU time: the loops' wall time on idle cores
            self.cpu[PAD * t] += self.cpu[PAD * t + 2]
            self.cpu[PAD * t + 1] += self.cpu[PAD * t + 3]
            span[0] = max(span[0], self.cpu[PAD * t + 2])
            span[1] = max(span[1], self.cpu[PAD * t + 3])
        self.timers[T_PAIRS_SPAN] += span[0]
        self.timers[T_PARTICLES_SPAN] += span[1]
        return 0

    cdef int place_halos(self) noexcept nogil:
        """The pair blocks' halos (see Halo) for the current bounds; -1 when out of memory."""
        cdef int b, i, start, end
        cdef long long total = 0
        cdef Halo* h
        cdef void* p
        self.nfarblocks = 0
        for b in range(self.nblocks):
            h = &self.halos[b]
            start = self.pb[b]
            end = self.pb[b + 1]
            h.near_off = total
            h.near_end = end - 1
            if end > start and end < self.n and self.last[end - 1] >= end:
                h.near_end = self.last[end - 1]
                total += h.near_end - end + 1
            h.far_lo = INT_MAX
            h.far_hi = -1
            for i in range(start, min(end, self.nfar)):
                if self.fhi[i] > h.near_end:
                    h.far_lo = min(h.far_lo, max(self.flo[i], h.near_end + 1))
                    h.far_hi = max(h.far_hi, self.fhi[i])
            h.far_off = total
            if h.far_hi >= h.far_lo:
                total += h.far_hi - h.far_lo + 1
            if start < self.nfar:
                self.nfarblocks = b + 1
        if total > self.halo_cap:   # the buffers are all zero between steps: start afresh
            p = calloc(6 * (total + total // 4), sizeof(double))
            if p == NULL:
                return -1
            free(self.halo)
            self.halo = <double*>p
            self.halo_cap = total + total // 4
        return 0

    cdef double drift(self, double dt) noexcept nogil:
        """First half kick and drift; the largest displacement since the last rebuild."""
        cdef int t
        cdef double t0 = pg_now()
        self.make_ctx(&self.ctx)
        self.ctx.dt = dt
        for t in range(self.nthreads):
            self.tmax[PAD * t] = 0.0
        self.parallel_rows(P_DRIFT, self.n)
        self.lap(T_DRIFT, t0)
        return self.max_displacement()

    # ------------------------------------------------------------------ the team --------
    cdef void parallel_rows(self, int phase, int rows) noexcept nogil:
        """Run a phase over rows [0, rows) in ``nblocks`` equal blocks on the team."""
        self.rows = rows
        self.run_phase(phase, self.nblocks)

    cdef void run_phase(self, int phase, int nblocks) noexcept nogil:
        """Master: open a phase, take blocks of it like the other threads, and return when
        all its blocks are done (whichever threads ran them); alone, run them in order."""
        cdef int b
        cdef double t0
        if self.nthreads == 1 or self.tuner.solo:
            t0 = thread_cpu() if phase == P_PAIRS or phase == P_PARTICLES else 0.0
            for b in range(nblocks):
                self.run_block(phase, b, nblocks, 0)
            if phase == P_PAIRS or phase == P_PARTICLES:
                self.cpu[2 if phase == P_PAIRS else 3] += thread_cpu() - t0
            return
        pg_begin(self.team, phase, nblocks)
        self.take(pg_epoch(self.team), phase, nblocks, 0)
        pg_wait_done(self.team, nblocks)

    cdef inline void run_block(self, int phase, int b, int nblocks, int tid) noexcept nogil:
        """Block b of a phase, run by thread ``tid``."""
        cdef long long lo, hi
        if phase == P_PAIRS:
            pair_block(&self.ctx, b)
        elif phase == P_PARTICLES:
            particle_block(&self.ctx, self.pb[b], self.pb[b + 1], tid)
        else:
            lo = <long long>self.rows * b // nblocks
            hi = <long long>self.rows * (b + 1) // nblocks
            if phase == P_DRIFT:
                drift_block(&self.ctx, <int>lo, <int>hi, tid)
            else:
                self.rebuild_rows(phase, <int>lo, <int>hi)

    cdef void tune(self) noexcept nogil:
        """Before a step: time the window that ends here and choose how to run the next
        one (see Tuner)."""
        cdef Tuner* u = &self.tuner
        cdef double now = pg_now(), window = u.elapsed + now - u.start
        cdef int probe
        if u.interval == 0.0:   # the first step with a team
            u.interval = TUNE_MIN
            u.next_probe = now + TUNE_WINDOW
        if u.steps > 0 and window >= TUNE_WINDOW:
            probe = 1 if u.solo else 0
            u.per_step[probe] = window / u.steps
            if u.probing:   # keep the faster mode; compare less often while the choice stands
                u.probing = False
                if u.per_step[probe] < u.per_step[1 - probe]:
                    u.interval = TUNE_MIN
                else:
                    u.solo = not u.solo
                    u.interval = min(2.0 * u.interval, TUNE_MAX)
                u.next_probe = now + u.interval
            elif now >= u.next_probe:
                u.probing = True
                u.solo = not u.solo
            u.steps = 0
            u.elapsed = 0.0
            u.start = now
        u.steps += 1

    cdef void take(self, unsigned int epoch, int phase, int nblocks, int tid) noexcept nogil:
        """Claim and run blocks of phase ``epoch`` until none is left, then report them done;
        the CPU time of the pair and particle loops goes to thread ``tid``'s counters."""
        cdef int b, k = 0
        cdef double t0 = 0.0
        b = pg_claim(self.team, epoch, tid)
        if b < 0:
            return
        if phase == P_PAIRS or phase == P_PARTICLES:
            t0 = thread_cpu()
        while b >= 0:
            self.run_block(phase, b, nblocks, tid)
            k += 1
            b = pg_claim(self.team, epoch, tid)
        if phase == P_PAIRS or phase == P_PARTICLES:
            self.cpu[PAD * tid + (2 if phase == P_PAIRS else 3)] += thread_cpu() - t0
        pg_finished(self.team, k, nblocks)

    cdef double max_displacement(self) noexcept nogil:
        cdef int i
        cdef double dmax = 0.0
        for i in range(self.nthreads):
            if self.tmax[PAD * i] > dmax:
                dmax = self.tmax[PAD * i]
        return sqrt(dmax)

    cdef int _run(self, long long nsteps, double dt) noexcept nogil:
        cdef long long s
        cdef double dp, dw, t0 = pg_now(), t1
        cdef bint fused = False
        if dt != self.dt_base:
            self.t_base = self.time
            self.step_base = self.step
            self.dt_base = dt
        if self.nslots:
            self.servo_start(dt)
        if self.dirty:
            if self.rebuild() < 0:
                return -1
            if self.forces(dt, False, False, False) < 0:
                return -1
            self.dirty = 0
        self.tuner.start = t0
        for s in range(nsteps):
            if self.nthreads > 1:
                self.tune()
            dp = self.max_displacement() if fused else self.drift(dt)
            self.step += 1
            self.time = self.t_base + (self.step - self.step_base) * dt
            t1 = pg_now()
            self.servo_move(dt)
            dw = self.move_walls()
            self.lap(T_WALLS, t1)
            if dp + dw > 0.5 * self.skin:
                if self.rebuild() < 0:
                    return -1
            fused = s + 1 < nsteps   # the last step ends after its second half kick
            if self.forces(dt, True, True, fused) < 0:
                return -1
        self.tuner.elapsed += self.lap(T_RUN, t0) - self.tuner.start
        return 0

    def run(self, long long nsteps, double dt):
        """Advance ``nsteps`` velocity-Verlet steps of ``dt`` without the GIL, on a team of
        ``nthreads`` threads: this one runs the loop, the others (started at the first run,
        asleep between runs) take part in its parallel passes."""
        cdef int rc
        if self.nthreads > 1:
            pg_start(self.team, team_task, <void*>self)
        with nogil:
            rc = self._run(nsteps, dt)
        if rc < 0:
            raise MemoryError("native solver: out of memory while rebuilding the neighbour lists")

    # ------------------------------------------------------------------ outputs ---------
    def array(self, str name):
        """Copy of a per-particle array in storage order."""
        cdef int n = self.n
        if name in ("x", "v", "w", "f", "t"):
            ptr = {"x": <size_t>self.x, "v": <size_t>self.v, "w": <size_t>self.w,
                   "f": <size_t>self.f, "t": <size_t>self.t}[name]
            return _copy_d(<double*><size_t>ptr, 3 * n).reshape(n, 3)
        if name == "r":
            return _copy_d(self.r, n)
        if name == "m":
            return _copy_d(self.m, n)
        if name == "type":
            return _copy_i(self.type, n)
        if name == "id":
            return _copy_l(self.pid, n)
        raise KeyError(name)

    def contacts(self):
        """Particle-particle contacts now: storage indices i, j, overlap, normal force."""
        cdef int i, k, q, cnt = 0, npair = self.nb_start[self.n]
        cdef double d2, d
        cdef double* sv
        for k in range(npair):
            cnt += self._in_contact(k)
        out_i = np.empty(cnt, dtype=np.intp)
        out_j = np.empty(cnt, dtype=np.intp)
        out_d = np.empty(cnt, dtype=float)
        out_f = np.empty(cnt, dtype=float)
        cdef Py_ssize_t[::1] oi = out_i, oj = out_j
        cdef double[::1] od = out_d, of = out_f
        cnt = 0
        for i in range(self.n):
            for k in range(self.nb_start[i], self.nb_start[i + 1]):
                if not self._in_contact(k):
                    continue
                sv = &self.shiftv[3 * (self.nb_s[k] & IMAGE)]
                d2 = 0.0
                for q in range(3):
                    d = self.x[3 * i + q] - self.x[3 * self.nb_j[k] + q] + sv[q]
                    d2 += d * d
                oi[cnt] = i
                oj[cnt] = self.nb_j[k]
                od[cnt] = self.r[i] + self.r[self.nb_j[k]] - sqrt(d2)
                of[cnt] = self.nb_h[k * self.hs + 3]
                cnt += 1
        return out_i, out_j, out_d, out_f

    cdef inline bint _in_contact(self, int k) noexcept nogil:
        return self.nb_s[k] & TOUCH and (self.model != THORNTON_NING or self.nb_h[k * self.hs + 4] > 0.0)

    def timings(self):
        """Seconds spent so far: wall clock per phase (``TIMERS``), and per-thread CPU time in
        the pair and particle loops (``pairs_cpu``, ``particles_cpu``)."""
        out = {name: self.timers[k] for k, name in enumerate(TIMERS)}
        out["pairs_cpu"] = np.array([self.cpu[PAD * t] for t in range(self.nthreads)])
        out["particles_cpu"] = np.array([self.cpu[PAD * t + 1] for t in range(self.nthreads)])
        return out

    def pair_count(self):
        """Entries of the neighbour and wall lists."""
        return self.nb_start[self.n], self.wl_start[self.n]

    def memory_bytes(self):
        """Bytes held by the per-particle arrays and lists (allocated capacity)."""
        return (self.cap * (18 * 8 + 2 * 8 + 4 * 4 + 8 + 7 * 4 + 6 * 8) + self.halo_cap * 6 * 8
                + self.nb_cap * (5 + 8 * self.hs) + self.ob_cap * (5 + 8 * self.hs)
                + self.wl_cap * (12 + 8 * self.hs) + self.ow_cap * (12 + 8 * self.hs)
                + self.cell_cap * 8 + self.ctri_cap * 4)

    def elements(self):
        """Current wall elements: kind, type, wall, geometry (9), vertex ids (3), moving."""
        cdef int ne = self.ne
        return (_copy_i(self.ekind, ne), _copy_i(self.etype, ne), _copy_i(self.ewall, ne),
                _copy_d(self.egeo, 9 * ne).reshape(ne, 9), _copy_i(self.evid, 3 * ne).reshape(ne, 3))

    # ------------------------------------------------------------------ state -----------
    def get_state(self):
        """Everything the time-step loop depends on, as numpy arrays (storage order)."""
        cdef int n = self.n, ne = self.ne
        cdef long long npair = self.nb_start[n], nwall = self.wl_start[n]
        state = {
            "x": _copy_d(self.x, 3 * n), "v": _copy_d(self.v, 3 * n), "w": _copy_d(self.w, 3 * n),
            "f": _copy_d(self.f, 3 * n), "t": _copy_d(self.t, 3 * n), "x0": _copy_d(self.x0, 3 * n),
            "r": _copy_d(self.r, n), "m": _copy_d(self.m, n), "type": _copy_i(self.type, n),
            "id": _copy_l(self.pid, n),
            "nb_start": _copy_i(self.nb_start, n + 1), "nb_j": _copy_i(self.nb_j, npair),
            "nb_s": _copy_b(self.nb_s, npair), "nb_h": _copy_d(self.nb_h, npair * self.hs),
            "wl_start": _copy_i(self.wl_start, n + 1), "wl_e": _copy_i(self.wl_e, nwall),
            "wl_h": _copy_d(self.wl_h, nwall * (self.hs + 1)),
            "ekind": _copy_i(self.ekind, ne), "etype": _copy_i(self.etype, ne),
            "ewall": _copy_i(self.ewall, ne), "evid": _copy_i(self.evid, 3 * ne),
            "emoving": _copy_i(self.emoving, ne), "egeo": _copy_d(self.egeo, 9 * ne),
            "eref": _copy_d(self.eref, 9 * ne), "ebuilt": _copy_d(self.ebuilt, 9 * ne),
            "emot": _copy_d(self.emot, NMOT * ne), "visc": _copy_d(self.visc, self.ntypes),
            "slots": _copy_d(self.slots, NSLOT * self.nslots),
            "vib": _copy_d(self.vib, NVIB * self.nvib),
            "scalars": np.array([self.time, self.t_base, self.dt_base, self.lost_speed], dtype=float),
            "lost": np.array([self.lost_at[k] for k in range(7)], dtype=np.int64),
            "counters": np.array([self.step, self.lost, self.rebuilds, self.dirty, self.step_base],
                                 dtype=np.int64),
            "bounds": _copy_i(self.pb, self.nblocks + 1),
        }
        return state

    def set_state(self, state):
        """Restore :meth:`get_state` output (the contact model must be set already). The entries
        must be consistent (see ``solver._checked_state``); every copy checks its length."""
        cdef int n = state["r"].shape[0], ne = state["ekind"].shape[0], i
        cdef long long npair = state["nb_j"].shape[0], nwall = state["wl_e"].shape[0]
        self.reserve(n)
        if self.reserve_pairs(npair) < 0 or self.reserve_walls(nwall) < 0:
            raise MemoryError()
        self.n = 0
        self.ne = 0
        kinds = np.ascontiguousarray(state["ekind"], dtype=np.int32)
        self.add_elements(kinds, np.ascontiguousarray(state["etype"], dtype=np.int32),
                          np.ascontiguousarray(state["ewall"], dtype=np.int32),
                          np.ascontiguousarray(state["egeo"], dtype=float).reshape(ne, 9),
                          np.ascontiguousarray(state["evid"], dtype=np.int32).reshape(ne, 3))
        _put_d(self.eref, state["eref"], 9 * ne)
        _put_d(self.ebuilt, state["ebuilt"], 9 * ne)
        _put_d(self.emot, state["emot"], NMOT * ne)
        _put_i(self.emoving, state["emoving"], ne)
        self.set_slots(np.ascontiguousarray(state["slots"], dtype=float).reshape(-1, NSLOT))
        self.set_vibrations(np.ascontiguousarray(state["vib"], dtype=float).reshape(-1, NVIB))
        for name, ptr, k in (("x", <size_t>self.x, 3 * n), ("v", <size_t>self.v, 3 * n),
                             ("w", <size_t>self.w, 3 * n), ("f", <size_t>self.f, 3 * n),
                             ("t", <size_t>self.t, 3 * n), ("x0", <size_t>self.x0, 3 * n),
                             ("r", <size_t>self.r, n), ("m", <size_t>self.m, n),
                             ("nb_h", <size_t>self.nb_h, npair * self.hs),
                             ("wl_h", <size_t>self.wl_h, nwall * (self.hs + 1))):
            _put_d(<double*><size_t>ptr, state[name], k)
        for name, ptr, k in (("type", <size_t>self.type, n), ("nb_start", <size_t>self.nb_start, n + 1),
                             ("nb_j", <size_t>self.nb_j, npair), ("wl_start", <size_t>self.wl_start, n + 1),
                             ("wl_e", <size_t>self.wl_e, nwall)):
            _put_i(<int*><size_t>ptr, state[name], k)
        ids = np.ascontiguousarray(state["id"], dtype=np.int64)
        nbs = np.ascontiguousarray(state["nb_s"], dtype=np.uint8)
        if ids.shape[0] != n or nbs.shape[0] != npair:
            raise ValueError("id, nb_s: one per particle and per listed pair")
        if n:
            memcpy(self.pid, cnp.PyArray_DATA(ids), n * sizeof(int64_t))
        if npair:
            memcpy(self.nb_s, cnp.PyArray_DATA(nbs), npair)
        self.set_viscous(np.ascontiguousarray(state["visc"], dtype=float))
        self.n = n
        self.time, self.t_base, self.dt_base, self.lost_speed = (float(k) for k in state["scalars"])
        for i in range(7):
            self.lost_at[i] = state["lost"][i]
        self.step, self.lost, self.rebuilds, self.dirty, self.step_base = (int(k) for k in state["counters"])
        if state["bounds"].shape[0] == self.nblocks + 1:
            _put_i(self.pb, state["bounds"], self.nblocks + 1)
        else:   # another thread count: sums in another order anyway
            for i in range(n):
                self.work[i] = self.estimated_work(i)
            self.balance()
        for i in range(n):
            self.find_partners(i)
        self.prefix_last()


cdef void team_task(void* owner, unsigned int epoch, int phase, int nblocks, int tid) noexcept nogil:
    """What the team's threads run: their part of a phase of ``owner``, a :class:`Core`."""
    (<Core>owner).take(epoch, phase, nblocks, tid)


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
