/* Shortest distances in a simple temporal network's distance graph, for the compiler's inner loops.

   An edge src --w--> dst stands for T(dst) - T(src) <= w (Dechter, Meiri & Pearl 1991). Two functions:

   - hrc_stn_distances: single-target shortest distances d(x, z) by queue-based Bellman-Ford (the
     earliest time of x after z is -d(x, z)); with z < 0, distances to a virtual node that every node
     reaches by an edge of weight 0 (the same numbers as single-target to z when every node has an edge
     of weight 0 to z; on any network, its consistency). A shortest walk of more edges than there are
     nodes means a negative cycle: the network is inconsistent.
   - hrc_stn_apsp: all-pairs shortest distances by Floyd-Warshall, dense, in float64 (integers below
     2**53 are exact, so the result is exact and does not depend on the order of the updates).

   The Python callers (hrc.compile.classify, hrc.compile.motion_pattern) keep their own implementations
   (and scipy's floyd_warshall) as the reference and the fallback when this library is not built; tests
   compare them. No Python headers: loaded with ctypes. */

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define DIST_INF INT64_MAX

/* 1 if every edge's ends (and z, unless negative) are timepoints 0..n-1: an index outside would read and
   write outside the arrays, so both functions refuse it (-2) before touching anything. */
static int indices_valid(int n, int m, const int *src, const int *dst, int z) {
    if (n <= 0 || m < 0 || z >= n) return 0;
    for (int e = 0; e < m; e++)
        if (src[e] < 0 || src[e] >= n || dst[e] < 0 || dst[e] >= n) return 0;
    return 1;
}

/* Returns 0 (out: the distances, DIST_INF where z is not reached), 1 (a negative cycle), -1 (memory) or
   -2 (an index out of range). Weights must be small enough that no sum of n of them overflows (the
   caller checks). */
int hrc_stn_distances(int n, int m, const int *src, const int *dst, const int64_t *wt, int z, int64_t *out) {
    if (!indices_valid(n, m, src, dst, z)) return -2;
    /* the edges by target (u -> v of weight w is read when v improves) */
    int *start = calloc((size_t)n + 1, sizeof(int));
    int *from = malloc(((size_t)m + 1) * sizeof(int));
    int64_t *w = malloc(((size_t)m + 1) * sizeof(int64_t));
    int *queue = malloc(((size_t)n + 1) * sizeof(int));
    int *hops = malloc(((size_t)n + 1) * sizeof(int));
    unsigned char *queued = calloc((size_t)n + 1, 1);
    int rc = 0;
    if (!start || !from || !w || !queue || !hops || !queued) { rc = -1; goto done; }
    for (int e = 0; e < m; e++) start[dst[e] + 1]++;
    for (int v = 0; v < n; v++) start[v + 1] += start[v];
    {
        int *fill = malloc(((size_t)n + 1) * sizeof(int));
        if (!fill) { rc = -1; goto done; }
        memcpy(fill, start, (size_t)n * sizeof(int));
        for (int e = 0; e < m; e++) {
            int p = fill[dst[e]]++;
            from[p] = src[e];
            w[p] = wt[e];
        }
        free(fill);
    }
    /* a ring buffer of at most n queued nodes */
    int head = 0, count = 0, limit;
    if (z >= 0) {
        for (int v = 0; v < n; v++) out[v] = DIST_INF;
        out[z] = 0;
        hops[z] = 0;
        queue[0] = z; queued[z] = 1; count = 1;
        limit = n;
    } else {
        for (int v = 0; v < n; v++) { out[v] = 0; hops[v] = 1; queue[v] = v; queued[v] = 1; }
        count = n;
        limit = n + 1;
    }
    while (count > 0) {
        int v = queue[head];
        head = (head + 1) % n;
        count--;
        queued[v] = 0;
        int64_t dv = out[v];
        int hv = hops[v] + 1;
        for (int p = start[v]; p < start[v + 1]; p++) {
            int u = from[p];
            int64_t cand = w[p] + dv;
            if (out[u] == DIST_INF || cand < out[u]) {
                out[u] = cand;
                hops[u] = hv;
                if (hv >= limit) { rc = 1; goto done; }
                if (!queued[u]) {
                    queued[u] = 1;
                    queue[(head + count) % n] = u;
                    count++;
                }
            }
        }
    }
done:
    free(start); free(from); free(w); free(queue); free(hops); free(queued);
    return rc;
}

/* Returns 0 (out: n x n distances, INFINITY where there is no path) or 1 (a negative cycle). Self-loops
   are the caller's to leave out (the distance of a node to itself starts at 0). */
int hrc_stn_apsp(int n, int m, const int *src, const int *dst, const int64_t *wt, double *out) {
    if (!indices_valid(n, m, src, dst, -1)) return -2;
    size_t nn = (size_t)n * n;
    for (size_t i = 0; i < nn; i++) out[i] = INFINITY;
    for (int i = 0; i < n; i++) out[(size_t)i * n + i] = 0.0;
    for (int e = 0; e < m; e++) {
        double v = (double)wt[e];
        double *cell = out + (size_t)src[e] * n + dst[e];
        if (v < *cell) *cell = v;
    }
    for (int k = 0; k < n; k++) {
        const double *rk = out + (size_t)k * n;
        for (int i = 0; i < n; i++) {
            double dik = out[(size_t)i * n + k];
            if (dik == INFINITY) continue;
            double *ri = out + (size_t)i * n;
            for (int j = 0; j < n; j++) {
                double v = dik + rk[j];
                if (v < ri[j]) ri[j] = v;
            }
        }
    }
    for (int i = 0; i < n; i++)
        if (out[(size_t)i * n + i] < 0) return 1;
    return 0;
}
