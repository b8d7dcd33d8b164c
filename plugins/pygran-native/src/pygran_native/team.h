#ifndef PYGRAN_TEAM_H
#define PYGRAN_TEAM_H

/* The team of threads of a native-solver run (used by _team.pxi; tested alone, under
   ThreadSanitizer, by tests/team_stress.c).

   The calling thread (the master) runs the time-step loop and hands each parallel phase out
   as numbered blocks, a contiguous share of them queued for each thread. A thread takes
   blocks from its own queue, then from the others' queues, then waits for the next phase: on
   an idle machine each thread works on the same rows step after step, and a thread held up
   (its core taken by another program) leaves its blocks to the others. Results do not depend
   on which thread runs a block.

   A phase can have two stages, each with its own queues: no block of the second is taken
   while one of the first is left. A block of the second stage may wait for blocks of the
   first (pg_post, pg_await); those are then taken already, so they finish without waiting.

   A waiting thread spins for PG_SPIN seconds (waking a sleeping thread takes tens of
   microseconds), then sleeps on a futex.

   API (everything else here is internal):
     pg_create(nthreads), pg_destroy(t)          a team; its threads start at the first pg_start
     pg_start(t, task, owner)                    start threads 1.. (again after a fork)
     epoch = pg_begin(t, phase, nfirst, nsecond) master: open a phase, wake the threads
     b = pg_claim(t, epoch, tid)                 a block to run, -1 when none is left
     pg_finished(t, k)                           a thread ran k blocks and found none left
     pg_wait_done(t)                             master: wait until every block is finished
     pg_flags(n), pg_post(f, epoch),             per-block flags: a block of the first stage
       pg_posted(f, epoch), pg_await(f, epoch)   is done, for a block of the second to wait
     pg_now()                                    monotonic seconds
     pg_moves(t)                                 moves off a teammate's CPU (heuristics)

   Heuristics (build option PG_TEAM_HEURISTICS, on unless defined 0):
   - a waiting thread does not spin at all while it has lately been kept waiting for its CPU
     (its run-queue delay, /proc/thread-self/schedstat, see pg_contended): a thread with
     nothing to do then gives its core away at once. Spinning in OpenMP's barriers (libgomp's
     default wait policy) made 2 threads 7x slower than 1 on a 2-core machine where another
     process kept a core busy.
   - a woken thread that finds itself on the CPU of another thread of the team moves to one of
     the team's CPUs that none of them is on (pg_spread). When no CPU is idle, Linux wakes a
     thread on its waker's CPU; two threads of the team then take turns on one CPU while the
     other program has a CPU to itself, and the load balancer leaves it so. */
#ifndef _GNU_SOURCE
#define _GNU_SOURCE   /* sched_getcpu, cpu_set_t; before the first system header */
#endif
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <pthread.h>
#include <signal.h>
#include <limits.h>
#include <stdio.h>
#include <time.h>
#include <sched.h>
#ifdef __linux__
#include <fcntl.h>
#include <linux/futex.h>
#include <sys/syscall.h>
#include <unistd.h>
#endif

#ifndef PG_TEAM_HEURISTICS
#define PG_TEAM_HEURISTICS 1
#endif
#define PG_SPIN 1e-4         /* seconds a waiting thread spins before it sleeps */
#define PG_MAX_THREADS 1024  /* with 4 blocks per thread, a stage's blocks stay below 65536 */
#define PG_STOP (-1)         /* the phase that ends the threads */

typedef struct { uint32_t word, sleepers; char pad[56]; } pg_flag;   /* a cache line */

/* A thread's queues of the two stages (each epoch << 32 | front << 16 | end), the CPU it was
   on at its last phase and how often it moved off a CPU of the team's (pg_spread). */
typedef struct { uint64_t word[2]; int cpu, moves; char pad[40]; } pg_queue;

/* What a thread does with phase `epoch`: claim blocks with pg_claim, run them, pg_finished. */
typedef void (*pg_task)(void* owner, uint32_t epoch, int phase, int nblocks, int tid);

struct pg_team_s;
typedef struct { struct pg_team_s* team; int tid; uint32_t epoch; } pg_start_arg;

typedef struct pg_team_s {
    char pad0[64];
    pg_flag epoch;         /* phase number; the threads wait for it to change */
    pg_flag done;          /* blocks finished in the phase; the master waits for nblocks */
    int phase, nblocks;    /* written by the master before it moves epoch on: the phase, its */
    int nfirst;            /* blocks, and those of its first stage */
    int nqueues;           /* one per thread */
    pg_task task;          /* the threads started by pg_start (in process pid) */
    void* owner;
    pthread_t* threads;
    pg_start_arg* args;
    int started;
    pid_t pid;
#ifdef __linux__
    cpu_set_t cpus;        /* the CPUs the team may use: the master's at its last pg_start */
#endif
    char pad1[64];
    pg_queue queue[];      /* thread q's blocks */
} pg_team;

