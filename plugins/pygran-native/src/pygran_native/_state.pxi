# The solver's structs: contact coefficients, halos, the tuner and the one State the
# time-step loop's kernels work on.

cdef enum:
    WLF = 7   # values per wall-list entry in wl_f: force on the particle (3), contact point (3),
              # 1.0 in contact, else 0.0 (see wall_row)


cdef struct Coef:
    double E        # effective modulus E*
    double G        # effective shear modulus G*
    double mu       # sliding friction
    double mur      # rolling friction
    double damp     # hertz: -2 sqrt(5/6) beta; hooke: -2 beta
    double tdamp    # hertz: gamma_t / gamma_n = sqrt(k_t / S_n) = sqrt(4 G* / E*)
    double coh      # cohesion energy (SJKR density or JKR surface energy)
    double py       # yield pressure (Thornton-Ning)
    double vchar    # characteristic velocity (hooke)
    double rdamp    # epsd: rolling viscous damping ratio (coefficientRollingViscousDamping)
    double limit    # hooke, hertz: 1 to keep the visco-elastic normal force >= 0 (limitForce)


cdef struct Halo:
    # Where a block of the pair loop puts forces on rows after its own (see pair_row): rows
    # up to near_end (partners in the same or the next cells) from halo entry near_off, and
    # rows far_lo..far_hi (partners across the periodic boundary of axis ax[0]) from far_off.
    long long near_off, far_off
    int near_end, far_lo, far_hi


cdef struct Found:
    # The pairs a block of the neighbour count found (partner, image code and WRAP flag), in
    # the order of its rows: the fill copies them into the list, so one pass searches the cells.
    # With the batched path they are in the block's share of the sublist's arrays (``borrowed``),
    # which the first pass after a rebuild makes anew, unless they outgrow it (see lend_found).
    int* j
    uint8_t* s
    long long cap
    int failed         # out of memory in the last count
    int borrowed
    long long kept     # contacts the fill carried over in the block's rows
    long long breaks   # of them, those whose slot does not follow the previous one's (see renew_slots)


cdef struct Tuner:
    # The master runs the phases alone (solo) or with the team, whichever was faster per step
    # when last compared: it times windows of at least TUNE_WINDOW seconds and, every
    # ``interval`` seconds, a window of the other mode; the interval doubles (up to
    # TUNE_MAX) while the choice stands and falls back to TUNE_MIN when it changes. On a busy
    # machine the team waits for a thread whose CPU another program holds, on a small system
    # for its own hand-offs: then one thread is faster. Results do not depend on the choice.
    # Rebuilds are left out of the windows: one in a window of a few steps would decide it.
    # A comparison costs a window of the slower mode. It is left out while the team's window
    # is well ahead (TUNE_AHEAD) of its guess of one thread's: the window with the loops'
    # wall time replaced by the sum of the threads' CPU time in them (a thread kept from its
    # CPU or waiting for a hand-off adds wall time but no CPU time), for up to TUNE_TRUSTED.
    bint solo, probing
    long long steps     # steps in the current window
    long long solo_steps  # steps the master ran alone, in all runs
    double elapsed      # seconds of the window in earlier runs (between runs is not timed)
    double rebuilt      # the rebuild timer when the window started
    double loops_wall   # the pair and particle loops' wall time when the window started
    double loops_cpu    # ... and their threads' CPU time
    double start, next_probe, interval, probed
    double per_step[2]  # seconds per step with the team [0] and solo [1], when last timed


cdef struct Particles:
    # The spheres, stored in cell order (re-sorted at every rebuild): n of cap allocated.
    int n, cap
    double *x
    double *v
    double *w
    double *f
    double *t
    double *x0         # positions at the last rebuild
    double *r
    double *m
    int *type
    int64_t *pid
    int *mem           # the clump member slot of each particle, -1 for a free sphere (see Clumps)
    # the rebuild's: each row's cell, then the old row of each new one (see rebuild); they are
    # the sublist's sb_n and sb_at, which only the pair loop reads and the first one after a
    # rebuild makes anew
    int *cell
    int *perm


