/* The depth-first search over passing orders of `hrc.compile.motion_pattern._search`, in C.

   The same search, step for step, as the Python one in that module (which stays, as the reference and
   the fallback when this library is not built): propagation at every node (orders the network already
   implies are forced, a conflict with one order left gets it, one at a time; a conflict with none left
   ends the branch), then a branch on the first open conflict, the order the earliest schedule is closer
   to first. Three all-pairs distance matrices ride along (the network with the task's limits, which
   prunes; without them, the human's durations free and at their upper bounds, which measure a leaf),
   each updated per added edge in O(n^2). A leaf's class comes from rul2021's C verdict
   (`hrc_rul_verdict`, `hrc/temporal/_rulcore.c`, linked into the same library) on the base network's
   index arrays plus the leaf's orders. Keys are compared in integer ticks, which orders them as the
   Python search's `pattern_key` does. Branch and bound as in Python: a node (after its edge is added)
   or a leaf whose bound is no better than the best key so far is cut, and not counted.

   Strassmair & Taylor 2014, section V.A (motion pattern); the search itself is documented in
   hrc/compile/motion_pattern.py. No Python headers: loaded with ctypes. */

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int hrc_rul_verdict(int n, int m, const int *src, const int *dst, const int64_t *w_lo, const int64_t *w_hi,
                    int k, const int *act, const int *ctg, const int64_t *x_lo, const int64_t *x_hi,
                    const int64_t *y_lo, const int64_t *y_hi);

#define KEY_INF INT64_MAX

typedef struct {
    int n, k, z;
    const int *earlier, *later;   /* k x 2 */
    const double *gap;            /* k x 2, ticks */
    const unsigned char *settled; /* k */
    int n_ends;
    const int *ends;
    /* the base network for the DC verdict, with room for k more edges at the end */
    int m;
    int *src, *dst;
    int64_t *wt;
    int nc;
    const int *act, *ctg;
    const int64_t *xs, *ys;
    int node_cap, leaf_cap, has_bound, rank_worst, prune;
    const int64_t *bound; /* 4 */
    int64_t best[4];      /* the best key so far (or the incumbent's): branch and bound */
    /* state, shared by both passes of the Python caller */
    int nodes, leaves, stop, exhaustive, failed;
    /* out */
    signed char *leaf_dec;    /* leaf_cap x k: order (0 robot first, 1 human first) or -1 (settled) */
    unsigned char *leaf_how;  /* leaf_cap x k: 1 forced, 2 chosen, 0 settled */
    int64_t *leaf_key;        /* leaf_cap x 4 */
    double *col, *row;        /* scratch, n each */
    int *rows, *cols;         /* scratch, n each */
} Search;

/* mat := min(mat, mat[:, lt] - g + mat[e, :]) (the Python update), on the rows and columns it can change.

   `mat` is a shortest-distance matrix without negative cycle (integer ticks, exact in doubles), so it
   keeps the triangle inequality d(i, j) <= d(i, x) + d(x, j). Row i cannot change when the new edge
   does not shorten its way to e, d(i, lt) - g >= d(i, e): every d(i, lt) - g + d(e, j) is then at least
   d(i, e) + d(e, j) >= d(i, j). Likewise column j when d(e, j) - g >= d(lt, j). So only the rows and
   columns that pass those tests are touched: the same matrix, operation for operation on the entries
   that change, and most of an n x n update skipped (an order usually moves a few timepoints). */
static void add_edge(Search *s, double *mat, int e, int lt, double g) {
    int n = s->n, ni = 0, nj = 0;
    const double *re = mat + (size_t)e * n, *rl = mat + (size_t)lt * n;
    for (int i = 0; i < n; i++) {
        double ci = mat[(size_t)i * n + lt] - g;
        if (ci < mat[(size_t)i * n + e]) { s->rows[ni] = i; s->col[ni++] = ci; }
    }
    if (ni == 0) return;
    for (int j = 0; j < n; j++)
        if (re[j] - g < rl[j]) { s->cols[nj] = j; s->row[nj++] = re[j]; }
    for (int a = 0; a < ni; a++) {
        double ci = s->col[a];
        double *r = mat + (size_t)s->rows[a] * n;
        for (int b = 0; b < nj; b++) {
            double v = ci + s->row[b];
            int j = s->cols[b];
            if (v < r[j]) r[j] = v;
        }
    }
}