static pg_team* pg_create(int nthreads) {
    pg_team* t = (pg_team*)calloc(1, sizeof(pg_team) + nthreads * sizeof(pg_queue));
    int q;
    if (t) {
        for (q = 0; q < nthreads; q++)
            t->queue[q].cpu = -1;
        t->nqueues = nthreads;
    }
    return t;
}

static inline double pg_now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static inline void pg_relax(void) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield" ::: "memory");
#endif
}

#if PG_TEAM_HEURISTICS && defined(__linux__)
/* Nanoseconds the calling thread has spent runnable but waiting for a CPU, -1 if unknown. */
static long long pg_run_delay(void) {
    char buf[96];
    unsigned long long run, delay;
    ssize_t k;
    int fd = open("/proc/thread-self/schedstat", O_RDONLY | O_CLOEXEC);
    if (fd < 0)
        return -1;
    k = read(fd, buf, sizeof(buf) - 1);
    close(fd);
    if (k <= 0)
        return -1;
    buf[k] = 0;
    return sscanf(buf, "%llu %llu", &run, &delay) == 2 ? (long long)delay : -1;
}

/* Whether the calling thread shares its CPU with another that wants it: more than a fifth of
   a window of 50 ms or more spent waiting for it; then its waits do not spin for the next
   100 ms. One interruption of up to 10 ms does not count: with windows of 10 ms, the few
   interruptions of about 3 ms that a quiet 2-CPU virtual machine had per run made the waits
   of a team's thread sleep for a tenth of the run, each wake-up tens of microseconds late. */
static __thread double pg_checked = -1.0, pg_calm_from = 0.0;
static __thread long long pg_delay = -1;
static int pg_contended(double now) {
    long long d;
    if (now - pg_checked >= 5e-2) {
        d = pg_run_delay();
        if (d >= 0 && pg_delay >= 0 && d - pg_delay > 0.2e9 * (now - pg_checked))
            pg_calm_from = now + 0.1;
        pg_delay = d;
        pg_checked = now;
    }
    return now < pg_calm_from;
}

/* Thread tid, woken for a phase: if another thread of the team was on its CPU at its last
   phase, move to a CPU of the team's that none was on, when there is one (the change of
   affinity moves the thread; putting the team's CPUs back then leaves it there). */
static void pg_spread(pg_team* t, int tid) {
    cpu_set_t free_cpus;
    int q, other, shared = 0, cpu = sched_getcpu();
    if (cpu < 0 || cpu >= CPU_SETSIZE)
        return;
    free_cpus = t->cpus;
    for (q = 0; q < t->nqueues; q++) {
        if (q == tid || (other = __atomic_load_n(&t->queue[q].cpu, __ATOMIC_RELAXED)) < 0
            || other >= CPU_SETSIZE)
            continue;
        shared |= other == cpu;
        CPU_CLR(other, &free_cpus);
    }
    CPU_CLR(cpu, &free_cpus);
    if (shared && CPU_COUNT(&free_cpus) && sched_setaffinity(0, sizeof(cpu_set_t), &free_cpus) == 0) {
        sched_setaffinity(0, sizeof(cpu_set_t), &t->cpus);
        cpu = sched_getcpu();
        __atomic_store_n(&t->queue[tid].moves, t->queue[tid].moves + 1, __ATOMIC_RELAXED);
    }
    __atomic_store_n(&t->queue[tid].cpu, cpu, __ATOMIC_RELAXED);
}
#else
static inline int pg_contended(double now) { (void)now; return 0; }
static inline void pg_spread(pg_team* t, int tid) { (void)t; (void)tid; }
#endif

/* How often the team's threads moved off a teammate's CPU (pg_spread). */
static long long pg_moves(pg_team* t) {
    long long k = 0;
    int q;
    for (q = 0; q < t->nqueues; q++)
        k += __atomic_load_n(&t->queue[q].moves, __ATOMIC_RELAXED);
    return k;
}

static inline void pg_wake(pg_flag* f) {
    if (__atomic_load_n(&f->sleepers, __ATOMIC_SEQ_CST)) {
#ifdef __linux__
        syscall(SYS_futex, &f->word, FUTEX_WAKE_PRIVATE, INT_MAX, NULL, NULL, 0);
#endif
    }
}

