# Wall elements: closest points and gaps of planes, cylinders and triangles.


cdef inline int closest_on_triangle(const double* p, const double* A, const double* B, const double* C,
                                    double* q, int* feature) noexcept nogil:
    """Closest point q on triangle ABC to p; returns FACE/EDGE/VERTEX and the feature index.

    Feature: for VERTEX 0/1/2 = A/B/C; for EDGE 0/1/2 = AB/BC/CA (Voronoi regions).
    """
    cdef double d1, d2, d3, d4, d5, d6, va, vb, vc, den, vv, ww
    cdef double ab[3]
    cdef double ac[3]
    cdef double ap[3]
    cdef double bp[3]
    cdef double cp[3]
    cdef int k
    for k in range(3):
        ab[k] = B[k] - A[k]
        ac[k] = C[k] - A[k]
        ap[k] = p[k] - A[k]
    d1 = dot3(ab, ap)
    d2 = dot3(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        memcpy(q, A, 3 * sizeof(double))
        feature[0] = 0
        return VERTEX
    for k in range(3):
        bp[k] = p[k] - B[k]
    d3 = dot3(ab, bp)
    d4 = dot3(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        memcpy(q, B, 3 * sizeof(double))
        feature[0] = 1
        return VERTEX
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        vv = d1 / (d1 - d3)
        for k in range(3):
            q[k] = A[k] + vv * ab[k]
        feature[0] = 0
        return EDGE
    for k in range(3):
        cp[k] = p[k] - C[k]
    d5 = dot3(ab, cp)
    d6 = dot3(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        memcpy(q, C, 3 * sizeof(double))
        feature[0] = 2
        return VERTEX
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        ww = d2 / (d2 - d6)
        for k in range(3):
            q[k] = A[k] + ww * ac[k]
        feature[0] = 2
        return EDGE
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        ww = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        for k in range(3):
            q[k] = B[k] + ww * (C[k] - B[k])
        feature[0] = 1
        return EDGE
    den = 1.0 / (va + vb + vc)
    vv = vb * den
    ww = vc * den
    for k in range(3):
        q[k] = A[k] + ab[k] * vv + ac[k] * ww
    feature[0] = 0
    return FACE


cdef inline double primitive_gap(int kind, const double* g, const double* p, double* nrm) noexcept nogil:
    """Distance from p to a plane or cylinder surface and the unit normal: negative behind
    a cylinder's surface; for a plane, negative on the side its normal points away from."""
    cdef double d, rho, u0, u1
    cdef int ax, a0, a1
    if kind == PLANE:
        d = (p[0] - g[0]) * g[3] + (p[1] - g[1]) * g[4] + (p[2] - g[2]) * g[5]
        nrm[0] = g[3]
        nrm[1] = g[4]
        nrm[2] = g[5]
        return d
    ax = <int>g[0]
    a0 = (ax + 1) % 3
    a1 = (ax + 2) % 3
    u0 = p[a0] - g[1]
    u1 = p[a1] - g[2]
    rho = sqrt(u0 * u0 + u1 * u1)
    nrm[ax] = 0.0
    if rho > 0.0:
        nrm[a0] = u0 / rho
        nrm[a1] = u1 / rho
    else:
        nrm[a0] = 1.0
        nrm[a1] = 0.0
    if g[4] != 0.0:   # inside
        nrm[a0] = -nrm[a0]
        nrm[a1] = -nrm[a1]
        return g[3] - rho
    return rho - g[3]


cdef inline bint has_vertex(const int* vid, int u) noexcept nogil:
    return vid[0] == u or vid[1] == u or vid[2] == u


cdef inline bint coplanar(const double* g, const double* f, const double* q, double tol) noexcept nogil:
    """Whether triangle g lies in the plane of triangle f and point q on it (to ``tol``)."""
    cdef double a[3]
    cdef double b[3]
    cdef double ng[3]
    cdef double nf[3]
    cdef int k
    for k in range(3):
        a[k] = g[3 + k] - g[k]
        b[k] = g[6 + k] - g[k]
    cross3(a, b, ng)
    for k in range(3):
        a[k] = f[3 + k] - f[k]
        b[k] = f[6 + k] - f[k]
    cross3(a, b, nf)
    for k in range(3):
        a[k] = q[k] - f[k]
    return fabs(dot3(ng, nf)) >= (1.0 - 1e-12) * sqrt(dot3(ng, ng) * dot3(nf, nf)) \
        and fabs(dot3(a, nf)) <= tol * sqrt(dot3(nf, nf))