cdef struct Spill:
    # What a pair block changed in the contact table in a pass, for after it (see settle_slots):
    # the new contacts it found no slot for (see new_contact): their list index, the slot they
    # get once the table has grown (beyond its capacity), history (hs each) and, in a recording
    # pass, force (3 each); and the slots of the contacts that ended (see forget_pair).
    int* k
    long long* slot
    double* h
    double* f
    long long n, cap
    int failed         # out of memory
    int* ended
    long long nended, ended_cap


cdef struct Contacts:
    # The pairs in contact: a slot each in this table, which the listed pair names (Lists.nb_c,
    # -1: no contact), holding its history (hs values, see contact_force) and, when contact
    # forces are recorded, the force a recording pass applied (3 values, see contact_forces). A
    # pass gives a pair that comes into contact a slot (new_contact): one of the free list (from
    # its end), else the next fresh one; a contact that ends leaves its slot to the free list
    # after the pass (a rebuild renumbers the contacts it keeps in list order when their order has
    # decayed, see renew_slots).
    # Slots are taken through ``take`` (atomic), so the threads of a pass need no lock; when
    # fresh slots run out, the pass puts the new contacts in its blocks' spills, and the table
    # grows after it (see settle_slots). Which slot a contact has changes no result.
    double *h          # hs per slot
    double *f          # 3 per slot; NULL unless recording
    long long n        # slots in use or free; fresh ones from n on
    long long cap
    int *free          # the free slots: ``nfree`` of them
    long long nfree
    long long *take    # the slots a pass took so far: free[nfree - 1 - take] while take < nfree,
                       # then fresh slot n + (take - nfree) (a cache line of its own)
    Spill *spill       # per pair block
    int recording      # keep each contact's force (see Core.set_recording)


cdef struct Extra:
    # A pair of a small particle's row i and a big one's row j > i, found from the big one's
    # side (see find_extras): image code and WRAP flag as row i sees j.
    int i
    int j
    uint8_t s


cdef struct Lists:
    # The cell grid, the neighbour and wall lists (current and previous, with the wall entries'
    # contact histories; a pair's is in Contacts), the sublist of the batched path, and the pair
    # loop's halos.
    int nc[3]
    int ax[3]          # axes from the slowest-varying in the cell index, see cell_id
    double cs[3]
    int ncells
    # the cells fit the particles up to radius rsplit; the few bigger ones (rows big[0..nbig),
    # see split_radius) search the cells within their reach, and their pairs with small rows
    # before them are the extras, sorted by row
    double rsplit
    int *big
    int nbig
    int big_cap
    Extra *extra
    long long nextra
    long long extra_cap
    int up[14]         # the offsets of the cell index to the cell itself and the 13 after it
                       # among its 27 neighbours (inside the grid), see scan_pairs
    int *cell_start
    int cell_cap
    int *nb_start
    int *nb_j
    uint8_t *nb_s
    int *nb_c          # the pair's contact slot (see Contacts), -1 if it is not in contact
    long long nb_cap
    Found* found       # per block of the rebuild's row passes, see Found
    # the sublist of the batched path: row i's listed pairs that were within SUB_SKIN skins of
    # contact when it was built, in list order, are entries sb_at[i] to sb_at[i] + sb_n[i] - 1
    # of sb_k (their list indices) and sb_i (i). No other pair can come into contact while every
    # particle has moved less than half that reach, so the pair loop skips them (see
    # gather_sublists) and sums the same forces in the same order. A block's rows have their
    # entries one after the other from its first row's list offset (see gather_row), so a run of
    # rows is one run of entries.
    int *sb_k
    int *sb_i
    long long sbk_cap
    int *sb_n
    int *sb_at
    int sub_build      # this pass's pair loop builds the sublist: after a rebuild, ...
    double sub_travel  # ... and once its drifts since the last build may add up to half the reach
    long long sub_builds
    int *ob_start
    int *ob_j
    uint8_t *ob_s
    int *ob_c
    long long ob_cap
    int *wl_start
    int *wl_e
    double *wl_h
    long long wl_cap
    double *wl_f       # each listed wall entry (WLF, see wall_row, contact_forces), written only by a
                       # pass that records (see State.record); NULL unless recording
    long long wlf_cap
    int *ow_start
    int *ow_e
    double *ow_h
    long long ow_cap
    double *halo       # the pair blocks' halo buffers, 6 per row (see Halo)
    long long halo_cap
    Halo *halos
    int nfarblocks     # the blocks that can have far halos: those starting before row nfar
    int *last          # the largest near partner (see Halo) of the rows up to i
    int *flo           # row i's smallest and largest far partner (INT_MAX, -1: none)
    int *fhi
    int nfar           # rows after the first nfar have no far partners


