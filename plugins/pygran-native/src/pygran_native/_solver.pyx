# cython: boundscheck=False, wraparound=False, cdivision=True, initializedcheck=False
"""Compiled core of the native DEM solver: data in C arrays, the time-step loop nogil/threaded.

One ``State`` struct holds everything, in named parts (``particles``, ``lists``, ``contacts``,
``walls``, ``clumps``, ``schedule``) beside the box, contact model, clock and counters (``_state.pxi``,
with the allocation tables of the per-particle, per-element, per-body and per-member arrays,
which also name the arrays a checkpoint keeps); :class:`Core` is its Python face, and the
kernels, in include files by concern, work on it:

- ``_defs.pxi``: constants, and the named offsets of histories, motions, vibrations, slots;
- ``_contact.pxi``: a contact's force from its sub-models, ``_contact_normal.pxi`` (hooke,
  hertz, Thornton-Ning; damping, cohesion), ``_contact_tangential.pxi``, ``_contact_rolling.pxi``;
  the spring-dashpot, hertz and tangential laws themselves are ``pair_law.h``'s, which the
  batched pair loop (``pair_batch.h``) shares;
- ``_contacts.pxi``: the contact table, a slot per pair in contact holding its history;
- ``_geometry.pxi``: wall elements (planes, cylinders, triangles);
- ``_motion.pxi``: moving walls (rigid motion, vibration), stress meshes and servos;
- ``_cells.pxi``: the cell grid and the triangles near each cell;
- ``_neighbours.pxi``: the rebuild, the neighbour and wall lists, the contacts carried over;
- ``_pairs.pxi``: the pair loop (pair and wall forces) and its halos;
- ``_integrate.pxi``: the particle loop, the drift and the time-step loop;
- ``_clumps.pxi``: rigid clumps of spheres: the body loop, its rotation, wrapping and dropping;
- ``_team.pxi``: parallel phases on team.h's threads, timers, block balance;
- ``_tuner.pxi``: the Tuner (team or one thread; a heuristic, see team.h);
- ``_checkpoint.pxi``: the State as numpy arrays and back (after Core, which it uses).

Layout (struct of arrays, particles stored in cell order, re-sorted at every neighbour
rebuild):

- particles: ``x, v, w, f, t, x0`` (3 per particle), ``r, m``, ``type``, ``pid``, ``mem``
  (the clump member slot, -1 for a free sphere);
- clumps: per body centre, velocity, orientation, angular momentum, mass, principal moments,
  force, torque; per member slot the sphere's offset in the body's frame, its periodic shift,
  row and body (see _clumps.pxi);
- half neighbour list (CSR over particles): partner ``nb_j`` (j > i), periodic image
  code ``nb_s`` (0..26, with the flags TOUCH and WRAP) and contact slot ``nb_c`` (-1 for a
  pair not in contact) per pair;
- contact table (see Contacts): per slot the contact's ``hs`` history values (tangential
  displacement (3), the last normal force, and for Thornton-Ning the largest overlap, the
  unloading curvature radius and the plastic offset), and the force a recording pass applied
  when contact forces are recorded; so a listed pair apart costs 9 bytes, not a history;
- its sublist (``sb_k``, ``sb_i``, ``sb_at``, ``sb_n``): each row's listed pairs that were near
  contact when it was built, which the batched pair loop visits instead of the whole list (see
  State.sb_k);
- wall list (CSR over particles): wall element ``wl_e`` and its ``whs = hs + 1`` history
  values: the contact's ``hs`` values and, for a plane, the side the contact started on
  (``+1`` along the plane's normal, ``-1`` against it, ``0`` while there is no contact);
- wall elements: planes, cylinders and triangles (with mesh topology and rigid motion).

Planes are two-sided: a new contact takes the side of the particle's centre and keeps it
while it lasts, so a deeply plastic contact whose centre sinks past the plane is still
pushed back to where it came from. A contact is carried across rebuilds and re-sorts by
looking the pair (or particle and wall element) up in the previous list: a pair keeps its
slot (its tangential history changing sign with the pair's orientation), a wall entry's
history is copied.

Threads: the pair loop (pair and wall forces) runs over ``nblocks`` contiguous blocks of the
cell-sorted rows (slabs of the domain): 1 for one thread, BLOCKS per thread otherwise. The
bounds move after every step to where the work the loop counted (listed pairs, touching
pairs, wall entries) splits evenly. Forces on a block's own rows are added into their ``f``
and ``t`` (zero between steps: the particle loop clears them as it reads them, and keeps there
the forces of a run's last step only), forces on later rows go to the block's halo buffers
(see Halo); the particle loop, over the same
blocks (each in SPLIT parts), adds them up in block order. The bounds are part of the state
and the order of every sum depends on the blocks only, so results are bitwise reproducible
for a given thread count, whichever thread runs a block.

The threads are the solver's own (team.h; measured against OpenMP with passive waits and
dynamic scheduling over the same blocks, see the plugin's README), started at the first run
and asleep between runs; the calling thread runs the time-step loop and hands each parallel pass out to the team
as blocks: each thread first takes its own share (the same slab step after step), then the
blocks others have not started. So a thread whose core is taken by another program delays a
pass by at most the block it is in, and threads with nothing to do sleep instead of spinning
(see team.h for why that matters). The pair and particle loops are one pass of two stages: a
part of the particle loop waits only for the pair blocks that read its rows or put forces on
them (see force_phase). The team's heuristics (team.h, and the Tuner, which runs a pass on the
calling thread alone while that is faster) are built unless PYGRAN_NATIVE_TEAM_HEURISTICS=0.
"""

from libc.math cimport sqrt, floor, ceil, fabs, cos, sin, cbrt, M_PI, isfinite, INFINITY
from libc.float cimport DBL_EPSILON
from libc.stdlib cimport malloc, calloc, free, qsort
cdef extern from "<stdlib.h>":
    void* aligned_alloc(size_t alignment, size_t size) nogil
from libc.string cimport memcpy, memmove, memset
from libc.stdint cimport int64_t, uint8_t
from libc.limits cimport INT_MAX
from posix.time cimport clock_gettime, timespec, CLOCK_THREAD_CPUTIME_ID

cdef extern from "pair_law.h":
    double pg_viscoelastic(double kn, double gn, double delta, double Rs, double vn, double coh,
                           double limit) noexcept nogil
    double pg_hertz_normal(double E, double G, double damp, double tdamp, double coh, double limit,
                           double delta, double Rs, double ms, double vn, double* kn, double* kt,
                           double* gt) noexcept nogil
    void pg_tangential(double mu, double kt, double gt, double fn, double vn, const double* n,
                       const double* vr, const double* rw, double* xi, double dt, int update,
                       double* Ft) noexcept nogil