/* Wait until f's word differs from `seen` (spin, then sleep); returns the new value. */
static uint32_t pg_wait(pg_flag* f, uint32_t seen) {
    uint32_t v;
    unsigned k = 0;
    double now, until;
    if ((v = __atomic_load_n(&f->word, __ATOMIC_ACQUIRE)) != seen)
        return v;
    now = pg_now();
    until = now + (pg_contended(now) ? 0.0 : PG_SPIN);
    while ((v = __atomic_load_n(&f->word, __ATOMIC_ACQUIRE)) == seen) {
        if (k++ & 63 && now < until) {   /* spinning: the clock is read every 64 rounds */
            pg_relax();
            continue;
        }
        now = pg_now();
        if (now < until)
            continue;
        __atomic_add_fetch(&f->sleepers, 1, __ATOMIC_SEQ_CST);
#ifdef __linux__
        syscall(SYS_futex, &f->word, FUTEX_WAIT_PRIVATE, seen, NULL, NULL, 0);
#else
        sched_yield();
#endif
        __atomic_sub_fetch(&f->sleepers, 1, __ATOMIC_SEQ_CST);
    }
    return v;
}

/* Master: open phase `phase` of `nfirst` blocks, then `nsecond` in a second stage (blocks
   nfirst to nfirst + nsecond - 1; each stage < 65536 blocks), and wake the team; returns the
   phase's epoch, which the master passes to pg_claim like the other threads. */
static uint32_t pg_begin(pg_team* t, int phase, int nfirst, int nsecond) {
    uint32_t e = __atomic_load_n(&t->epoch.word, __ATOMIC_RELAXED) + 1;
    uint64_t lo, hi;
    int q, s, n;
    if (e == 0)   /* after 2^32 phases: 0 is no phase (flags start at 0, see pg_post) */
        e = 1;
#if PG_TEAM_HEURISTICS && defined(__linux__)
    __atomic_store_n(&t->queue[0].cpu, sched_getcpu(), __ATOMIC_RELAXED);
#endif
    __atomic_store_n(&t->phase, phase, __ATOMIC_RELAXED);
    __atomic_store_n(&t->nblocks, nfirst + nsecond, __ATOMIC_RELAXED);
    __atomic_store_n(&t->nfirst, nfirst, __ATOMIC_RELAXED);
    __atomic_store_n(&t->done.word, 0, __ATOMIC_RELAXED);
    for (s = 0; s < 2; s++) {
        n = s ? nsecond : nfirst;
        for (q = 0; q < t->nqueues; q++) {
            lo = (uint64_t)n * q / t->nqueues;
            hi = (uint64_t)n * (q + 1) / t->nqueues;
            __atomic_store_n(&t->queue[q].word[s], (uint64_t)e << 32 | lo << 16 | hi, __ATOMIC_RELAXED);
        }
    }
    __atomic_store_n(&t->epoch.word, e, __ATOMIC_SEQ_CST);
    pg_wake(&t->epoch);
    return e;
}

/* The front (or last) block of queue q of stage s of phase `epoch`, counted in the stage; -1
   when it is empty or the phase is over. */
static inline int pg_take(pg_queue* q, int s, uint32_t epoch, int last) {
    uint64_t w = __atomic_load_n(&q->word[s], __ATOMIC_ACQUIRE);
    uint32_t lo, hi;
    for (;;) {
        lo = (w >> 16) & 0xffff;
        hi = w & 0xffff;
        if ((uint32_t)(w >> 32) != epoch || lo >= hi)
            return -1;
        if (__atomic_compare_exchange_n(&q->word[s], &w, last ? w - 1 : w + (1u << 16), 1,
                                        __ATOMIC_ACQ_REL, __ATOMIC_ACQUIRE))
            return (int)(last ? hi - 1 : lo);
    }
}

/* A block of phase `epoch` for thread `tid`, of its first stage while one is left: the next
   of its own queue, which even threads run forwards and odd threads backwards (two
   neighbouring threads reach the blocks at their common border last), else one of another
   queue (the nearest after its own first), from its other end in the first stage and from
   the end its owner takes next in the second (those depend on the first stage's blocks in
   the owner's order, so they are the ones that are ready); -1 when none is left. */
static inline int pg_claim(pg_team* t, uint32_t epoch, int tid) {
    int k, b, q, s, base, nq = t->nqueues;
    for (s = 0; s < 2; s++) {
        base = s ? __atomic_load_n(&t->nfirst, __ATOMIC_RELAXED) : 0;   /* the stage's first block */
        if (tid < nq && (b = pg_take(&t->queue[tid], s, epoch, tid & 1)) >= 0)
            return base + b;
        for (k = 1; k < nq; k++) {
            q = (tid + k) % nq;
            if ((b = pg_take(&t->queue[q], s, epoch, s ? (q & 1) : !(q & 1))) >= 0)
                return base + b;
        }
    }
    return -1;
}

