# Constants and enums of the native solver (included by _solver.pyx).

cdef enum:
    MAXCAND = 64       # triangles in reach of one particle that wall_row classifies, at most
    MAXHS = 10         # history values of a contact, at most (Thornton-Ning with a rolling spring)
    SPILL_KEPT = 256   # contacts a pair block's spill keeps room for between passes (see settle_slots)
    ORDERED_RUN = 8    # contacts in list order per run of consecutive slots, on average, below
                       # which a rebuild renumbers them (see renew_slots)
    NCOLUMNS = 21      # per-particle arrays, see particle_columns
    NBCOLUMNS = 12     # per-body arrays of clumps, see body_columns
    NMCOLUMNS = 4      # per-member arrays of clumps, see member_columns
    NECOLUMNS = 9      # per-element arrays, see element_columns
    PAD = 8            # doubles per cache line: per-thread scalars are this far apart
    TOUCH = 0x80       # flag bit of nb_s: the pair was in contact at the last force evaluation
    WRAP = 0x40        # flag bit of nb_s: the partner is across the periodic boundary of axis ax[0]
    IMAGE = 0x1f       # bits of nb_s: the periodic image code
    NMOT = 14          # motion values per wall element, see Motion
    NSLOT = 34         # values per stress mesh (a mesh whose force is summed, maybe a servo), see Slot
    NVIB = 96          # values per vibrating mesh, see Vibration
    NHARM = 30         # harmonics of a vibration at most
    SACC = 8           # values per stress mesh in a pair block's sums, see Slot (A_FORCE...)
    WROW = 5           # work of a row of the pair loop, a touching pair and a wall entry in units of
    WTOUCH = 12        # a listed pair that is apart (measured: about 20, 48, 48 and 4 ns)
    BLOCKS = 4         # blocks of the pair loop per thread (more threads than one): a thread
                       # kept from its core holds up at most 1 / (BLOCKS threads) of a pass
    SPLIT = 4          # blocks of the particle loop per pair-loop block: its threads end closer
    BIG_MAX = 4096     # big particles (see split_radius) at most: their pairs among them are
                       # found by trying each pair

# Constants in seconds or skins, as C literals (macros), so the compiler folds them as before.
cdef extern from *:
    """
    #define PG_SUB_SKIN 0.125      /* the sublist's reach beyond contact, in skins (see State.sb_k) */
    #define PG_TUNE_WINDOW 0.02    /* seconds: shortest window the Tuner times */
    #define PG_TUNE_MIN 0.1        /* seconds between the Tuner's comparisons, at first and after a change */
    #define PG_TUNE_MAX 2.0        /* ... at most */
    #define PG_TUNE_AHEAD 0.75     /* the team's time per step, at most, against its guess of one thread's ... */
    #define PG_TUNE_TRUSTED 10.0   /* ... for the Tuner to skip comparisons for up to this many seconds */
    """
    const double SUB_SKIN "PG_SUB_SKIN"
    const double TUNE_WINDOW "PG_TUNE_WINDOW"
    const double TUNE_MIN "PG_TUNE_MIN"
    const double TUNE_MAX "PG_TUNE_MAX"
    const double TUNE_AHEAD "PG_TUNE_AHEAD"
    const double TUNE_TRUSTED "PG_TUNE_TRUSTED"

cdef enum:
    HOOKE = 0
    HERTZ = 1
    THORNTON_NING = 2

cdef enum:
    CDT = 0            # rolling resistance models (LIGGGHTS rolling_friction cdt, epsd, epsd2)
    EPSD = 1
    EPSD2 = 2

cdef enum:
    NO_CONTACT = 0     # the history is cleared
    IN_CONTACT = 1
    MEMORY = 2         # Thornton-Ning: apart, plastic history kept while the bodies still overlap

cdef enum:
    PLANE = 0
    CYLINDER = 1
    TRIANGLE = 2

cdef enum:
    FACE = 0
    EDGE = 1
    VERTEX = 2

# wall-clock timers of the time-step loop's phases (seconds), in the order of TIMERS
cdef enum:
    T_RUN = 0
    T_DRIFT = 1
    T_WALLS = 2
    T_PAIRS = 3
    T_PARTICLES = 4
    T_REBUILD = 5
    T_CELLS = 6
    T_SORT = 7
    T_PERMUTE = 8
    T_COUNT = 9
    T_FILL = 10
    T_FORCES_SPAN = 11
    NTIMERS = 12