/* the three matrices of a node: [0] with limits, [1] free reading, [2] upper-bound reading; alive[1..2]
   is 0 once that reading has a negative cycle */
static void add(Search *s, double *mats, int *alive, int j, int o) {
    size_t nn = (size_t)s->n * s->n;
    int e = s->earlier[2 * j + o], lt = s->later[2 * j + o];
    double g = s->gap[2 * j + o];
    add_edge(s, mats, e, lt, g);
    for (int r = 1; r < 3; r++) {
        if (!alive[r]) continue;
        double *f = mats + r * nn;
        if (f[(size_t)e * s->n + lt] - g < 0) { alive[r] = 0; continue; }
        add_edge(s, f, e, lt, g);
    }
}

static int64_t span(Search *s, const double *f) {
    if (s->n_ends == 0) return 0;
    double best = 0;
    for (int i = 0; i < s->n_ends; i++) {
        double v = -f[(size_t)s->ends[i] * s->n + s->z];
        if (i == 0 || v > best) best = v;
    }
    return (int64_t)best;
}

static int key_less(const int64_t *a, const int64_t *b) {
    for (int i = 0; i < 4; i++)
        if (a[i] != b[i]) return a[i] < b[i];
    return 0;
}

/* `_node_bound`: a key no leaf below this node beats; 1 if it is no better than the best so far */
static int cut(Search *s, const double *mats, const int *alive) {
    if (!s->prune) return 0;
    size_t nn = (size_t)s->n * s->n;
    int64_t lb[4];
    if (!alive[1]) {
        lb[0] = 0; lb[1] = lb[2] = lb[3] = KEY_INF;
    } else {
        int64_t early = span(s, mats + nn);
        if (!alive[2]) {
            lb[0] = 1; lb[1] = lb[2] = lb[3] = early;
        } else {
            int64_t late = span(s, mats + 2 * nn);
            lb[0] = 0; lb[1] = s->rank_worst ? late : early; lb[2] = late; lb[3] = early;
        }
    }
    return !key_less(lb, s->best);
}

static void leaf(Search *s, const double *mats, const int *alive, const signed char *dec, const unsigned char *how) {
    size_t nn = (size_t)s->n * s->n;
    if (cut(s, mats, alive)) return;
    int slot = s->leaves++;
    int m = s->m;
    for (int j = 0; j < s->k; j++) {
        if (dec[j] < 0) continue;
        int o = dec[j];
        s->src[m] = s->later[2 * j + o];
        s->dst[m] = s->earlier[2 * j + o];
        s->wt[m] = -(int64_t)s->gap[2 * j + o];
        m++;
    }
    int verdict = hrc_rul_verdict(s->n, m, s->src, s->dst, s->wt, NULL, s->nc, s->act, s->ctg, s->xs, NULL, s->ys, NULL);
    if (verdict < 0) { s->failed = 1; s->stop = 1; return; }
    int64_t *key = s->leaf_key + 4 * slot;
    key[0] = verdict; /* 0 DC, 1 not DC (consistent), 2 inconsistent: the classes' order */
    if (!alive[1]) {
        key[1] = key[2] = key[3] = KEY_INF;
    } else {
        int64_t early = span(s, mats + nn);
        int64_t late = alive[2] ? span(s, mats + 2 * nn) : early;
        key[1] = s->rank_worst ? late : early;
        key[2] = late;
        key[3] = early;
    }
    if (key_less(key, s->best)) memcpy(s->best, key, sizeof s->best);
    memcpy(s->leaf_dec + (size_t)slot * s->k, dec, (size_t)s->k);
    memcpy(s->leaf_how + (size_t)slot * s->k, how, (size_t)s->k);
    if (s->has_bound) {
        int le = 1;
        for (int i = 0; i < 4; i++) {
            if (key[i] != s->bound[i]) { le = key[i] < s->bound[i]; break; }
        }
        if (le) s->stop = 1; /* nothing can beat the network without passing orders */
    }
}

