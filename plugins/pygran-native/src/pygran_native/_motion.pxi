# Moving walls: triangles placed at the current time by their rigid motion, vibration or
# servo, and the servos' controller (LIGGGHTS mesh/surface/stress/servo).

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
    for e in range(sim.ne):
        if not sim.emoving[e]:
            continue
        if sim.ewall[e] != last:
            last = sim.ewall[e]
            slot = -1
            for k in range(sim.nslots):
                if sim.slots[NSLOT * k + S_WALL] == last and sim.slots[NSLOT * k + S_CONTROL] != 0.0:
                    slot = k
            if slot >= 0:   # a force servo translates by com - com0, a torque servo turns by phi
                sl = &sim.slots[NSLOT * slot]
                for d in range(3):
                    o[d] = sl[S_XCM + d]
                    o0[d] = sl[S_XCM0 + d]
                rotation(&sl[S_AXIS], sl[S_PHI] if sl[S_CONTROL] == 2.0 else 0.0, Rm)
            else:
                mot = &sim.emot[NMOT * e]
                motion_origin(mot, sim.time - mot[M_START], o, vo)
                rotation(&mot[M_OMEGA], sim.time - mot[M_START], Rm)
                for d in range(3):
                    o0[d] = mot[M_ORIGIN + d]
                vb = vibration_of(sim.vib, sim.nvib, last) if sim.nvib else NULL
                if vb != NULL:   # viblin: the origin moves along the axis; vibrot: turns about it
                    vibration(vb, sim.time - mot[M_START], &sv, &dsv)
                    if vb[V_KIND] == VIBLIN:
                        for d in range(3):
                            o[d] += sv * vb[V_AXIS + d]
                    else:
                        rotation(&vb[V_AXIS], sv, Rm)
        for k in range(3):
            ref = &sim.eref[9 * e + 3 * k]
            cur = &sim.egeo[9 * e + 3 * k]
            for d in range(3):
                rel[d] = ref[d] - o0[d]
            dd = 0.0
            for d in range(3):
                cur[d] = o[d] + Rm[3 * d] * rel[0] + Rm[3 * d + 1] * rel[1] + Rm[3 * d + 2] * rel[2]
                s = cur[d] - sim.ebuilt[9 * e + 3 * k + d]
                dd += s * s
            if dd > dmax:
                dmax = dd
    return sqrt(dmax)


cdef void servo_move(State* sim, double dt) noexcept nogil:
    """The servos' move at the start of a step (LIGGGHTS' initial_integrate): com by
    dt times the velocity, or the angle by dt times the angular velocity along the axis."""
    cdef int s, d
    cdef double* sl
    for s in range(sim.nslots):
        sl = &sim.slots[NSLOT * s]
        if sl[S_CONTROL] == 1.0:
            for d in range(3):
                sl[S_XCM + d] += dt * sl[S_VEL + d]
        elif sl[S_CONTROL] == 2.0:
            sl[S_PHI] += dt * dot3(&sl[S_VEL], &sl[S_AXIS])


cdef void servo_sums(State* sim) noexcept nogil:
    """The particles' force, torque and contacts on each stress mesh: the pair blocks'
    sums, added in block order (the same bits whichever thread ran a block)."""
    cdef int s, b, k
    cdef double* sl
    cdef const double* a
    for s in range(sim.nslots):
        sl = &sim.slots[NSLOT * s]
        for k in range(NACC):
            sl[S_FORCE + k] = 0.0
        for b in range(sim.nblocks):
            a = &sim.sacc[SACC * (sim.nslots * b + s)]
            for k in range(NACC):
                sl[S_FORCE + k] += a[A_FORCE + k]


cdef void servo_control(State* sim, double dt) noexcept nogil:
    """The servos' new output at the end of a step: LIGGGHTS' final_integrate and limit_vel
    of mesh_module_stress_servo.cpp (its PID law on the force or torque along the axis, the
    piecewise P law of mode auto, the saturation and the integral's anti-windup)."""
    cdef int s, d
    cdef double* sl
    cdef double pv, err, kp, mag, vmag, limit, spinv, low = 0.9, high = 1.0, scale = 0.1
    for s in range(sim.nslots):
        sl = &sim.slots[NSLOT * s]
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


cdef void servo_start(State* sim, double dt) noexcept nogil:
    """As a run starts (LIGGGHTS' init): mode auto's speed in contact from the smallest
    particle present (a radius of 1e6 m without particles, as LIGGGHTS)."""
    cdef int s, i
    cdef double rmin = 1e6
    for i in range(sim.n):
        rmin = min(rmin, sim.r[i])
    for s in range(sim.nslots):
        sim.slots[NSLOT * s + S_OPMIN] = sim.slots[NSLOT * s + S_RATIO] * rmin / dt \
            / sim.slots[NSLOT * s + S_RPA]