# phases of a run on the team (see take)
cdef enum:
    P_DRIFT = 1
    P_FORCES = 2       # the pair loop, then the particle loop (see force_phase)
    P_PLACE = 4
    P_GATHER = 5
    P_GATHER_SCALARS = 6
    P_COPY_BACK = 7
    P_COUNT = 8
    P_FILL = 9
    P_BODIES = 10      # clumps: sum their spheres' forces, kick (and with fuse drift), see body_row
    P_BODY_DRIFT = 11  # clumps: first half kick and drift
    P_DISPLACEMENT = 12  # the largest displacement since the rebuild, of a drift that did not measure it

# A stress mesh's values (NSLOT doubles): the particles' force on it is summed each step (LIGGGHTS
# mesh/surface/stress); a servo moves it by LIGGGHTS' controller (mesh/surface/stress/servo,
# mesh_module_stress_servo.cpp), see servo_control.
cdef enum:
    S_WALL = 0         # the mesh's wall handle
    S_CONTROL = 1      # STRESS_ONLY, FORCE_SERVO or TORQUE_SERVO
    S_AUTO = 2         # 1: mode auto (piecewise P controller), 0: PID
    S_SP = 3           # set point: -target (the particles' force acts against the servo's push)
    S_VMAX = 4         # vel_max (m/s)
    S_KP = 5
    S_KI = 6
    S_KD = 7
    S_RATIO = 8        # mode auto: speed in contact ratio r_min / dt
    S_OPMAX = 9        # largest output: vel_max, or vel_max / (largest node distance from the axis)
    S_RPA = 10         # 1, or the largest node distance from the axis (torque)
    S_OPMIN = 11       # mode auto: ratio r_min / dt / S_RPA, set as each run starts
    S_AXIS = 12        # the unit axis (3)
    S_XCM = 15         # the reference point (com), moving with a force servo (3)
    S_XCM0 = 18        # com when the servo was set (the mesh's reference vertices belong to it) (3)
    S_VEL = 21         # the controller's output: velocity or angular velocity (3)
    S_PHI = 24         # torque: angle turned since the servo was set
    S_SUM = 25         # integral of the error
    S_OLDPV = 26       # the process value of the previous step
    S_FORCE = 27       # the particles' force on the mesh at the last step (3)
    S_TORQUE = 30      # ... their torque about S_XCM (3)
    S_CONTACTS = 33    # ... and the number of contacts

# The particles' sums over a stress mesh in a pair block (SACC per mesh), added up into its
# S_FORCE, S_TORQUE and S_CONTACTS (in this order: servo_sums adds NACC values at once).
cdef enum:
    A_FORCE = 0        # force on the mesh (3)
    A_TORQUE = 3       # its torque about S_XCM (3)
    A_CONTACTS = 6     # contacts
    NACC = 7

# A contact's history values (hs per listed pair, hs + 1 per wall entry), see contact_force.
cdef enum:
    H_SHEAR = 0        # the tangential spring's displacement (3)
    H_FN = 3           # the normal force at the last evaluation
    H_DMAX = 4         # Thornton-Ning: the largest overlap (negated: broken, see tn_normal)
    H_RP = 5           # ... the unloading curvature radius
    H_DP = 6           # ... the plastic offset
    # then, with rolling epsd or epsd2, the rolling spring's torque (3) from ``roff`` = hs - 3,
    # and for a wall entry the side of a plane contact at ``hs`` (see wall_row)

# A moving wall element's motion values (NMOT per element, see motion_origin).
cdef enum:
    M_VEL = 0          # translation velocity V (3)
    M_OMEGA = 3        # angular velocity W (3)
    M_ORIGIN = 6       # the origin o0 at the motion's start (3)
    M_START = 9        # the motion's start time
    M_AMP = 10         # wiggle amplitude A (3)
    M_PERIOD = 13      # wiggle period T (0: no wiggle)

# A vibrating mesh's values (NVIB per mesh, see vibration): LIGGGHTS' move/mesh viblin, vibrot.
cdef enum:
    V_WALL = 0         # the mesh's wall handle
    V_KIND = 1         # VIBLIN or VIBROT
    V_ORDER = 2        # harmonics
    V_AXIS = 3         # the unit axis (3)
    V_AMP = 6          # amplitudes A (NHARM)
    V_PHASE = 36       # phases phi (NHARM)
    V_FREQ = 66        # angular frequencies w (NHARM)

cdef enum:
    VIBLIN = 1
    VIBROT = 2

# What a stress mesh's S_CONTROL says: its force is summed only, or it is a servo on the
# force along its axis (it translates) or on the torque about it (it turns).
cdef enum:
    STRESS_ONLY = 0
    FORCE_SERVO = 1
    TORQUE_SERVO = 2
