# Moving walls: rigid motion (translation, rotation, wiggle) and vibration (viblin, vibrot)
# in closed form, the velocity of a wall at a contact, triangles placed at the current time,
# and stress meshes and servos (LIGGGHTS mesh/surface/stress/servo) with their controller.

cdef inline void motion_origin(const double* mot, double tau, double* o, double* vo) noexcept nogil:
    """Position and velocity of a moving wall's origin ``tau`` after its motion started.

    ``mot`` (offsets M_VEL...): velocity V (3), angular velocity W (3), origin o0 (3), start
    time, wiggle amplitude A (3) and period T (0: no wiggle); the origin is at
    ``o0 + V tau + A sin(2 pi tau / T)``, and the wall at ``o + R(W tau)(X - o0)``.
    """
    cdef double ph, s = 0.0, cw = 0.0
    cdef int k
    if mot[M_PERIOD] > 0.0:
        ph = 2.0 * M_PI * tau / mot[M_PERIOD]
        s = sin(ph)
        cw = 2.0 * M_PI / mot[M_PERIOD] * cos(ph)
    for k in range(3):
        o[k] = mot[M_ORIGIN + k] + mot[M_VEL + k] * tau + mot[M_AMP + k] * s
        vo[k] = mot[M_VEL + k] + mot[M_AMP + k] * cw


cdef inline const double* vibration_of(const double* vib, int nvib, int wall) noexcept nogil:
    """The vibration of a wall (its row of ``vib``), NULL for none."""
    cdef int k
    for k in range(nvib):
        if vib[NVIB * k + V_WALL] == wall:
            return &vib[NVIB * k]
    return NULL


cdef inline void vibration(const double* row, double tau, double* s, double* ds) noexcept nogil:
    """Displacement along the axis (viblin, m) or angle about it (vibrot, rad) ``tau`` after
    the motion started, and its rate: LIGGGHTS' ``move/mesh viblin`` and ``vibrot``, whose rate
    is ``-sum_j A_j w_j sin(w_j tau + phi_j)``, in closed form
    ``s = sum_j A_j (cos(w_j tau + phi_j) - cos(phi_j))``. ``row``: see V_WALL
    and the other V_ offsets."""
    cdef int j
    cdef double a
    s[0] = 0.0
    ds[0] = 0.0
    for j in range(<int>row[V_ORDER]):
        a = row[V_FREQ + j] * tau + row[V_PHASE + j]
        s[0] += row[V_AMP + j] * (cos(a) - cos(row[V_PHASE + j]))
        ds[0] -= row[V_AMP + j] * row[V_FREQ + j] * sin(a)


cdef inline void rotation(const double* w, double tau, double* Rm) noexcept nogil:
    """Rotation matrix (row major) of angle |w| tau about w (Rodrigues)."""
    cdef double wm = sqrt(dot3(w, w)), th, c, s, k0, k1, k2, C
    if wm == 0.0:
        memset(Rm, 0, 9 * sizeof(double))
        Rm[0] = 1.0
        Rm[4] = 1.0
        Rm[8] = 1.0
        return
    th = wm * tau
    c = cos(th)
    s = sin(th)
    C = 1.0 - c
    k0 = w[0] / wm
    k1 = w[1] / wm
    k2 = w[2] / wm
    Rm[0] = c + k0 * k0 * C
    Rm[1] = k0 * k1 * C - k2 * s
    Rm[2] = k0 * k2 * C + k1 * s
    Rm[3] = k1 * k0 * C + k2 * s
    Rm[4] = c + k1 * k1 * C
    Rm[5] = k1 * k2 * C - k0 * s
    Rm[6] = k2 * k0 * C - k1 * s
    Rm[7] = k2 * k1 * C + k0 * s
    Rm[8] = c + k2 * k2 * C


cdef inline int slot_of(const State* c, int e) noexcept nogil:
    """The stress mesh (index into ``slots``) wall element e belongs to, -1 for none."""
    cdef int s
    for s in range(c.walls.nslots):
        if c.walls.slots[NSLOT * s + S_WALL] == c.walls.ewall[e]:
            return s
    return -1


cdef inline void wall_velocity(const State* c, int e, const double* q, const double* sl,
                               double* vw) noexcept nogil:
    """Velocity ``vw`` of wall element e at point ``q`` (NULL: a fixed primitive, at rest): a
    servo's (``sl``: its stress mesh's values, NULL for none), or its rigid motion's and
    vibration's."""
    cdef double o[3]
    cdef double vo[3]
    cdef double rel[3]
    cdef const double* mot
    cdef const double* vb
    cdef double sv, dsv
    cdef int k
    for k in range(3):
        vw[k] = 0.0
    if sl != NULL and sl[S_CONTROL] == FORCE_SERVO:   # a force servo translates at its output
        for k in range(3):
            vw[k] = sl[S_VEL + k]
    elif sl != NULL and sl[S_CONTROL] == TORQUE_SERVO:   # a torque servo turns about its axis through com
        for k in range(3):
            rel[k] = q[k] - sl[S_XCM + k]
        cross3(&sl[S_VEL], rel, vw)
    elif q != NULL and c.walls.emoving[e]:
        mot = &c.walls.emot[NMOT * e]
        motion_origin(mot, c.time - mot[M_START], o, vo)
        for k in range(3):
            rel[k] = q[k] - o[k]
        cross3(&mot[M_OMEGA], rel, vw)
        for k in range(3):
            vw[k] += vo[k]
        vb = vibration_of(c.walls.vib, c.walls.nvib, c.walls.ewall[e]) if c.walls.nvib else NULL
        if vb != NULL:   # along the axis, or about it through the origin
            vibration(vb, c.time - mot[M_START], &sv, &dsv)
            for k in range(3):
                o[k] = dsv * vb[V_AXIS + k]
            if vb[V_KIND] == VIBLIN:
                for k in range(3):
                    vw[k] += o[k]
            else:
                cross3(o, rel, vo)
                for k in range(3):
                    vw[k] += vo[k]