/* `parent` (3 matrices) plus order o at conflict j (or nothing, j < 0), into a node of its own; with
   `take` the node works in `parent` itself (the parent's last child: the parent reads its matrices no
   more), else in a copy */
static void dfs(Search *s, double *parent, const int *parent_alive, const signed char *parent_dec,
                const unsigned char *parent_how, int j0, int o0, int take) {
    if (s->stop) return;
    if (s->nodes >= s->node_cap || s->leaves >= s->leaf_cap) { s->exhaustive = 0; return; }
    int n = s->n, k = s->k;
    size_t nn = (size_t)n * n;
    double *mats = take ? parent : malloc(3 * nn * sizeof(double));
    signed char *dec = malloc((size_t)k + 1);
    unsigned char *how = malloc((size_t)k + 1);
    int *open = malloc(((size_t)k + 1) * sizeof(int));
    unsigned char *held = malloc((size_t)k + 1), *h0 = malloc((size_t)k + 1);
    unsigned char *nfit = malloc((size_t)k + 1), *f0 = malloc((size_t)k + 1);
    if (!mats || !dec || !how || !open || !held || !h0 || !nfit || !f0) { s->failed = 1; s->stop = 1; goto done; }
    if (!take) memcpy(mats, parent, 3 * nn * sizeof(double));
    int alive[3] = {1, parent_alive[1], parent_alive[2]};
    memcpy(dec, parent_dec, (size_t)k);
    memcpy(how, parent_how, (size_t)k);
    if (j0 >= 0) {
        add(s, mats, alive, j0, o0);
        dec[j0] = (signed char)o0;
        how[j0] = 2;
    }
    if (cut(s, mats, alive)) goto done; /* not counted towards the node cap, as in Python */
    s->nodes++;
    int branch = -1;
    for (;;) {
        int n_open = 0;
        for (int j = 0; j < k; j++)
            if (!s->settled[j] && dec[j] < 0) open[n_open++] = j;
        if (n_open == 0) {
            leaf(s, mats, alive, dec, how);
            goto done;
        }
        for (int p = 0; p < n_open; p++) {
            int j = open[p];
            int hold0 = 0, hold1 = 0, fit0 = 0, fit1 = 0;
            for (int o = 0; o < 2; o++) {
                int e = s->earlier[2 * j + o], lt = s->later[2 * j + o];
                double g = s->gap[2 * j + o];
                int h = mats[(size_t)lt * n + e] <= -g;   /* already implied by what is decided */
                int f = mats[(size_t)e * n + lt] - g >= 0; /* adding it closes no negative cycle */
                if (o == 0) { hold0 = h; fit0 = f; } else { hold1 = h; fit1 = f; }
            }
            held[p] = (unsigned char)(hold0 || hold1);
            h0[p] = (unsigned char)hold0;
            nfit[p] = (unsigned char)(fit0 + fit1);
            f0[p] = (unsigned char)fit0;
        }
        for (int p = 0; p < n_open; p++)
            if (!held[p] && nfit[p] == 0) goto done; /* they would block each other: dead end */
        for (int p = 0; p < n_open; p++)
            if (held[p]) { dec[open[p]] = (signed char)(h0[p] ? 0 : 1); how[open[p]] = 1; }
        int unit = -1;
        for (int p = 0; p < n_open; p++)
            if (!held[p] && nfit[p] == 1) { unit = p; break; }
        if (unit >= 0) { /* one at a time: each edge may settle or forbid others */
            int j = open[unit], o = f0[unit] ? 0 : 1;
            add(s, mats, alive, j, o);
            dec[j] = (signed char)o;
            how[j] = 1;
            continue;
        }
        for (int p = 0; p < n_open; p++)
            if (!held[p]) { branch = open[p]; break; }
        if (branch >= 0) break;
    }
    {
        int j = branch;
        double slack[2];
        for (int o = 0; o < 2; o++) {
            double el = -mats[(size_t)s->later[2 * j + o] * n + s->z];
            double ee = -mats[(size_t)s->earlier[2 * j + o] * n + s->z];
            slack[o] = el - ee - s->gap[2 * j + o];
        }
        int first = (-slack[1] < -slack[0]) ? 1 : 0; /* Python's stable sort on -slack */
        for (int t = 0; t < 2; t++) {
            dfs(s, mats, alive, dec, how, j, t == 0 ? first : 1 - first, t == 1);
            if (s->stop) break;
        }
    }
done:
    if (!take) free(mats);
    free(dec); free(how); free(open); free(held); free(h0); free(nfit); free(f0);
}