cdef struct Walls:
    # The wall elements (ne of ecap allocated), the triangles near each cell, stress meshes
    # and vibrating meshes.
    int ne
    int ecap
    int *ekind
    int *etype
    int *ewall
    int *evid
    int *emoving
    double *egeo       # 9 per element: plane p,n; cylinder axis,c0,c1,R,inside; triangle vertices
    double *eref       # triangle vertices at the motion's start
    double *ebuilt     # triangle vertices at the last rebuild
    double *emot       # NMOT per element, see motion_origin
    int *ctri_start
    int *ctri
    long long ctri_cap
    int binned_dirty   # triangles added, removed or set in motion since the last binning
    double binned_reach
    int binned_nc[3]
    int nslots         # stress meshes (see Slot)
    double *slots      # NSLOT per stress mesh
    double *sacc       # the pair blocks' sums over stress meshes: SACC per mesh per block
    int nvib           # vibrating meshes (viblin, vibrot)
    double *vib        # NVIB per vibrating mesh, see vibration


cdef struct Clumps:
    # Rigid bodies of spheres (see _clumps.pxi): nbody bodies (bcap allocated) of nmem member
    # slots (mcap allocated); body b's slots are mstart[b] to mstart[b + 1] - 1.
    int nbody, bcap, nmem, mcap
    int64_t *bid       # per body: its id
    int *btype         # ... its spheres' type (viscous damping)
    double *bx         # ... centre of mass (3)
    double *bv         # ... velocity (3)
    double *bq         # ... orientation of its principal axes, a unit quaternion w, x, y, z (4)
    double *bp         # ... angular momentum in the principal frame (3)
    double *bm         # ... mass
    double *bI         # ... principal moments of inertia (3)
    double *bf         # ... force at the last evaluation (3)
    double *bt         # ... torque about the centre at the last evaluation (3)
    double *bdd        # ... scratch: its spheres' largest squared displacement since the rebuild
    int *mstart        # ... its first member slot (nbody + 1 entries)
    double *md         # per member slot: the sphere's offset from the centre, principal frame (3)
    double *mimg       # ... the periodic shift of the sphere's position (3, see place_bodies)
    int *mrow          # ... the sphere's storage row (since the last rebuild)
    int *mbody         # ... its body


cdef struct Schedule:
    # How the passes run: their blocks, the threads, and the timers.
    int nthreads
    int nblocks        # blocks of the pair loop
    int *pb            # rows [pb[b], pb[b + 1]) of the pair loop are block b
    int *work          # work of each row in the last pair loop (see row_work)
    long long *tstat   # per block (PAD apart): work of its rows, last row of its halo
    pg_flag *posted    # per block: the epoch of the team's last phase that ran it (see force_phase)
    double turn        # when the master began the particle loop of the last force phase
    pg_team *team      # the threads of a run (see pg_team)
    int rows           # rows of the current row phase
    Tuner tuner        # whether the master runs the phases with the team or alone
    double timers[NTIMERS]
    double *cpu        # per thread (PAD apart): CPU seconds in the pair and particle loops,
                       # in total and in the last step


