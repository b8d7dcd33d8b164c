# The Tuner (a heuristic of the team, built with PG_TEAM_HEURISTICS): before each step, whether
# the master runs the phases with the team or alone, whichever was faster when last compared
# (see Tuner in _state.pxi).

cdef double loops_cpu(const State* sim) noexcept nogil:
    """The CPU seconds of all threads in the pair and particle loops, in all runs."""
    cdef int t
    cdef double total = 0.0
    for t in range(sim.schedule.nthreads):
        total += sim.schedule.cpu[PAD * t] + sim.schedule.cpu[PAD * t + 1]
    return total


cdef inline void mark_window(State* sim, double loops_wall) noexcept nogil:
    """Keep the timers the Tuner's window that starts now is measured from: rebuilds, and the
    pair and particle loops' wall time (``loops_wall``) and CPU time."""
    sim.schedule.tuner.rebuilt = sim.schedule.timers[T_REBUILD]
    sim.schedule.tuner.loops_wall = loops_wall
    sim.schedule.tuner.loops_cpu = loops_cpu(sim)


cdef void tune(State* sim) noexcept nogil:
    """Before a step: time the window that ends here and choose how to run the next
    one (see Tuner)."""
    cdef Tuner* u = &sim.schedule.tuner
    cdef double now = pg_now(), window, loops_wall = sim.schedule.timers[T_PAIRS] + sim.schedule.timers[T_PARTICLES]
    cdef double one_thread
    cdef int probe
    if u.interval == 0.0:   # the first step with a team
        u.interval = TUNE_MIN
        u.next_probe = now + TUNE_WINDOW
        u.probed = now
        mark_window(sim, loops_wall)
    window = u.elapsed + now - u.start - (sim.schedule.timers[T_REBUILD] - u.rebuilt)
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
            one_thread = window - (loops_wall - u.loops_wall) + (loops_cpu(sim) - u.loops_cpu)
            if not u.solo and window < TUNE_AHEAD * one_thread and now < u.probed + TUNE_TRUSTED:
                u.next_probe = now + u.interval
            else:
                u.probing = True
                u.solo = not u.solo
                u.probed = now
        u.steps = 0
        u.elapsed = 0.0
        u.start = now
        mark_window(sim, loops_wall)
    u.steps += 1
    u.solo_steps += u.solo