cdef extern from "pair_batch.h":
    enum: PG_BATCH
    ctypedef struct pg_pair_batch:
        double d[3 * PG_BATCH]
        double dist2[PG_BATCH]
        double ri[PG_BATCH]
        double rj[PG_BATCH]
        double mi[PG_BATCH]
        double mj[PG_BATCH]
        double vr[3 * PG_BATCH]
        double wi[3 * PG_BATCH]
        double wj[3 * PG_BATCH]
        double E[PG_BATCH]
        double G[PG_BATCH]
        double mu[PG_BATCH]
        double damp[PG_BATCH]
        double tdamp[PG_BATCH]
        double coh[PG_BATCH]
        double limit[PG_BATCH]
        double xi[3 * PG_BATCH]
        double fn[PG_BATCH]
        double F[3 * PG_BATCH]
        double Ti[3 * PG_BATCH]
        double Tj[3 * PG_BATCH]
        double touch[PG_BATCH]
    void pg_hertz_batch(pg_pair_batch* b, int n, double dt, int update, const double* cf) noexcept nogil

cdef extern from "kick_drift.h":
    void pg_row_forces(long long i, double g0, double g1, double g2, const double* m, const int* type,
                       const double* visc, double* f, double* t, const double* v, double* F, double* T) noexcept nogil
    void pg_row_drift(long long i, double dt, double s, double u, double* peak, double* x, double* v, double* w,
                      const double* x0, const double* F, const double* T) noexcept nogil
    void pg_row_displacement(long long i, double* peak, const double* x, const double* x0) noexcept nogil
    void pg_row_kick(long long i, double s, double u, double* v, double* w, const double* F,
                     const double* T) noexcept nogil
    void pg_row_kick_factors(long long i, double dt, const double* m, const double* r, double* s,
                             double* u) noexcept nogil
    void pg_row_kick_drift(long long i, double dt, double* peak, const double* m, const double* r, double* x,
                           double* v, double* w, const double* x0, const double* F, const double* T) noexcept nogil
    void pg_kick_drift(int lo, int hi, double dt, double* peak, const double* grav, const double* m,
                         const double* r, const int* type, const double* visc, double* f, double* t, double* x,
                         double* v, double* w, const double* x0, double* halo) noexcept nogil

cdef extern from "team.h":
    enum: PG_TEAM_HEURISTICS
    enum: PG_MAX_THREADS
    ctypedef struct pg_team:
        pass
    ctypedef struct pg_flag:
        pass
    ctypedef void (*pg_task)(void* owner, unsigned int epoch, int phase, int nblocks, int tid) noexcept nogil
    pg_team* pg_create(int nthreads) noexcept nogil
    int pg_start(pg_team* t, pg_task task, void* owner) noexcept nogil
    void pg_destroy(pg_team* t) noexcept nogil
    unsigned int pg_begin(pg_team* t, int phase, int nfirst, int nsecond) noexcept nogil
    int pg_claim(pg_team* t, unsigned int epoch, int tid) noexcept nogil
    void pg_finished(pg_team* t, int k) noexcept nogil
    void pg_wait_done(pg_team* t) noexcept nogil
    pg_flag* pg_flags(int n) noexcept nogil
    void pg_post(pg_flag* f, unsigned int epoch) noexcept nogil
    int pg_posted(pg_flag* f, unsigned int epoch) noexcept nogil
    void pg_await(pg_flag* f, unsigned int epoch) noexcept nogil
    double pg_now() noexcept nogil
    long long pg_moves(pg_team* t) noexcept nogil

import numpy as np
cimport numpy as cnp

cnp.import_array()

include "_defs.pxi"

MAX_THREADS = PG_MAX_THREADS
#: Whether the thread team was built with its heuristics (setup.py, team.h).
TEAM_HEURISTICS = bool(PG_TEAM_HEURISTICS)
MOTION_VALUES = NMOT
SLOT_VALUES = NSLOT
VIBRATION_VALUES = NVIB
HARMONICS = NHARM
#: The values of a row of Core.get_slots() (a stress mesh, the Slot enum of _defs.pxi) and of
#: Core.get_vibrations() (a vibrating mesh, the Vibration enum): name -> (first, count).
SLOT_LAYOUT = {
    "WALL": (S_WALL, 1), "CONTROL": (S_CONTROL, 1), "AUTO": (S_AUTO, 1), "SET_POINT": (S_SP, 1),
    "VEL_MAX": (S_VMAX, 1), "KP": (S_KP, 1), "KI": (S_KI, 1), "KD": (S_KD, 1), "RATIO": (S_RATIO, 1),
    "OUTPUT_MAX": (S_OPMAX, 1), "ARM": (S_RPA, 1), "OUTPUT_MIN": (S_OPMIN, 1), "AXIS": (S_AXIS, 3),
    "COM": (S_XCM, 3), "COM0": (S_XCM0, 3), "VELOCITY": (S_VEL, 3), "ANGLE": (S_PHI, 1),
    "INTEGRAL": (S_SUM, 1), "PREVIOUS": (S_OLDPV, 1), "FORCE": (S_FORCE, 3), "TORQUE": (S_TORQUE, 3),
    "CONTACTS": (S_CONTACTS, 1),
}
VIBRATION_LAYOUT = {
    "WALL": (V_WALL, 1), "KIND": (V_KIND, 1), "ORDER": (V_ORDER, 1), "AXIS": (V_AXIS, 3),
    "AMPLITUDE": (V_AMP, NHARM), "PHASE": (V_PHASE, NHARM), "FREQUENCY": (V_FREQ, NHARM),
}
#: Where :meth:`Core.take_lost` counts lost particles: the faces of the box, then non-finite.
LOST_PLACES = ("x-", "x+", "y-", "y+", "z-", "z+", "non-finite")

TIMERS = ("run", "drift", "walls", "pairs", "particles", "rebuild", "rebuild_cells", "rebuild_sort",
          "rebuild_permute", "rebuild_count", "rebuild_fill", "forces_span")


include "_state.pxi"
include "_common.pxi"
include "_contacts.pxi"
include "_contact_normal.pxi"
include "_contact_tangential.pxi"
include "_contact_rolling.pxi"
include "_contact.pxi"
include "_geometry.pxi"
include "_cells.pxi"
include "_neighbours.pxi"
include "_pairs.pxi"
include "_integrate.pxi"
include "_clumps.pxi"
include "_motion.pxi"
include "_team.pxi"
include "_tuner.pxi"


