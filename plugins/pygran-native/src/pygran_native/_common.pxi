# Small helpers: 3-vectors, memory, CPU clock.

cdef inline double thread_cpu() noexcept nogil:
    """CPU seconds of the calling thread (not counting time it was descheduled or waiting)."""
    cdef timespec ts
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts)
    return ts.tv_sec + 1e-9 * ts.tv_nsec


cdef inline double dot3(const double* a, const double* b) noexcept nogil:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


cdef inline void cross3(const double* a, const double* b, double* c) noexcept nogil:
    c[0] = a[1] * b[2] - a[2] * b[1]
    c[1] = a[2] * b[0] - a[0] * b[2]
    c[2] = a[0] * b[1] - a[1] * b[0]


cdef extern from "arrays.h":
    # the solver's growable arrays (see arrays.h): a pointer from grow (or NULL) grown to
    # ``nbytes``, the old block kept on failure (NULL then); release frees one
    void* grow "pg_grow"(void* p, size_t nbytes) noexcept nogil
    void release "pg_release"(void* p) noexcept nogil
