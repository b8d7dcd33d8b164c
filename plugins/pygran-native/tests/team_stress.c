/* Stress test of team.h: `team_stress THREADS PHASES SEED` opens PHASES phases of two stages
   with random numbers of blocks on a team of THREADS threads (the caller one of them); blocks
   wait at random (spins, yields, short sleeps), first-stage blocks write a value and post
   their flag, and each second-stage block awaits two of them and checks their values. After
   each phase the master checks that every block ran once, in this phase. Prints the phases,
   blocks and errors; exits 1 on any error. Built by test_team.py, also under ThreadSanitizer. */
#include "team.h"

#define MAX_STAGE 16

typedef struct {
    pg_team* team;
    pg_flag* posted;
    int nfirst, nsecond;   /* the phase's blocks: written by the master before pg_begin */
    int phase;             /* the phase's number, from 1 */
    uint32_t seed;
    int ran[2 * MAX_STAGE];          /* per block: the phase that ran it (plain writes) */
    long long value[MAX_STAGE];      /* per first-stage block: its output */
    int errors;                      /* atomic */
} stress;

static uint32_t mix(uint32_t x) {   /* a hash (lowbias32) for the random choices */
    x ^= x >> 16;
    x *= 0x7feb352dU;
    x ^= x >> 15;
    x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}

static void delay(uint32_t r) {
    struct timespec ts = {0, 20000};
    unsigned k;
    if (r % 4 == 0)
        for (k = 0; k < (r >> 8) % 256; k++)
            pg_relax();
    else if (r % 509 == 1)
        sched_yield();
    else if (r % 4099 == 2)
        nanosleep(&ts, NULL);
}

static void run_block(stress* s, uint32_t epoch, int b) {
    uint32_t r = mix(s->seed ^ mix((uint32_t)s->phase * 131u + (uint32_t)b));
    int d0, d1;
    delay(r);
    if (b < s->nfirst) {
        s->value[b] = (long long)s->phase * 1000 + b;
        s->ran[b] = s->phase;
        pg_post(&s->posted[b], epoch);
        return;
    }
    d0 = (int)(mix(r) % (uint32_t)s->nfirst);
    d1 = (b - s->nfirst) % s->nfirst;
    pg_await(&s->posted[d0], epoch);
    pg_await(&s->posted[d1], epoch);
    if (s->value[d0] != (long long)s->phase * 1000 + d0 || s->value[d1] != (long long)s->phase * 1000 + d1)
        __atomic_add_fetch(&s->errors, 1, __ATOMIC_RELAXED);
    s->ran[b] = s->phase;
}

static void task(void* owner, uint32_t epoch, int phase, int nblocks, int tid) {
    stress* s = (stress*)owner;
    int b, k = 0;
    (void)phase;
    (void)nblocks;
    while ((b = pg_claim(s->team, epoch, tid)) >= 0) {
        run_block(s, epoch, b);
        k++;
    }
    pg_finished(s->team, k);
}

int main(int argc, char** argv) {
    static stress s;
    long long blocks = 0;
    int nthreads, phases, p, b, missed = 0;
    uint32_t epoch;
    if (argc != 4)
        return 2;
    nthreads = atoi(argv[1]);
    phases = atoi(argv[2]);
    s.seed = (uint32_t)atoi(argv[3]);
    s.team = pg_create(nthreads);
    s.posted = pg_flags(MAX_STAGE);
    if (!s.team || !s.posted || pg_start(s.team, task, &s) != nthreads - 1)
        return 2;
    for (p = 1; p <= phases; p++) {
        s.phase = p;
        s.nfirst = 1 + (int)(mix(s.seed + 2u * p) % MAX_STAGE);
        s.nsecond = (int)(mix(s.seed + 2u * p + 1) % (MAX_STAGE + 1));
        epoch = pg_begin(s.team, 1, s.nfirst, s.nsecond);
        task(&s, epoch, 1, s.nfirst + s.nsecond, 0);
        pg_wait_done(s.team);
        for (b = 0; b < s.nfirst + s.nsecond; b++)
            missed += s.ran[b] != p;
        blocks += s.nfirst + s.nsecond;
    }
    pg_destroy(s.team);
    free(s.posted);
    printf("%d phases, %lld blocks, %d missed, %d wrong values\n", phases, blocks, missed, s.errors);
    return missed || s.errors;
}