cdef class Core:
    """Particles, neighbour and wall lists, wall elements and the time-step loop: the Python
    face of one :c:type:`State` (set-up, runs, outputs, checkpoints).

    Used through :class:`pygran_native.solver.Solver`, which validates arguments, orders
    outputs by id and builds the contact tables.
    """

    cdef State s   # the one copy of the state (see State), which the kernels work on

    @property
    def n(self):
        return self.s.particles.n

    @property
    def cap(self):
        return self.s.particles.cap

    @property
    def nthreads(self):
        return self.s.schedule.nthreads

    @property
    def hs(self):
        return self.s.hs

    @property
    def model(self):
        return self.s.model

    @property
    def rolling(self):
        return self.s.rolling

    @property
    def roff(self):
        return self.s.roff

    @property
    def ntypes(self):
        return self.s.ntypes

    @property
    def dirty(self):
        return self.s.dirty

    @property
    def time(self):
        return self.s.time

    @property
    def skin(self):
        return self.s.skin

    @property
    def step(self):
        return self.s.step

    @property
    def lost(self):
        return self.s.lost

    @property
    def rebuilds(self):
        return self.s.rebuilds

    @property
    def grid(self):
        """The last rebuild's cells per axis, the radius they fit (inf: every particle's) and
        the big particles, which search the cells within their reach (see split_radius)."""
        return (tuple(self.s.lists.nc[d] for d in range(3)), self.s.lists.rsplit, self.s.lists.nbig)

    @property
    def ne(self):
        return self.s.walls.ne

    @property
    def nslots(self):
        return self.s.walls.nslots

    @property
    def nvib(self):
        return self.s.walls.nvib

    @property
    def nbody(self):
        return self.s.clumps.nbody

    def __cinit__(self, lo, hi, periodic, gravity, double skin, int threads):
        cdef int d, a, b, c
        self.s.schedule.nthreads = threads
        self.s.skin = skin
        for d in range(3):
            self.s.lo[d] = lo[d]
            self.s.hi[d] = hi[d]
            self.s.L[d] = hi[d] - lo[d]
            self.s.per[d] = 1 if periodic[d] else 0
            self.s.grav[d] = gravity[d]
        for a in range(3):
            for b in range(3):
                for c in range(3):
                    d = 9 * a + 3 * b + c
                    self.s.shiftv[3 * d] = (a - 1) * self.s.L[0]
                    self.s.shiftv[3 * d + 1] = (b - 1) * self.s.L[1]
                    self.s.shiftv[3 * d + 2] = (c - 1) * self.s.L[2]
        self.s.hs = 4
        self.s.whs = 5
        self.s.model = HERTZ
        self.s.dirty = 1
        self.s.travel = INFINITY
        self.s.measure = 1
        self.s.lists.nb_start = <int*>grow(NULL, sizeof(int))
        self.s.lists.ob_start = <int*>grow(NULL, sizeof(int))
        self.s.lists.wl_start = <int*>grow(NULL, sizeof(int))
        self.s.lists.ow_start = <int*>grow(NULL, sizeof(int))
        if not 1 <= threads <= PG_MAX_THREADS:
            raise ValueError(f"threads: between 1 and {PG_MAX_THREADS}")
        self.s.schedule.nblocks = 1 if threads == 1 else BLOCKS * threads
        self.s.tmax = <double*>calloc(threads * PAD, sizeof(double))
        self.s.schedule.cpu = <double*>calloc(threads * PAD, sizeof(double))
        self.s.schedule.pb = <int*>calloc(self.s.schedule.nblocks + 1, sizeof(int))
        self.s.schedule.tstat = <long long*>calloc(self.s.schedule.nblocks * PAD, sizeof(long long))
        self.s.lists.halos = <Halo*>calloc(self.s.schedule.nblocks, sizeof(Halo))
        self.s.schedule.posted = pg_flags(self.s.schedule.nblocks)
        self.s.lists.found = <Found*>calloc(self.s.schedule.nblocks, sizeof(Found))
        self.s.contacts.spill = <Spill*>calloc(self.s.schedule.nblocks, sizeof(Spill))
        self.s.contacts.take = <long long*>aligned_alloc(64, 64)   # a cache line of its own
        self.s.contacts.recording = 1
        self.s.schedule.team = pg_create(threads)
        self.s.coef = <Coef*>calloc(1, sizeof(Coef))
        self.s.visc = <double*>calloc(1, sizeof(double))
        self.s.ntypes = 1
        if not (self.s.lists.nb_start and self.s.lists.ob_start and self.s.lists.wl_start and self.s.lists.ow_start and self.s.tmax
                and self.s.schedule.pb and self.s.schedule.tstat and self.s.schedule.cpu and self.s.lists.halos and self.s.schedule.posted and self.s.lists.found
                and self.s.contacts.spill and self.s.contacts.take and self.s.schedule.team):
            raise MemoryError()
        self.s.contacts.take[0] = 0
        self.s.lists.nb_start[0] = self.s.lists.ob_start[0] = self.s.lists.wl_start[0] = self.s.lists.ow_start[0] = 0

    def __dealloc__(self):
        cdef Column cols[NCOLUMNS]
        cdef int k
        pg_destroy(self.s.schedule.team)
        if self.s.lists.found:
            for k in range(self.s.schedule.nblocks):
                release_found(&self.s.lists.found[k])
        if self.s.contacts.spill:
            for k in range(self.s.schedule.nblocks):
                free_spill(&self.s.contacts.spill[k])
                release(self.s.contacts.spill[k].ended)
        particle_columns(&self.s, cols)
        for k in range(NCOLUMNS):
            release(cols[k].p[0])
        element_columns(&self.s, cols)
        for k in range(NECOLUMNS):
            release(cols[k].p[0])
        body_columns(&self.s, cols)
        for k in range(NBCOLUMNS):
            release(cols[k].p[0])
        member_columns(&self.s, cols)
        for k in range(NMCOLUMNS):
            release(cols[k].p[0])
        for p in (<size_t>self.s.lists.nb_j, <size_t>self.s.lists.nb_s, <size_t>self.s.lists.nb_c,
                  <size_t>self.s.lists.sb_k, <size_t>self.s.lists.sb_i, <size_t>self.s.lists.ob_j,
                  <size_t>self.s.lists.ob_s, <size_t>self.s.lists.ob_c, <size_t>self.s.lists.wl_e,
                  <size_t>self.s.lists.wl_h, <size_t>self.s.lists.wl_f, <size_t>self.s.lists.ow_e,
                  <size_t>self.s.lists.ow_h, <size_t>self.s.contacts.h, <size_t>self.s.contacts.f,
                  <size_t>self.s.contacts.free, <size_t>self.s.lists.cell_start,
                  <size_t>self.s.walls.ctri_start, <size_t>self.s.walls.ctri, <size_t>self.s.lists.big,
                  <size_t>self.s.lists.extra):
            release(<void*>p)   # the growable arrays (see grow)
        for p in (<size_t>self.s.lists.halo, <size_t>self.s.lists.halos, <size_t>self.s.schedule.posted,
                  <size_t>self.s.contacts.take, <size_t>self.s.contacts.spill, <size_t>self.s.walls.slots,
                  <size_t>self.s.walls.sacc, <size_t>self.s.walls.vib, <size_t>self.s.coef, <size_t>self.s.visc,
                  <size_t>self.s.tmax, <size_t>self.s.schedule.pb, <size_t>self.s.schedule.tstat,
                  <size_t>self.s.schedule.cpu, <size_t>self.s.lists.found):
            free(<void*>p)

    # ------------------------------------------------------------------ memory ----------
    cdef int reserve(self, int need) except -1:
        """Grow every per-particle array (the allocation table, see particle_columns) to hold
        ``need`` particles."""
        cdef int cap = self.s.particles.cap, k
        cdef size_t c
        cdef Column cols[NCOLUMNS]
        if need <= cap:
            return 0
        cap = max(need, 2 * cap, 64)
        c = cap
        particle_columns(&self.s, cols)
        for k in range(NCOLUMNS):
            cols[k].p[0] = self._grow(cols[k].p[0], (c + cols[k].extra) * cols[k].size)
        self.s.particles.cell = self.s.lists.sb_n   # the rebuild's scratch (see Particles)
        self.s.particles.perm = self.s.lists.sb_at
        self.s.particles.cap = cap
        return 0

    cdef int reserve_bodies(self, int nbody, int nmem) except -1:
        """Grow the clumps' per-body and per-slot arrays (see body_columns, member_columns)."""
        cdef Column cols[NBCOLUMNS]
        cdef int k, cap
        if nbody + 1 > self.s.clumps.bcap:
            cap = max(nbody + 1, 2 * self.s.clumps.bcap, 8)
            body_columns(&self.s, cols)
            for k in range(NBCOLUMNS):
                cols[k].p[0] = self._grow(cols[k].p[0], (cap + cols[k].extra) * cols[k].size)
            if self.s.clumps.bcap == 0:
                self.s.clumps.mstart[0] = 0
            self.s.clumps.bcap = cap
        if nmem > self.s.clumps.mcap:
            cap = max(nmem, 2 * self.s.clumps.mcap, 8)
            member_columns(&self.s, cols)
            for k in range(NMCOLUMNS):
                cols[k].p[0] = self._grow(cols[k].p[0], cap * cols[k].size)
            self.s.clumps.mcap = cap
        return 0

    cdef void* _grow(self, void* p, size_t nbytes) except NULL:
        cdef void* q = grow(p, nbytes)
        if q == NULL:
            raise MemoryError()
        return q

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
        for a in range(min(nt, self.s.ntypes)):
            vis[a] = self.s.visc[a]
        free(self.s.coef)
        free(self.s.visc)
        self.s.coef = c
        self.s.visc = vis
        self.s.ntypes = nt
        if hs != self.s.hs:
            release(self.s.contacts.h)
            release(self.s.contacts.f)
            release(self.s.lists.wl_h)
            release(self.s.lists.ow_h)
            self.s.contacts.h = self.s.contacts.f = self.s.lists.wl_h = self.s.lists.ow_h = NULL
            self.s.contacts.cap = self.s.lists.wl_cap = self.s.lists.ow_cap = 0
            clear_contacts(&self.s)
            memset(self.s.lists.nb_start, 0, (self.s.particles.n + 1) * sizeof(int))
            memset(self.s.lists.wl_start, 0, (self.s.particles.n + 1) * sizeof(int))
            self.s.hs = hs
            self.s.whs = hs + 1
        self.s.model = model
        self.s.rolling = rolling
        self.s.roff = 0 if rolling == CDT else hs - 3
        self.s.batched = model == HERTZ and not np.any(np.asarray(mur))
        self.s.dirty = 1

    def set_recording(self, bint on):
        """Keep, or not, each contact's force at a run's last step (see contact_forces): 3 values
        per pair in contact, 7 per wall-list entry."""
        cdef void* p
        cdef void* q
        if on and not self.s.contacts.recording:
            p = grow(self.s.contacts.f, max(self.s.contacts.cap, 1) * 3 * sizeof(double))
            if p == NULL:
                raise MemoryError()
            self.s.contacts.f = <double*>p
            q = grow(self.s.lists.wl_f, max(self.s.lists.wl_cap, 1) * WLF * sizeof(double))
            if q == NULL:
                raise MemoryError()
            self.s.lists.wl_f = <double*>q
            self.s.lists.wlf_cap = self.s.lists.wl_cap
            self.s.forces_valid = 0
        elif not on:
            release(self.s.contacts.f)
            release(self.s.lists.wl_f)
            self.s.contacts.f = self.s.lists.wl_f = NULL
            self.s.lists.wlf_cap = 0
        self.s.contacts.recording = on

    @property
    def recording(self):
        return bool(self.s.contacts.recording)

    def set_viscous(self, double[::1] gamma):
        cdef int a
        for a in range(min(gamma.shape[0], self.s.ntypes)):
            self.s.visc[a] = gamma[a]

    def add_particles(self, const double[:, ::1] x, const double[::1] r, const double[::1] m, const int[::1] typ,
                      const double[:, :] v, const double[:, :] w, int64_t first_id):
        """Add spheres, with ids from ``first_id`` on (``v`` and ``w`` may repeat one row: any strides)."""
        cdef int k = x.shape[0], i, d, base = self.s.particles.n
        self.reserve(base + k)
        for i in range(k):
            for d in range(3):
                self.s.particles.x[3 * (base + i) + d] = x[i, d]
                self.s.particles.x0[3 * (base + i) + d] = x[i, d]
                self.s.particles.v[3 * (base + i) + d] = v[i, d]
                self.s.particles.w[3 * (base + i) + d] = w[i, d]
                self.s.particles.f[3 * (base + i) + d] = 0.0
                self.s.particles.t[3 * (base + i) + d] = 0.0
            self.s.particles.r[base + i] = r[i]
            self.s.particles.m[base + i] = m[i]
            self.s.particles.type[base + i] = typ[i]
            self.s.particles.pid[base + i] = first_id + i
            self.s.particles.mem[base + i] = -1
            self.s.lists.nb_start[base + i + 1] = self.s.lists.nb_start[base]
            self.s.lists.wl_start[base + i + 1] = self.s.lists.wl_start[base]
        self.s.particles.n = base + k
        self.s.dirty = 1

    def add_bodies(self, double[:, ::1] x, double[:, ::1] v, double[:, ::1] q, double[:, ::1] p,
                   double[::1] m, double[:, ::1] inertia, int[::1] typ, int64_t[::1] bids, int[::1] counts,
                   double[:, ::1] offsets, double[::1] r, int64_t[::1] ids):
        """Add clumps: body k with centre x[k], velocity v[k], orientation q[k] (unit quaternion
        of its principal axes), angular momentum p[k] (principal frame), mass m[k], principal
        moments inertia[k], type typ[k] and id bids[k] has the next counts[k] spheres of
        ``offsets`` (principal frame), radii r and ids; they are placed from the body."""
        cdef int nb = x.shape[0], total = offsets.shape[0], b, k, d, s, i
        cdef int base = self.s.particles.n, b0 = self.s.clumps.nbody, s0 = self.s.clumps.nmem
        self.reserve(base + total)
        self.reserve_bodies(b0 + nb, s0 + total)
        i = base
        s = s0
        for b in range(nb):
            self.s.clumps.bid[b0 + b] = bids[b]
            self.s.clumps.btype[b0 + b] = typ[b]
            self.s.clumps.bm[b0 + b] = m[b]
            self.s.clumps.bdd[b0 + b] = 0.0
            for d in range(3):
                self.s.clumps.bx[3 * (b0 + b) + d] = x[b, d]
                self.s.clumps.bv[3 * (b0 + b) + d] = v[b, d]
                self.s.clumps.bp[3 * (b0 + b) + d] = p[b, d]
                self.s.clumps.bI[3 * (b0 + b) + d] = inertia[b, d]
                self.s.clumps.bf[3 * (b0 + b) + d] = 0.0
                self.s.clumps.bt[3 * (b0 + b) + d] = 0.0
            for d in range(4):
                self.s.clumps.bq[4 * (b0 + b) + d] = q[b, d]
            self.s.clumps.mstart[b0 + b] = s
            for k in range(counts[b]):
                for d in range(3):
                    self.s.clumps.md[3 * s + d] = offsets[s - s0, d]
                    self.s.clumps.mimg[3 * s + d] = 0.0
                    self.s.particles.x0[3 * i + d] = 0.0
                    self.s.particles.f[3 * i + d] = 0.0
                    self.s.particles.t[3 * i + d] = 0.0
                self.s.clumps.mrow[s] = i
                self.s.clumps.mbody[s] = b0 + b
                self.s.particles.r[i] = r[s - s0]
                self.s.particles.m[i] = m[b]
                self.s.particles.type[i] = typ[b]
                self.s.particles.pid[i] = ids[s - s0]
                self.s.particles.mem[i] = s
                self.s.lists.nb_start[i + 1] = self.s.lists.nb_start[base]
                self.s.lists.wl_start[i + 1] = self.s.lists.wl_start[base]
                i += 1
                s += 1
        self.s.clumps.mstart[b0 + nb] = s
        self.s.clumps.nbody = b0 + nb
        self.s.clumps.nmem = s
        self.s.particles.n = base + total
        for b in range(b0, b0 + nb):
            body_members(&self.s, b, True)
        for i in range(base, base + total):
            for d in range(3):
                self.s.particles.x0[3 * i + d] = self.s.particles.x[3 * i + d]
        self.s.dirty = 1

    def bodies(self):
        """The clumps now: per body ``id``, ``type``, centre ``x``, velocity ``v``, orientation
        ``q`` (of its principal axes), angular momentum ``p`` (principal frame), mass ``m``,
        principal moments ``inertia``, force ``f`` and torque ``t`` of the last evaluation."""
        cdef int nb = self.s.clumps.nbody
        return {
            "id": _copy_l(self.s.clumps.bid, nb), "type": _copy_i(self.s.clumps.btype, nb),
            "x": _copy_d(self.s.clumps.bx, 3 * nb).reshape(nb, 3), "v": _copy_d(self.s.clumps.bv, 3 * nb).reshape(nb, 3),
            "q": _copy_d(self.s.clumps.bq, 4 * nb).reshape(nb, 4), "p": _copy_d(self.s.clumps.bp, 3 * nb).reshape(nb, 3),
            "m": _copy_d(self.s.clumps.bm, nb), "inertia": _copy_d(self.s.clumps.bI, 3 * nb).reshape(nb, 3),
            "f": _copy_d(self.s.clumps.bf, 3 * nb).reshape(nb, 3), "t": _copy_d(self.s.clumps.bt, 3 * nb).reshape(nb, 3),
        }

    def mark_removed(self, cnp.uint8_t[::1] mask):
        """Mark particles (storage order) for removal at the next rebuild (a clump's sphere:
        the clump)."""
        cdef int i
        for i in range(self.s.particles.n):
            if mask[i]:
                self.s.particles.type[i] = -1
        self.s.dirty = 1

    def set_vectors(self, str name, int[::1] index, double[:, ::1] values):
        cdef double* a = self.s.particles.v if name == "v" else self.s.particles.w
        cdef int i, d
        for i in range(index.shape[0]):
            for d in range(3):
                a[3 * index[i] + d] = values[i, d]

    def set_radii(self, int[::1] index, double[::1] r, double[::1] m):
        """New radii and masses of particles (storage order); lists are rebuilt at the next run."""
        cdef int i
        for i in range(index.shape[0]):
            self.s.particles.r[index[i]] = r[i]
            self.s.particles.m[index[i]] = m[i]
        self.s.dirty = 1

    def add_elements(self, int[::1] kind, int[::1] etype, int[::1] wall, double[:, ::1] geo, int[:, ::1] vid):
        cdef int k = kind.shape[0], i, d, base = self.s.walls.ne, cap = max(base + k, 2 * self.s.walls.ecap, 8)
        cdef Column cols[NECOLUMNS]
        if base + k > self.s.walls.ecap:
            element_columns(&self.s, cols)
            for d in range(NECOLUMNS):
                cols[d].p[0] = self._grow(cols[d].p[0], cap * cols[d].size)
            self.s.walls.ecap = cap
        for i in range(k):
            self.s.walls.ekind[base + i] = kind[i]
            self.s.walls.etype[base + i] = etype[i]
            self.s.walls.ewall[base + i] = wall[i]
            self.s.walls.emoving[base + i] = 0
            for d in range(3):
                self.s.walls.evid[3 * (base + i) + d] = vid[i, d]
            for d in range(9):
                self.s.walls.egeo[9 * (base + i) + d] = geo[i, d]
                self.s.walls.eref[9 * (base + i) + d] = geo[i, d]
                self.s.walls.ebuilt[9 * (base + i) + d] = geo[i, d]
            for d in range(NMOT):
                self.s.walls.emot[NMOT * (base + i) + d] = 0.0
        self.s.walls.ne = base + k
        self.s.dirty = 1
        self.s.walls.binned_dirty = 1

    def remove_elements(self, int wall):
        """Drop the elements of one wall; wall-list entries are renumbered, their histories kept."""
        cdef int e, k = 0, i, d
        cdef int* newidx = <int*>malloc((self.s.walls.ne + 1) * sizeof(int))
        cdef Column cols[NECOLUMNS]
        if newidx == NULL:
            raise MemoryError()
        element_columns(&self.s, cols)
        for e in range(self.s.walls.ne):
            if self.s.walls.ewall[e] == wall:
                newidx[e] = -1
                continue
            newidx[e] = k
            for d in range(NECOLUMNS):
                memmove(<char*>cols[d].p[0] + k * cols[d].size, <char*>cols[d].p[0] + e * cols[d].size,
                        cols[d].size)
            k += 1
        self.s.walls.ne = k
        k = 0
        for i in range(self.s.particles.n):
            e = self.s.lists.wl_start[i]
            self.s.lists.wl_start[i] = k
            while e < self.s.lists.wl_start[i + 1]:
                if newidx[self.s.lists.wl_e[e]] >= 0:
                    self.s.lists.wl_e[k] = newidx[self.s.lists.wl_e[e]]
                    for d in range(self.s.hs + 1):
                        self.s.lists.wl_h[k * (self.s.hs + 1) + d] = self.s.lists.wl_h[e * (self.s.hs + 1) + d]
                    for d in range(WLF if self.s.lists.wl_f != NULL else 0):
                        self.s.lists.wl_f[k * WLF + d] = self.s.lists.wl_f[e * WLF + d]
                    k += 1
                e += 1
        self.s.lists.wl_start[self.s.particles.n] = k
        free(newidx)
        self.s.dirty = 1
        self.s.walls.binned_dirty = 1
        self.set_slots(np.array([v for v in self.get_slots() if v[S_WALL] != wall]).reshape(-1, NSLOT))
        self.set_vibrations(
            np.array([v for v in self.get_vibrations() if v[V_WALL] != wall]).reshape(-1, NVIB))

    def set_motion(self, int wall, double[::1] vel, double[::1] omega, double[::1] origin,
                   double[::1] amplitude, double period):
        """Rigid motion of a wall's triangles from now on (see motion_origin); ``period`` 0:
        no wiggle."""
        cdef int e, d
        cdef bint moving = period > 0.0
        for d in range(3):
            moving = moving or vel[d] != 0.0 or omega[d] != 0.0
        for e in range(self.s.walls.ne):
            if self.s.walls.ewall[e] != wall or self.s.walls.ekind[e] != TRIANGLE:
                continue
            for d in range(9):
                self.s.walls.eref[9 * e + d] = self.s.walls.egeo[9 * e + d]
            for d in range(3):
                self.s.walls.emot[NMOT * e + M_VEL + d] = vel[d]
                self.s.walls.emot[NMOT * e + M_OMEGA + d] = omega[d]
                self.s.walls.emot[NMOT * e + M_ORIGIN + d] = origin[d]
                self.s.walls.emot[NMOT * e + M_AMP + d] = amplitude[d]
            self.s.walls.emot[NMOT * e + M_START] = self.s.time
            self.s.walls.emot[NMOT * e + M_PERIOD] = period
            self.s.walls.emoving[e] = moving
        self.s.dirty = 1
        self.s.walls.binned_dirty = 1

    def get_vibrations(self):
        """The vibrating meshes' values, (nvib, NVIB) (see vibration)."""
        return _copy_d(self.s.walls.vib, NVIB * self.s.walls.nvib).reshape(self.s.walls.nvib, NVIB)

    def set_vibrations(self, double[:, ::1] values):
        """Replace the vibrating meshes' values; their triangles vibrate about their positions
        at the start of their motion (set_motion, with no other motion)."""
        cdef int k = values.shape[0], e, s
        cdef void* q = malloc(max(k, 1) * NVIB * sizeof(double))
        if q == NULL:
            raise MemoryError()
        if k:
            memcpy(q, &values[0, 0], k * NVIB * sizeof(double))
        free(self.s.walls.vib)
        self.s.walls.vib = <double*>q
        self.s.walls.nvib = k
        for s in range(k):
            for e in range(self.s.walls.ne):
                if self.s.walls.ewall[e] == <int>self.s.walls.vib[NVIB * s + V_WALL] and self.s.walls.ekind[e] == TRIANGLE:
                    self.s.walls.emoving[e] = 1
        self.s.dirty = 1
        self.s.walls.binned_dirty = 1

    def get_slots(self):
        """The stress meshes' values, (nslots, NSLOT) (see Slot)."""
        return _copy_d(self.s.walls.slots, NSLOT * self.s.walls.nslots).reshape(self.s.walls.nslots, NSLOT)

    def set_slots(self, double[:, ::1] values):
        """Replace the stress meshes' values; a servo's triangles move from their positions now
        (their reference), and move with the wall list's rebuilds."""
        cdef int k = values.shape[0], e, s, d
        cdef size_t nbytes = max(k, 1) * NSLOT * sizeof(double)
        cdef void* p = calloc(max(k, 1) * self.s.schedule.nblocks * SACC, sizeof(double))
        cdef void* q = malloc(nbytes)
        if p == NULL or q == NULL:
            free(p)
            free(q)
            raise MemoryError()
        if k:
            memcpy(q, &values[0, 0], k * NSLOT * sizeof(double))
        free(self.s.walls.sacc)
        free(self.s.walls.slots)
        self.s.walls.sacc = <double*>p
        self.s.walls.slots = <double*>q
        self.s.walls.nslots = k
        for s in range(k):
            if self.s.walls.slots[NSLOT * s + S_CONTROL] == STRESS_ONLY:
                continue
            for e in range(self.s.walls.ne):
                if self.s.walls.ewall[e] == <int>self.s.walls.slots[NSLOT * s + S_WALL] and self.s.walls.ekind[e] == TRIANGLE \
                        and not self.s.walls.emoving[e]:
                    for d in range(9):
                        self.s.walls.eref[9 * e + d] = self.s.walls.egeo[9 * e + d]
                    self.s.walls.emoving[e] = 1
        self.s.dirty = 1
        self.s.walls.binned_dirty = 1

    # ------------------------------------------------------------------ rebuild ---------
    def take_lost(self):
        """Particles lost since the last call, by place (``LOST_PLACES``), and the largest speed
        of those lost through a face (0 if none); resets both."""
        counts = np.array([self.s.lost_at[k] for k in range(7)], dtype=np.int64)
        speed = self.s.lost_speed
        memset(self.s.lost_at, 0, 7 * sizeof(long long))
        self.s.lost_speed = 0.0
        return counts, speed

    # ------------------------------------------------------------------ the team --------
    def run(self, long long nsteps, double dt):
        """Advance ``nsteps`` velocity-Verlet steps of ``dt`` without the GIL, on a team of
        ``nthreads`` threads: this one runs the loop, the others (started at the first run,
        asleep between runs) take part in its parallel passes."""
        cdef int rc
        if self.s.schedule.nthreads > 1:
            pg_start(self.s.schedule.team, team_task, <void*>&self.s)
        with nogil:
            rc = run_steps(&self.s, nsteps, dt)
        if rc < 0:
            raise MemoryError("native solver: out of memory while rebuilding the neighbour lists")

    # ------------------------------------------------------------------ outputs ---------
    def array(self, str name):
        """Copy of a per-particle array in storage order."""
        cdef int n = self.s.particles.n, i
        if name in ("x", "v", "w", "f", "t"):
            ptr = {"x": <size_t>self.s.particles.x, "v": <size_t>self.s.particles.v, "w": <size_t>self.s.particles.w,
                   "f": <size_t>self.s.particles.f, "t": <size_t>self.s.particles.t}[name]
            return _copy_d(<double*><size_t>ptr, 3 * n).reshape(n, 3)
        if name == "r":
            return _copy_d(self.s.particles.r, n)
        if name == "m":
            return _copy_d(self.s.particles.m, n)
        if name == "type":
            return _copy_i(self.s.particles.type, n)
        if name == "id":
            return _copy_l(self.s.particles.pid, n)
        if name == "body":   # the clump's id, -1 for a free sphere
            out = np.full(n, -1, dtype=np.int64)
            for i in range(n):
                if self.s.particles.mem[i] >= 0:
                    out[i] = self.s.clumps.bid[self.s.clumps.mbody[self.s.particles.mem[i]]]
            return out
        raise KeyError(name)

    def by_id(self, str name):
        """A per-particle array (``x``, ``v``, ``w``, ``f``, ``t``, ``r``, ``m``, ``type``, ``id``, or
        ``body``: the clump's id, -1 for a free sphere) in the order of the particles' ids: each row
        copied to its place once (when ids were deleted, its place found through their order)."""
        cdef int n = self.s.particles.n, i, q, count = 3
        cdef int64_t top = -1, dst
        cdef const int64_t* pid = self.s.particles.pid
        cdef const int64_t* rank = NULL
        cdef const double* src = NULL
        cdef double* od
        cdef int* oi
        cdef int64_t* ol
        for i in range(n):
            if pid[i] > top:
                top = pid[i]
        if top != n - 1:   # not ids 0 to n - 1 (distinct, so each row goes to its id): their ranks
            order = np.argsort(_copy_l(pid, n), kind="stable")
            ranks = np.empty(n, dtype=np.int64)
            ranks[order] = np.arange(n, dtype=np.int64)
            rank = <const int64_t*>cnp.PyArray_DATA(ranks)
        if name == "x":
            src = self.s.particles.x
        elif name == "v":
            src = self.s.particles.v
        elif name == "w":
            src = self.s.particles.w
        elif name == "f":
            src = self.s.particles.f
        elif name == "t":
            src = self.s.particles.t
        elif name in ("r", "m"):
            src = self.s.particles.r if name == "r" else self.s.particles.m
            count = 1
        elif name == "type":
            out = np.empty(n, dtype=np.int32)
            oi = <int*>cnp.PyArray_DATA(out)
            for i in range(n):
                oi[rank[i] if rank != NULL else pid[i]] = self.s.particles.type[i]
            return out
        elif name in ("id", "body"):
            out = np.empty(n, dtype=np.int64)
            ol = <int64_t*>cnp.PyArray_DATA(out)
            for i in range(n):
                dst = rank[i] if rank != NULL else pid[i]
                if name == "id":
                    ol[dst] = pid[i]
                else:
                    ol[dst] = -1 if self.s.particles.mem[i] < 0 else self.s.clumps.bid[self.s.clumps.mbody[self.s.particles.mem[i]]]
            return out
        else:
            raise KeyError(name)
        out = np.empty((n, 3), dtype=float) if count == 3 else np.empty(n, dtype=float)
        od = <double*>cnp.PyArray_DATA(out)
        for i in range(n):
            dst = rank[i] if rank != NULL else pid[i]
            for q in range(count):
                od[count * dst + q] = src[count * i + q]
        return out

    def largest_radius(self):
        """The largest particle radius (0 without particles)."""
        cdef double top = 0.0
        cdef int i
        for i in range(self.s.particles.n):
            if self.s.particles.r[i] > top:
                top = self.s.particles.r[i]
        return top

    def contacts(self):
        """Particle-particle contacts now: storage indices i, j, overlap, normal force."""
        cdef int i, k, q, cnt = 0, npair = self.s.lists.nb_start[self.s.particles.n]
        cdef double d2, d
        cdef double* sv
        for k in range(npair):
            cnt += in_contact(&self.s, k)
        out_i = np.empty(cnt, dtype=np.intp)
        out_j = np.empty(cnt, dtype=np.intp)
        out_d = np.empty(cnt, dtype=float)
        out_f = np.empty(cnt, dtype=float)
        cdef Py_ssize_t[::1] oi = out_i, oj = out_j
        cdef double[::1] od = out_d, of = out_f
        cnt = 0
        for i in range(self.s.particles.n):
            for k in range(self.s.lists.nb_start[i], self.s.lists.nb_start[i + 1]):
                if not in_contact(&self.s, k):
                    continue
                sv = &self.s.shiftv[3 * (self.s.lists.nb_s[k] & IMAGE)]
                d2 = 0.0
                for q in range(3):
                    d = self.s.particles.x[3 * i + q] - self.s.particles.x[3 * self.s.lists.nb_j[k] + q] + sv[q]
                    d2 += d * d
                oi[cnt] = i
                oj[cnt] = self.s.lists.nb_j[k]
                od[cnt] = self.s.particles.r[i] + self.s.particles.r[self.s.lists.nb_j[k]] - sqrt(d2)
                of[cnt] = pair_history(&self.s, k, NO_HISTORY)[H_FN]
                cnt += 1
        return out_i, out_j, out_d, out_f

    def contact_forces(self):
        """Contacts at the last force evaluation, as the pair loop applied them: ids ``id1``,
        ``id2`` (for a wall, ``-(handle + 1)``); the force on id1 by id2 ``fx, fy, fz`` (normal
        and tangential); the contact point ``cx, cy, cz`` (for a pair in the middle of the
        overlap, on the line of centres from id1's centre; for a wall on its surface: the
        closest point of the triangle in contact, the foot point on a plane or cylinder) and
        the branch vector ``bx, by, bz`` = x1 - x2 (the periodic image in contact), x1 - c for
        a wall. Pairs first, then walls, each by storage row. A ValueError when the lists have
        entries but no evaluation since the state was set or recording was switched on (the
        forces are not checkpointed), or when the contacts' forces are not recorded."""
        cdef int i, j, k, q, cnt = 0, nwall = 0, npair = self.s.lists.nb_start[self.s.particles.n]
        cdef int nlisted = self.s.lists.wl_start[self.s.particles.n]
        cdef double dist, rc
        cdef double d[3]
        cdef const double* sv
        cdef const double* rec
        if not self.s.contacts.recording:
            raise ValueError("the contacts' forces are not recorded")
        for k in range(npair):
            cnt += (self.s.lists.nb_s[k] & TOUCH) != 0
        if (cnt or nlisted) and not self.s.forces_valid:
            raise ValueError("no force evaluation since the state was set")
        for k in range(nlisted):
            nwall += self.s.lists.wl_f[<long long>k * WLF + 6] != 0.0
        out = {key: np.empty(cnt + nwall, dtype=np.int64) for key in ("id1", "id2")}
        for key in ("fx", "fy", "fz", "cx", "cy", "cz", "bx", "by", "bz"):
            out[key] = np.empty(cnt + nwall, dtype=float)
        cdef int64_t[::1] id1 = out["id1"], id2 = out["id2"]
        cdef double[::1] fx = out["fx"], fy = out["fy"], fz = out["fz"]
        cdef double[::1] cx = out["cx"], cy = out["cy"], cz = out["cz"]
        cdef double[::1] bx = out["bx"], by = out["by"], bz = out["bz"]
        cnt = 0
        for i in range(self.s.particles.n):
            for k in range(self.s.lists.nb_start[i], self.s.lists.nb_start[i + 1]):
                if not self.s.lists.nb_s[k] & TOUCH:
                    continue
                j = self.s.lists.nb_j[k]
                sv = &self.s.shiftv[3 * (self.s.lists.nb_s[k] & IMAGE)]
                for q in range(3):
                    d[q] = self.s.particles.x[3 * i + q] - self.s.particles.x[3 * j + q] + sv[q]
                dist = sqrt(dot3(d, d))
                rc = self.s.particles.r[i] - 0.5 * (self.s.particles.r[i] + self.s.particles.r[j] - dist)   # centre to contact point
                id1[cnt] = self.s.particles.pid[i]
                id2[cnt] = self.s.particles.pid[j]
                rec = &self.s.contacts.f[3 * <long long>self.s.lists.nb_c[k]]
                fx[cnt], fy[cnt], fz[cnt] = rec[0], rec[1], rec[2]
                bx[cnt], by[cnt], bz[cnt] = d[0], d[1], d[2]
                cx[cnt] = self.s.particles.x[3 * i] - rc * d[0] / dist
                cy[cnt] = self.s.particles.x[3 * i + 1] - rc * d[1] / dist
                cz[cnt] = self.s.particles.x[3 * i + 2] - rc * d[2] / dist
                cnt += 1
        for i in range(self.s.particles.n):
            for k in range(self.s.lists.wl_start[i], self.s.lists.wl_start[i + 1]):
                rec = &self.s.lists.wl_f[<long long>k * WLF]
                if rec[6] == 0.0:
                    continue
                id1[cnt] = self.s.particles.pid[i]
                id2[cnt] = -(self.s.walls.ewall[self.s.lists.wl_e[k]] + 1)
                fx[cnt], fy[cnt], fz[cnt] = rec[0], rec[1], rec[2]
                cx[cnt], cy[cnt], cz[cnt] = rec[3], rec[4], rec[5]
                bx[cnt] = self.s.particles.x[3 * i] - rec[3]
                by[cnt] = self.s.particles.x[3 * i + 1] - rec[4]
                bz[cnt] = self.s.particles.x[3 * i + 2] - rec[5]
                cnt += 1
        return out

    def timings(self):
        """Seconds spent so far: wall clock per phase (``TIMERS``), and per-thread CPU time in
        the pair and particle loops (``pairs_cpu``, ``particles_cpu``); the steps the master
        ran without the team (``solo_steps``); how often a thread moved off a teammate's CPU
        (``moves``, see team.h); the pair loop's passes that built the sublist (``sublist_builds``,
        see State.sb_k); the steps whose drift measured displacements (``measured_drifts``) and
        the passes that measured them after a drift that did not (``displacement_passes``, see
        State.travel)."""
        out = {name: self.s.schedule.timers[k] for k, name in enumerate(TIMERS)}
        out["solo_steps"] = self.s.schedule.tuner.solo_steps
        out["sublist_builds"] = self.s.lists.sub_builds
        out["measured_drifts"] = self.s.measured
        out["displacement_passes"] = self.s.passes
        out["moves"] = pg_moves(self.s.schedule.team) if self.s.schedule.team else 0
        out["pairs_cpu"] = np.array([self.s.schedule.cpu[PAD * t] for t in range(self.s.schedule.nthreads)])
        out["particles_cpu"] = np.array([self.s.schedule.cpu[PAD * t + 1] for t in range(self.s.schedule.nthreads)])
        return out

    def list_entries(self):
        """Entries of the neighbour and wall lists."""
        return self.s.lists.nb_start[self.s.particles.n], self.s.lists.wl_start[self.s.particles.n]

    def memory(self):
        """Bytes allocated (capacity, not use) by part: ``particles`` (the per-particle columns),
        ``list`` (the neighbour list: partners, image codes, contact slots), ``previous list``
        (the last one, which contacts are carried over from at a rebuild), ``contacts`` (the
        contact table: histories, forces when recorded, free list; and the spills), ``sublist``,
        ``found`` (the rebuild's pairs per block, when not in the sublist's arrays), ``walls`` (the wall lists, current and
        previous, and their records), ``halos``, ``cells`` (the grid and the triangles near each
        cell), ``clumps``."""
        cdef Column cols[NCOLUMNS]
        cdef size_t per_particle = 0, per_body = 0, per_member = 0, found = 0, spills = 0
        cdef int k
        particle_columns(&self.s, cols)
        for k in range(NCOLUMNS):
            per_particle += cols[k].size
        body_columns(&self.s, cols)
        for k in range(NBCOLUMNS):
            per_body += cols[k].size
        member_columns(&self.s, cols)
        for k in range(NMCOLUMNS):
            per_member += cols[k].size
        for k in range(self.s.schedule.nblocks):
            if not self.s.lists.found[k].borrowed:
                found += self.s.lists.found[k].cap * (sizeof(int) + sizeof(uint8_t))
            spills += (self.s.contacts.spill[k].cap * (sizeof(int) + sizeof(long long) + (self.s.hs + 3) * sizeof(double))
                       + self.s.contacts.spill[k].ended_cap * sizeof(int))
        pair = 2 * sizeof(int) + sizeof(uint8_t)
        wall = sizeof(int) + (self.s.hs + 1) * sizeof(double)
        contact = (self.s.hs + (3 if self.s.contacts.recording else 0)) * sizeof(double) + sizeof(int) + sizeof(uint8_t)
        return {
            "particles": self.s.particles.cap * per_particle,
            "list": self.s.lists.nb_cap * pair,
            "previous list": self.s.lists.ob_cap * pair,
            "contacts": self.s.contacts.cap * contact + spills,
            "sublist": self.s.lists.sbk_cap * 2 * sizeof(int),
            "found": found,
            "walls": (self.s.lists.wl_cap + self.s.lists.ow_cap) * wall + self.s.lists.wlf_cap * WLF * sizeof(double),
            "halos": self.s.lists.halo_cap * 6 * sizeof(double),
            "cells": self.s.lists.cell_cap * 2 * sizeof(int) + self.s.walls.ctri_cap * sizeof(int),
            "clumps": self.s.clumps.bcap * per_body + self.s.clumps.mcap * per_member,
        }

    def elements(self):
        """Current wall elements: kind, type, wall, geometry (9), vertex ids (3), moving."""
        cdef int ne = self.s.walls.ne
        return (_copy_i(self.s.walls.ekind, ne), _copy_i(self.s.walls.etype, ne), _copy_i(self.s.walls.ewall, ne),
                _copy_d(self.s.walls.egeo, 9 * ne).reshape(ne, 9), _copy_i(self.s.walls.evid, 3 * ne).reshape(ne, 3))

    # ------------------------------------------------------------------ state -----------
    def get_state(self):
        """Everything the time-step loop depends on, as numpy arrays (storage order)."""
        return state_of(self)

    def set_state(self, state):
        """Restore :meth:`get_state` output (the contact model must be set already). The entries
        must be consistent (see ``solver._checked_state``); every copy checks its length."""
        restore(self, state)


include "_checkpoint.pxi"
