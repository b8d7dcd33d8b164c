#ifndef PYGRAN_ARRAYS_H
#define PYGRAN_ARRAYS_H

/* The solver's growable arrays (particles, lists, contacts...): pg_grow and pg_release. An
   array from 1 MiB on is a memory mapping of its own, grown in place or moved by mremap
   without a copy, and given back to the system when released. Left to malloc, such arrays
   come from the heap the Python side's temporaries (numpy's) share once glibc has raised its
   mapping threshold: the holes they leave between the solver's arrays stay resident (about
   90 bytes per particle at 10^6 particles, measured). Each block starts with PG_HEADER bytes
   holding its size and whether it is a mapping; the array after them keeps malloc's
   alignment (64 bytes in a mapping). */
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#define PG_HEADER 64
#define PG_MAPPED ((size_t)1 << 20)

static void pg_release(void* p)
{
    if (!p)
        return;
    char* base = (char*)p - PG_HEADER;
    size_t size = ((size_t*)base)[0];
    if (((size_t*)base)[1])
        munmap(base, size);
    else
        free(base);
}

/* p (NULL, or from pg_grow) grown or shrunk to nbytes, its contents kept up to the smaller
   size; NULL when out of memory (p is kept then). */
static void* pg_grow(void* p, size_t nbytes)
{
    size_t want = nbytes + PG_HEADER, old = 0;
    int mapped = want >= PG_MAPPED, was_mapped = 0;
    char* base = p ? (char*)p - PG_HEADER : NULL;
    char* q;
    if (p) {
        old = ((size_t*)base)[0];
        was_mapped = (int)((size_t*)base)[1];
    }
    if (p && mapped && was_mapped) {
        q = (char*)mremap(base, old, want, MREMAP_MAYMOVE);
        if (q == (char*)MAP_FAILED)
            return NULL;
    } else if (p && !mapped && !was_mapped) {
        q = (char*)realloc(base, want);
        if (!q)
            return NULL;
    } else {
        if (mapped) {
            q = (char*)mmap(NULL, want, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
            if (q == (char*)MAP_FAILED)
                return NULL;
        } else {
            q = (char*)malloc(want);
            if (!q)
                return NULL;
        }
        if (p) {
            memcpy(q + PG_HEADER, p, (old < want ? old : want) - PG_HEADER);
            pg_release(p);
        }
    }
    ((size_t*)q)[0] = want;
    ((size_t*)q)[1] = (size_t)mapped;
    return q + PG_HEADER;
}

#endif