cdef struct State:
    # The one copy of the solver's state: Core holds it, the kernels and the time-step loop
    # work on it (through a pointer, as the team's threads do). Its parts, then the box, the
    # contact model, the clock and counters, the displacement check and the force evaluation.
    Particles particles
    Lists lists
    Contacts contacts
    Walls walls
    Clumps clumps
    Schedule schedule
    int hs, model, rolling, roff, ntypes, dirty
    int whs            # history values per wall-list entry: hs + 1 (see wall_row)
    int batched        # hertz without rolling resistance on any pair: the pair loop's batched path
    double time, skin
    # the clock: time = t_base + (step - step_base) dt_base, re-based when dt changes, so it
    # does not accumulate round-off step by step
    double t_base, dt_base
    long long step_base
    long long step, lost, rebuilds
    # particles lost since the last take_lost: through each face x-, x+, y-, y+, z-, z+ of the
    # box and non-finite (LOST_PLACES), and the largest speed of those lost through a face
    long long lost_at[7]
    double lost_speed
    double lo[3]
    double hi[3]
    double L[3]
    int per[3]
    double grav[3]
    double shiftv[81]
    # contact tables
    Coef *coef
    double *visc
    double *tmax       # per thread (PAD apart): largest squared displacement, then squared speed
                       # (see pg_row_drift)
    # the displacement check: no free sphere has moved further since the last rebuild than
    # ``travel`` (the drifts' largest speeds times |dt|, summed over its ``since`` steps) and
    # round-off; while that proves no rebuild due, a drift need not measure each particle's
    # displacement from x0 (``measure``, see displacement; with clumps it always does)
    double travel
    double vlast       # the largest speed of the last drift
    double dw_last     # the walls' largest move since the rebuild, at the last step
    long long since
    int measure
    long long measured, passes   # steps whose drift measured, and passes that measured after one
    # the force evaluation under way (see forces): step, whether histories advance, whether
    # the particle loop kicks, and whether it fuses the next step's drift (see particle_row)
    double dt
    int update, kick, fuse
    # the pass ends a run (the set-up pass, a run's last step) and contact forces are recorded:
    # it writes the contacts' forces and wl_f, which only contact_forces reads; the steps
    # between skip those stores
    int record
    int forces_valid   # they hold the forces of the last recording pass (not after set_state)


cdef enum:   # the type of a Column's values
    F64 = 0
    I32 = 1
    I64 = 2


cdef struct Column:
    # A per-particle (or per-element, per-body, per-member) array of the State in an allocation
    # table (see particle_columns, element_columns, body_columns, member_columns).
    void** p           # where the State keeps its pointer
    int kind           # F64, I32 or I64
    int count          # values per particle
    size_t size        # bytes per particle
    int extra          # entries beyond one per particle (a CSR start array has cap + 1)
    const char* key    # its name in a checkpoint (Core.get_state), NULL: not saved


cdef inline void column(Column* c, void** p, int kind, int count, int extra, const char* key) noexcept nogil:
    c.p = p
    c.kind = kind
    c.count = count
    c.size = count * (sizeof(int) if kind == I32 else sizeof(int64_t) if kind == I64 else sizeof(double))
    c.extra = extra
    c.key = key


cdef void particle_columns(State* s, Column* c) noexcept nogil:
    """The allocation table: the NCOLUMNS per-particle arrays of the State, which Core grows
    together (reserve), frees (dealloc), counts (Core.memory) and checkpoints (state_of; the
    clump member slots ``mem`` with the clumps)."""
    column(&c[0], <void**>&s.particles.x, F64, 3, 0, "x")
    column(&c[1], <void**>&s.particles.v, F64, 3, 0, "v")
    column(&c[2], <void**>&s.particles.w, F64, 3, 0, "w")
    column(&c[3], <void**>&s.particles.f, F64, 3, 0, "f")
    column(&c[4], <void**>&s.particles.t, F64, 3, 0, "t")
    column(&c[5], <void**>&s.particles.x0, F64, 3, 0, "x0")
    column(&c[6], <void**>&s.particles.r, F64, 1, 0, "r")
    column(&c[7], <void**>&s.particles.m, F64, 1, 0, "m")
    column(&c[8], <void**>&s.particles.type, I32, 1, 0, "type")
    column(&c[9], <void**>&s.schedule.work, I32, 1, 0, NULL)
    column(&c[10], <void**>&s.particles.pid, I64, 1, 0, "id")
    column(&c[11], <void**>&s.lists.nb_start, I32, 1, 1, "nb_start")
    column(&c[12], <void**>&s.lists.ob_start, I32, 1, 1, NULL)
    column(&c[13], <void**>&s.lists.wl_start, I32, 1, 1, "wl_start")
    column(&c[14], <void**>&s.lists.ow_start, I32, 1, 1, NULL)
    column(&c[15], <void**>&s.lists.last, I32, 1, 0, NULL)
    column(&c[16], <void**>&s.lists.flo, I32, 1, 0, NULL)
    column(&c[17], <void**>&s.lists.fhi, I32, 1, 0, NULL)
    column(&c[18], <void**>&s.particles.mem, I32, 1, 0, NULL)
    column(&c[19], <void**>&s.lists.sb_n, I32, 1, 0, NULL)
    column(&c[20], <void**>&s.lists.sb_at, I32, 1, 0, NULL)