/* One pass of the search from `start` (3 n x n matrices; alive[1], alive[2] say whether the free and
   upper-bound readings have a schedule at all). `state` (in/out): nodes, leaves, stop, exhaustive.
   Returns 0, or -1 when memory or the verdict failed (the caller then runs the Python search). */
int hrc_pattern_search(int n, int k, int z, const double *start, const int *start_alive,
                       const int *earlier, const int *later, const double *gap, const unsigned char *settled,
                       int n_ends, const int *ends,
                       int m, const int *src, const int *dst, const int64_t *wt,
                       int nc, const int *act, const int *ctg, const int64_t *xs, const int64_t *ys,
                       int node_cap, int leaf_cap, int has_bound, const int64_t *bound, int rank_worst,
                       int prune, const int64_t *best, int *state, signed char *leaf_dec, unsigned char *leaf_how, int64_t *leaf_key) {
    Search s;
    memset(&s, 0, sizeof s);
    s.n = n; s.k = k; s.z = z;
    s.earlier = earlier; s.later = later; s.gap = gap; s.settled = settled;
    s.n_ends = n_ends; s.ends = ends;
    s.m = m; s.nc = nc; s.act = act; s.ctg = ctg; s.xs = xs; s.ys = ys;
    s.node_cap = node_cap; s.leaf_cap = leaf_cap; s.has_bound = has_bound; s.bound = bound;
    s.rank_worst = rank_worst;
    s.prune = prune;
    memcpy(s.best, best, sizeof s.best);
    s.nodes = state[0]; s.leaves = state[1]; s.stop = state[2]; s.exhaustive = state[3];
    s.leaf_dec = leaf_dec; s.leaf_how = leaf_how; s.leaf_key = leaf_key;
    s.src = malloc(((size_t)m + k + 1) * sizeof(int));
    s.dst = malloc(((size_t)m + k + 1) * sizeof(int));
    s.wt = malloc(((size_t)m + k + 1) * sizeof(int64_t));
    s.col = malloc(((size_t)n + 1) * sizeof(double));
    s.row = malloc(((size_t)n + 1) * sizeof(double));
    s.rows = malloc(((size_t)n + 1) * sizeof(int));
    s.cols = malloc(((size_t)n + 1) * sizeof(int));
    signed char *dec = malloc((size_t)k + 1);
    unsigned char *how = calloc((size_t)k + 1, 1);
    int rc = 0;
    if (!s.src || !s.dst || !s.wt || !s.col || !s.row || !s.rows || !s.cols || !dec || !how) {
        rc = -1;
    } else {
        memcpy(s.src, src, (size_t)m * sizeof(int));
        memcpy(s.dst, dst, (size_t)m * sizeof(int));
        memcpy(s.wt, wt, (size_t)m * sizeof(int64_t));
        memset(dec, -1, (size_t)k + 1);
        int alive[3] = {1, start_alive[0], start_alive[1]};
        dfs(&s, (double *)start, alive, dec, how, -1, 0, 0); /* copied: `start` is the caller's */
        if (s.failed) rc = -1;
    }
    state[0] = s.nodes; state[1] = s.leaves; state[2] = s.stop; state[3] = s.exhaustive;
    free(s.src); free(s.dst); free(s.wt); free(s.col); free(s.row); free(s.rows); free(s.cols); free(dec); free(how);
    return rc;
}
