# The solver's structs: contact coefficients, halos, the tuner and the state the
# time-step loop's kernels work on.

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


cdef struct Tuner:
    # The master runs the phases alone (solo) or with the team, whichever was faster per step
    # when last compared: it times windows of at least TUNE_WINDOW seconds and, every
    # ``interval`` seconds, a window of the other mode; the interval doubles (up to
    # TUNE_MAX) while the choice stands and falls back to TUNE_MIN when it changes. On a busy
    # machine the team waits for a thread whose CPU another program holds, on a small system
    # for its own hand-offs: then one thread is faster. Results do not depend on the choice.
    bint solo, probing
    long long steps     # steps in the current window
    double elapsed      # seconds of the window in earlier runs (between runs is not timed)
    double start, next_probe, interval
    double per_step[2]  # seconds per step with the team [0] and solo [1], when last timed


cdef struct Ctx:
    int n, cap, hs, whs, model, rolling, roff, nt, nblocks, ncells, update, kick, fuse
    int nc[3]
    int ax[3]
    double cs[3]
    double lo[3]
    double grav[3]
    double skin, dt, time
    double *x
    double *v
    double *w
    double *f
    double *t
    double *x0
    double *tmax
    double *r
    double *m
    int *type
    double *buf
    double *halo
    Halo *halos
    int nfarblocks
    int *last
    int *pb
    int *work
    long long *tstat
    int *perm
    int *cell
    int *nb_start
    int *nb_j
    uint8_t *nb_s
    double *nb_h
    int *ob_start
    int *ob_j
    uint8_t *ob_s
    double *ob_h
    int *wl_start
    int *wl_e
    double *wl_h
    int *ow_start
    int *ow_e
    double *ow_h
    int *cell_start
    int *ctri_start
    int *ctri
    int *per
    double *shiftv
    int ne
    int *ekind
    int *etype
    int *evid
    int *emoving
    double *egeo
    double *emot
    int *ewall
    int nslots
    double *slots
    int nvib
    double *vib
    double *sacc
    Coef *coef
    double *visc
    double *cpu