cdef void element_columns(State* s, Column* c) noexcept nogil:
    """The allocation table of the wall elements: the NECOLUMNS per-element arrays of the State,
    which Core grows together (add_elements), compacts (remove_elements), frees (dealloc) and
    checkpoints (state_of)."""
    column(&c[0], <void**>&s.walls.ekind, I32, 1, 0, "ekind")
    column(&c[1], <void**>&s.walls.etype, I32, 1, 0, "etype")
    column(&c[2], <void**>&s.walls.ewall, I32, 1, 0, "ewall")
    column(&c[3], <void**>&s.walls.emoving, I32, 1, 0, "emoving")
    column(&c[4], <void**>&s.walls.evid, I32, 3, 0, "evid")
    column(&c[5], <void**>&s.walls.egeo, F64, 9, 0, "egeo")
    column(&c[6], <void**>&s.walls.eref, F64, 9, 0, "eref")
    column(&c[7], <void**>&s.walls.ebuilt, F64, 9, 0, "ebuilt")
    column(&c[8], <void**>&s.walls.emot, F64, NMOT, 0, "emot")


cdef void body_columns(State* s, Column* c) noexcept nogil:
    """The allocation table of the clumps' bodies: the NBCOLUMNS per-body arrays of the State,
    which Core grows together (add_bodies), compacts (drop_bodies), frees (dealloc) and
    checkpoints (state_of)."""
    column(&c[0], <void**>&s.clumps.bid, I64, 1, 0, "body_id")
    column(&c[1], <void**>&s.clumps.btype, I32, 1, 0, "body_type")
    column(&c[2], <void**>&s.clumps.bx, F64, 3, 0, "body_x")
    column(&c[3], <void**>&s.clumps.bv, F64, 3, 0, "body_v")
    column(&c[4], <void**>&s.clumps.bq, F64, 4, 0, "body_q")
    column(&c[5], <void**>&s.clumps.bp, F64, 3, 0, "body_p")
    column(&c[6], <void**>&s.clumps.bm, F64, 1, 0, "body_m")
    column(&c[7], <void**>&s.clumps.bI, F64, 3, 0, "body_inertia")
    column(&c[8], <void**>&s.clumps.bf, F64, 3, 0, "body_f")
    column(&c[9], <void**>&s.clumps.bt, F64, 3, 0, "body_t")
    column(&c[10], <void**>&s.clumps.bdd, F64, 1, 0, NULL)
    column(&c[11], <void**>&s.clumps.mstart, I32, 1, 1, "body_start")


cdef void member_columns(State* s, Column* c) noexcept nogil:
    """The allocation table of the clumps' member slots: the NMCOLUMNS per-slot arrays."""
    column(&c[0], <void**>&s.clumps.md, F64, 3, 0, "member_offset")
    column(&c[1], <void**>&s.clumps.mimg, F64, 3, 0, "member_shift")
    column(&c[2], <void**>&s.clumps.mrow, I32, 1, 0, NULL)
    column(&c[3], <void**>&s.clumps.mbody, I32, 1, 0, NULL)