/* n (> 0) zeroed flags, each on a cache line of its own (free with free); NULL when out of
   memory. */
static pg_flag* pg_flags(int n) {
    void* p = NULL;
    if (posix_memalign(&p, 64, (size_t)n * sizeof(pg_flag)) != 0)
        return NULL;
    return (pg_flag*)memset(p, 0, (size_t)n * sizeof(pg_flag));
}

/* A block of the first stage of phase `epoch` is done: stamp its flag f with the epoch. */
static inline void pg_post(pg_flag* f, uint32_t epoch) {
    __atomic_store_n(&f->word, epoch, __ATOMIC_SEQ_CST);
    pg_wake(f);
}

/* Whether flag f carries the stamp of phase `epoch` (see pg_post). */
static inline int pg_posted(pg_flag* f, uint32_t epoch) {
    return __atomic_load_n(&f->word, __ATOMIC_ACQUIRE) == epoch;
}

/* Wait until flag f carries the stamp of phase `epoch` (see pg_post). */
static inline void pg_await(pg_flag* f, uint32_t epoch) {
    uint32_t v;
    while ((v = __atomic_load_n(&f->word, __ATOMIC_ACQUIRE)) != epoch)
        pg_wait(f, v);
}

/* A thread ran k blocks of the phase (after its last claim failed). */
static inline void pg_finished(pg_team* t, int k) {
    if ((int)__atomic_add_fetch(&t->done.word, (uint32_t)k, __ATOMIC_SEQ_CST)
            == __atomic_load_n(&t->nblocks, __ATOMIC_RELAXED))
        pg_wake(&t->done);
}

/* Master: wait until every block of the phase is finished. */
static void pg_wait_done(pg_team* t) {
    uint32_t d;
    int nblocks = __atomic_load_n(&t->nblocks, __ATOMIC_RELAXED);
    while ((int)(d = __atomic_load_n(&t->done.word, __ATOMIC_ACQUIRE)) != nblocks)
        pg_wait(&t->done, d);
}

static void* pg_main(void* p) {
    pg_start_arg* a = (pg_start_arg*)p;
    pg_team* t = a->team;
    uint32_t e = a->epoch;
    int phase;
    for (;;) {
        e = pg_wait(&t->epoch, e);
        phase = __atomic_load_n(&t->phase, __ATOMIC_RELAXED);
        if (phase == PG_STOP)
            return NULL;
        pg_spread(t, a->tid);
        t->task(t->owner, e, phase, __atomic_load_n(&t->nblocks, __ATOMIC_RELAXED), a->tid);
    }
}

/* Start threads 1 .. nthreads - 1 of the team (the caller is thread 0), unless they run
   already in this process (after a fork they do not); they take part in each phase the
   master opens, with signals blocked (Python handles them in its main thread). Returns how
   many run: fewer when the system refuses some, and the others then run their blocks. */
static int pg_start(pg_team* t, pg_task task, void* owner) {
    sigset_t all, old;
    int k;
#if PG_TEAM_HEURISTICS && defined(__linux__)
    if (sched_getaffinity(0, sizeof(cpu_set_t), &t->cpus) != 0)
        CPU_ZERO(&t->cpus);
#endif
    if (t->started && t->pid == getpid())
        return t->started;
    t->started = 0;
    t->pid = getpid();
    t->task = task;
    t->owner = owner;
    if (!t->threads)
        t->threads = (pthread_t*)calloc(t->nqueues, sizeof(pthread_t));
    if (!t->args)
        t->args = (pg_start_arg*)calloc(t->nqueues, sizeof(pg_start_arg));
    if (!t->threads || !t->args)
        return 0;
    sigfillset(&all);
    pthread_sigmask(SIG_SETMASK, &all, &old);
    for (k = 1; k < t->nqueues; k++) {
        t->args[k].team = t;
        t->args[k].tid = k;
        t->args[k].epoch = __atomic_load_n(&t->epoch.word, __ATOMIC_ACQUIRE);
        if (pthread_create(&t->threads[k], NULL, pg_main, &t->args[k]) != 0)
            break;
        t->started++;
    }
    pthread_sigmask(SIG_SETMASK, &old, NULL);
    return t->started;
}

/* End the threads pg_start started in this process and free the team. */
static void pg_destroy(pg_team* t) {
    int k;
    if (!t)
        return;
    if (t->started && t->pid == getpid()) {
        pg_begin(t, PG_STOP, 0, 0);
        for (k = 1; k <= t->started; k++)
            pthread_join(t->threads[k], NULL);
    }
    free(t->threads);
    free(t->args);
    free(t);
}

#endif