cdef double move_walls(State* sim) noexcept nogil:
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
    for e in range(sim.walls.ne):
        if not sim.walls.emoving[e]:
            continue
        if sim.walls.ewall[e] != last:
            last = sim.walls.ewall[e]
            slot = -1
            for k in range(sim.walls.nslots):
                if sim.walls.slots[NSLOT * k + S_WALL] == last and sim.walls.slots[NSLOT * k + S_CONTROL] != STRESS_ONLY:
                    slot = k
            if slot >= 0:   # a force servo translates by com - com0, a torque servo turns by phi
                sl = &sim.walls.slots[NSLOT * slot]
                for d in range(3):
                    o[d] = sl[S_XCM + d]
                    o0[d] = sl[S_XCM0 + d]
                rotation(&sl[S_AXIS], sl[S_PHI] if sl[S_CONTROL] == TORQUE_SERVO else 0.0, Rm)
            else:
                mot = &sim.walls.emot[NMOT * e]
                motion_origin(mot, sim.time - mot[M_START], o, vo)
                rotation(&mot[M_OMEGA], sim.time - mot[M_START], Rm)
                for d in range(3):
                    o0[d] = mot[M_ORIGIN + d]
                vb = vibration_of(sim.walls.vib, sim.walls.nvib, last) if sim.walls.nvib else NULL
                if vb != NULL:   # viblin: the origin moves along the axis; vibrot: turns about it
                    vibration(vb, sim.time - mot[M_START], &sv, &dsv)
                    if vb[V_KIND] == VIBLIN:
                        for d in range(3):
                            o[d] += sv * vb[V_AXIS + d]
                    else:
                        rotation(&vb[V_AXIS], sv, Rm)
        for k in range(3):
            ref = &sim.walls.eref[9 * e + 3 * k]
            cur = &sim.walls.egeo[9 * e + 3 * k]
            for d in range(3):
                rel[d] = ref[d] - o0[d]
            dd = 0.0
            for d in range(3):
                cur[d] = o[d] + Rm[3 * d] * rel[0] + Rm[3 * d + 1] * rel[1] + Rm[3 * d + 2] * rel[2]
                s = cur[d] - sim.walls.ebuilt[9 * e + 3 * k + d]
                dd += s * s
            if dd > dmax:
                dmax = dd
    return sqrt(dmax)


cdef void servo_move(State* sim, double dt) noexcept nogil:
    """The servos' move at the start of a step (LIGGGHTS' initial_integrate): com by
    dt times the velocity, or the angle by dt times the angular velocity along the axis."""
    cdef int s, d
    cdef double* sl
    for s in range(sim.walls.nslots):
        sl = &sim.walls.slots[NSLOT * s]
        if sl[S_CONTROL] == FORCE_SERVO:
            for d in range(3):
                sl[S_XCM + d] += dt * sl[S_VEL + d]
        elif sl[S_CONTROL] == TORQUE_SERVO:
            sl[S_PHI] += dt * dot3(&sl[S_VEL], &sl[S_AXIS])


cdef void servo_sums(State* sim) noexcept nogil:
    """The particles' force, torque and contacts on each stress mesh: the pair blocks'
    sums, added in block order (the same bits whichever thread ran a block)."""
    cdef int s, b, k
    cdef double* sl
    cdef const double* a
    for s in range(sim.walls.nslots):
        sl = &sim.walls.slots[NSLOT * s]
        for k in range(NACC):
            sl[S_FORCE + k] = 0.0
        for b in range(sim.schedule.nblocks):
            a = &sim.walls.sacc[SACC * (sim.walls.nslots * b + s)]
            for k in range(NACC):
                sl[S_FORCE + k] += a[A_FORCE + k]


cdef void servo_control(State* sim, double dt) noexcept nogil:
    """The servos' new output at the end of a step: LIGGGHTS' final_integrate and limit_vel
    of mesh_module_stress_servo.cpp (its PID law on the force or torque along the axis, the
    piecewise P law of mode auto, the saturation and the integral's anti-windup)."""
    cdef int s, d
    cdef double* sl
    cdef double pv, err, kp, mag, vmag, limit, spinv, low = 0.9, high = 1.0, scale = 0.1
    for s in range(sim.walls.nslots):
        sl = &sim.walls.slots[NSLOT * s]
        if sl[S_CONTROL] == STRESS_ONLY:
            continue
        pv = dot3(&sl[S_FORCE if sl[S_CONTROL] == FORCE_SERVO else S_TORQUE], &sl[S_AXIS])
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


cdef void servo_start(State* sim, double dt) noexcept nogil:
    """As a run starts (LIGGGHTS' init): mode auto's speed in contact from the smallest
    particle present (a radius of 1e6 m without particles, as LIGGGHTS)."""
    cdef int s, i
    cdef double rmin = 1e6
    for i in range(sim.particles.n):
        rmin = min(rmin, sim.particles.r[i])
    for s in range(sim.walls.nslots):
        sim.walls.slots[NSLOT * s + S_OPMIN] = sim.walls.slots[NSLOT * s + S_RATIO] * rmin / dt \
            / sim.walls.slots[NSLOT * s + S_RPA]
