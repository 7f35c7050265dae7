/*
 * The dispatcher's set ranking in C (loaded with ctypes by hrc.dispatch.native; no Python headers):
 * each plan of a dispatch form (hrc/compile/dispatch_form.py) evaluated under what has been seen, as
 * hrc.dispatch.ranking.reference_evaluate defines it on the plan's residual network
 * (hrc.temporal.execution.residual_network), many plans per call:
 *
 *   - executed timepoints: the origin (0) at 0; each seen event of the agents' legs at its tick; an
 *     unseen earlier event of a seen leg at the tick of the next seen one (hrc.dispatch.validation.executed);
 *   - class: the residual's DC verdict (the RUL2021 core of hrc/temporal/_rulcore.c, through its reusable
 *     workspace): its distance edges are the plan's edges but those between two executed timepoints,
 *     a pin for each executed timepoint, "at now or later" for every other executable, and its contingent
 *     links but those observed, one in progress shortened by what it has lasted (past its upper bound an
 *     overrun: [e, e]); a blocked plan is inconsistent whatever the verdict. Most residuals are decided
 *     without the RUL check, by two longest-path computations that give the same verdict:
 *       1. strongly controllable (one schedule of the executables meets every constraint whatever the
 *          durations still to come: Vidal & Fargier 1999, substituting each unobserved contingent
 *          timepoint C of link A --[l, u]--> C by T(A) + [l, u], so T(Y) - T(C) <= w becomes
 *          T(Y) - T(A) <= w + l and T(C) - T(X) <= w becomes T(A) - T(X) <= w - u): then DC, since
 *          that schedule is a dynamic strategy that never reads an observation (strongly);
 *       2. else, no schedule at all with each duration still to come anywhere in its range now (the STN
 *          of the residual, its links as requirements, inconsistent): then "inconsistent", which is the
 *          RUL check's own second test after its first fails, and the first (a schedule at the lower
 *          bounds) does fail then (ranges_consistent);
 *     only the rest (consistent, not strongly controllable: not DC, or DC by reacting to observations)
 *     takes the RUL check. In the runs of kitting and the two-robot teams most plans are settled by 1
 *     or 2, and no residual seen was DC without being strongly controllable;
 *   - finish: the end of the earliest schedule with each unrevealed duration fixed as rank_by reads it
 *     (0 worst: upper bound, 1 earliest: lower bound, 2 nominal: midpoint, floored), a longest-path
 *     computation (Bellman-Ford swept in the plan's topological numbering: one or two sweeps); when no
 *     schedule keeps every bound, the same on the orderings and lower bounds still to come alone;
 *   - idle: per agent, the time from the start to its last end that it neither travels (a stop at a
 *     waiting place counts as idle) nor works, summed.
 *
 * Returns, per plan, class 0 DC, 1 consistent, 2 inconsistent (or -1: out of memory, the caller falls
 * back), finish in ticks (INT64_MIN: no schedule at all) and idle ticks. A workspace (hrc_dispatch_work_new)
 * belongs to one thread at a time; the form and the state are only read.
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../temporal/_rulcore.h"

#define NONE INT64_MIN
#define EVENTS 6 /* depart, park, unpark, arrive, start, end */

typedef struct {
    int32_t plans, agents, legs;
    const uint16_t *n;          /* timepoints of each plan */
    const uint8_t *blocked;     /* 1: no motion pattern, never promised */
    const int16_t *nodes;       /* plans x agents x legs x EVENTS: a leg's timepoints, -1 none */
    const int64_t *edges_ptr;   /* plans + 1 */
    const uint16_t *eu, *ev;    /* T(v) - T(u) <= w */
    const int32_t *ew32;        /* the weights: one of these two is set */
    const int64_t *ew64;
    const int64_t *conts_ptr;   /* plans + 1 */
    const uint16_t *ca, *cc;    /* a --[lb, ub]--> c */
    const int32_t *clb32, *cub32;
    const int64_t *clb64, *cub64;
} HrcForm;

typedef struct {
    const int64_t *seen;       /* agents x legs x EVENTS: the tick of agent g's k-th leg's event, -1 unseen */
    const int32_t *legs_seen;  /* agents: how many of each agent's legs were seen (its first ones) */
    int64_t now;
    int32_t rank_by;           /* 0 worst, 1 earliest, 2 nominal */
} HrcState;

typedef struct {
    HrcRul *rul;
    int ncap, mcap;
    int64_t *ex, *t, *pot, *pot2, now;
    int *map, *unmap, nn;           /* executed timepoints folded into the origin: map[x], and back */
    uint8_t *contingent;
    int *first, *next_src;          /* longest-path edges by source: counting sort */
    int *lu, *lv, *order;
    int64_t *len;
    int64_t *lb, *ub, *fixed;       /* per contingent link: its range now, its fixed duration */
    int *root;                      /* strongly: a timepoint's controllable root (itself, or its link's activation) */
    int64_t *dlo, *dhi;             /* strongly: the range of T(x) - T(root[x]) (0, 0 for a root) */
    int64_t *fx, *t2, *len2;        /* strongly: T(x) - T(root[x]) as rank_by fixes it; the strict schedule */
    int strict;                     /* strongly found the strict schedule (into t) */
} HrcWork;

HrcWork *hrc_dispatch_work_new(void) {
    HrcWork *w = calloc(1, sizeof *w);
    if (w && !(w->rul = hrc_rul_new())) { free(w); return NULL; }
    return w;
}

void hrc_dispatch_work_free(HrcWork *w) {
    if (!w) return;
    hrc_rul_free(w->rul);
    free(w->ex); free(w->t); free(w->pot); free(w->pot2); free(w->map); free(w->unmap); free(w->contingent);
    free(w->first); free(w->next_src); free(w->lu); free(w->lv);
    free(w->order); free(w->len); free(w->lb); free(w->ub); free(w->fixed);
    free(w->root); free(w->dlo); free(w->dhi); free(w->fx); free(w->t2); free(w->len2);
    free(w);
}

static int reserve(HrcWork *w, int n, int m) {
    if (n > w->ncap) {
        free(w->ex); free(w->t); free(w->pot); free(w->pot2); free(w->map); free(w->unmap); free(w->contingent);
        free(w->first); free(w->root); free(w->dlo); free(w->dhi); free(w->fx); free(w->t2);
        w->root = malloc(sizeof(int) * (size_t)n);
        w->fx = malloc(sizeof(int64_t) * (size_t)n); w->t2 = malloc(sizeof(int64_t) * (size_t)n);
        w->dlo = malloc(sizeof(int64_t) * (size_t)n); w->dhi = malloc(sizeof(int64_t) * (size_t)n);
        w->ex = malloc(sizeof(int64_t) * (size_t)n); w->t = malloc(sizeof(int64_t) * (size_t)n);
        w->pot = malloc(sizeof(int64_t) * (size_t)n); w->pot2 = malloc(sizeof(int64_t) * (size_t)n);
        w->map = malloc(sizeof(int) * (size_t)n); w->unmap = malloc(sizeof(int) * (size_t)n);
        w->contingent = malloc((size_t)n); w->first = malloc(sizeof(int) * (size_t)(n + 1));
        if (!w->ex || !w->t || !w->pot || !w->pot2 || !w->map || !w->unmap || !w->contingent || !w->first ||
            !w->root || !w->dlo || !w->dhi || !w->fx || !w->t2) {
            w->ncap = 0;
            return -1;
        }
        w->ncap = n;
    }
    if (m > w->mcap) {
        free(w->next_src); free(w->lu); free(w->lv); free(w->order); free(w->len); free(w->lb); free(w->ub);
        free(w->fixed); free(w->len2);
        size_t c = (size_t)m;
        w->len2 = malloc(sizeof(int64_t) * c);
        w->next_src = malloc(sizeof(int) * c); w->lu = malloc(sizeof(int) * c); w->lv = malloc(sizeof(int) * c);
        w->order = malloc(sizeof(int) * c); w->len = malloc(sizeof(int64_t) * c);
        w->lb = malloc(sizeof(int64_t) * c); w->ub = malloc(sizeof(int64_t) * c); w->fixed = malloc(sizeof(int64_t) * c);
        if (!w->next_src || !w->lu || !w->lv || !w->order || !w->len || !w->lb || !w->ub || !w->fixed || !w->len2) {
            w->mcap = 0;
            return -1;
        }
        w->mcap = m;
    }
    return 0;
}

static int64_t max64(int64_t a, int64_t b) { return a > b ? a : b; }

static int64_t floor_half(int64_t x) { return x >= 0 ? x / 2 : -((-x + 1) / 2); }

static int64_t weight(const int32_t *w32, const int64_t *w64, int64_t i) { return w32 ? (int64_t)w32[i] : w64[i]; }

/* The nl edges as lists by their source (w->first, w->next_src), each list in index order. */
static void by_source(HrcWork *w, int n, int nl) {
    int *first = w->first, *nxt = w->next_src;
    for (int x = 0; x <= n; x++) first[x] = -1;
    for (int i = nl - 1; i >= 0; i--) { nxt[i] = first[w->lu[i]]; first[w->lu[i]] = i; }
}

/* Longest paths from the initial times in w->t over the nl edges in w->lu/lv/len, swept by source in
 * index order (the plan's topological numbering) until a sweep moves nothing along an edge that goes back
 * in that order. 0 done; 1 no schedule (an executed timepoint or the origin would have to move, or a
 * positive cycle: no end after n + 1 sweeps). */
static int longest(HrcWork *w, int n, int nl) {
    by_source(w, n, nl);
    int *first = w->first, *nxt = w->next_src;
    int64_t *t = w->t, *ex = w->ex;
    for (int sweep = 0; sweep <= n; sweep++) {
        int again = 0;
        for (int u = 0; u < n; u++) {
            int64_t tu = t[u];
            for (int i = first[u]; i >= 0; i = nxt[i]) {
                int v = w->lv[i];
                int64_t val = tu + w->len[i];
                if (val > t[v]) {
                    if (ex[v] != NONE || v == 0) return 1;
                    t[v] = val;
                    if (v <= u) again = 1;
                }
            }
        }
        if (!again) return 0;
    }
    return 1;
}

/* longest, on two sets of lengths over the same edges at once (w->len into w->t, w->len2 into w->t2):
 * 0 when the first is done, *second set to 0 when the second is done too, 1 when the second has no end
 * (a pinned timepoint would have to move); 1 when the first has no schedule (or the two need more than
 * n + 1 sweeps together). */
static int longest2(HrcWork *w, int n, int nl, int *second) {
    by_source(w, n, nl);
    int *first = w->first, *nxt = w->next_src;
    int64_t *t = w->t, *t2 = w->t2, *ex = w->ex;
    int ok2 = 1;
    for (int sweep = 0; sweep <= n; sweep++) {
        int again = 0;
        for (int u = 0; u < n; u++) {
            int64_t tu = t[u], tu2 = t2[u];
            for (int i = first[u]; i >= 0; i = nxt[i]) {
                int v = w->lv[i];
                int64_t val = tu + w->len[i];
                if (val > t[v]) {
                    if (ex[v] != NONE || v == 0) return 1;
                    t[v] = val;
                    if (v <= u) again = 1;
                }
                if (ok2 && (val = tu2 + w->len2[i]) > t2[v]) {
                    if (ex[v] != NONE || v == 0) ok2 = 0;
                    else { t2[v] = val; if (v <= u) again = 1; }
                }
            }
        }
        if (!again) { *second = ok2 ? 0 : 1; return 0; }
    }
    return 1;
}

/* longest, on two sets of lengths over the same edges, each on its own (w->len into w->t, w->len2 into
 * w->t2): *ok1, *ok2 set to 1 for each that is done, 0 for each with no schedule. */
static void longest_both(HrcWork *w, int n, int nl, int *ok1, int *ok2) {
    by_source(w, n, nl);
    int *first = w->first, *nxt = w->next_src;
    int64_t *t = w->t, *t2 = w->t2, *ex = w->ex;
    int live1 = 1, live2 = 1;
    *ok1 = 0; *ok2 = 0;
    for (int sweep = 0; sweep <= n && (live1 || live2); sweep++) {
        int again1 = 0, again2 = 0;
        for (int u = 0; u < n; u++) {
            int64_t tu = t[u], tu2 = t2[u];
            for (int i = first[u]; i >= 0; i = nxt[i]) {
                int v = w->lv[i];
                int64_t val;
                if (live1 && (val = tu + w->len[i]) > t[v]) {
                    if (ex[v] != NONE || v == 0) live1 = 0;
                    else { t[v] = val; if (v <= u) again1 = 1; }
                }
                if (live2 && (val = tu2 + w->len2[i]) > t2[v]) {
                    if (ex[v] != NONE || v == 0) live2 = 0;
                    else { t2[v] = val; if (v <= u) again2 = 1; }
                }
            }
        }
        if (live1 && !again1) { live1 = 0; *ok1 = 1; }
        if (live2 && !again2) { live2 = 0; *ok2 = 1; }
    }
}

/* The earliest schedule of plan p's residual into w->t, each contingent link's duration fixed at
 * durations[j]: strict (every constraint not yet history; a duration exactly), or not (only the orderings
 * and lower bounds into timepoints still to come). 0 found, 1 none. w->ex, w->contingent set. */
static int schedule(const HrcForm *f, HrcWork *w, int64_t p, int n, int strict, const int64_t *durations) {
    int64_t e0 = f->edges_ptr[p], e1 = f->edges_ptr[p + 1], c0 = f->conts_ptr[p], c1 = f->conts_ptr[p + 1];
    int k = (int)(c1 - c0), nl = 0;
    int64_t *ex = w->ex, *t = w->t;
    for (int64_t i = e0; i < e1; i++) {
        int u = f->eu[i], v = f->ev[i];  /* T(v) - T(u) <= w: T(u) >= T(v) - w */
        if (ex[u] != NONE && ex[v] != NONE) continue;
        int64_t len = -weight(f->ew32, f->ew64, i);
        if (v == 0 && len <= 0) continue;  /* T(u) >= -w <= 0: every time here is at 0 or later */
        if (!strict && (ex[u] != NONE || len < 0)) continue;
        w->lu[nl] = v; w->lv[nl] = u; w->len[nl] = len; nl++;
    }
    for (int j = 0; j < k; j++) {
        int a = f->ca[c0 + j], c = f->cc[c0 + j];
        if (ex[a] != NONE && ex[c] != NONE) continue;
        if (!strict && ex[c] != NONE) continue;
        w->lu[nl] = a; w->lv[nl] = c; w->len[nl] = durations[j]; nl++;
        if (strict) { w->lu[nl] = c; w->lv[nl] = a; w->len[nl] = -durations[j]; nl++; }
    }
    for (int x = 0; x < n; x++) t[x] = ex[x] != NONE ? ex[x] : w->contingent[x] ? 0 : w->now;
    t[0] = 0;
    return longest(w, n, nl);
}

/* Plan p's executed timepoints (w->ex) and contingent timepoints (w->contingent), each contingent link's
 * range now (w->lb, w->ub) and its duration as rank_by reads it (w->fixed); returns the number of
 * contingent links not yet observed, or -1 (out of memory, or an index out of range in the form). */
static int prepare(const HrcForm *f, const HrcState *s, int64_t p, HrcWork *w) {
    int n = f->n[p];
    int64_t e0 = f->edges_ptr[p], e1 = f->edges_ptr[p + 1], c0 = f->conts_ptr[p], c1 = f->conts_ptr[p + 1];
    int m = (int)(e1 - e0), k = (int)(c1 - c0);
    if (n < 1 || reserve(w, n, 2 * m + 2 * k + 1)) return -1;
    int64_t *ex = w->ex, now = s->now;
    w->now = now;
    for (int x = 0; x < n; x++) { ex[x] = NONE; w->contingent[x] = 0; }
    ex[0] = 0;
    int G = f->agents, L = f->legs;
    const int16_t *nodes = f->nodes + (int64_t)p * G * L * EVENTS;
    for (int g = 0; g < G; g++) {
        for (int leg = 0; leg < s->legs_seen[g] && leg < L; leg++) {
            const int16_t *nd = nodes + (g * L + leg) * EVENTS;
            const int64_t *tm = s->seen + (g * L + leg) * EVENTS;
            int pending[EVENTS], np = 0;
            for (int e = 0; e < EVENTS; e++) {
                int x = nd[e];
                if (x < 0 || x >= n) continue;
                if (tm[e] < 0) { pending[np++] = x; continue; }
                for (int i = 0; i < np; i++) ex[pending[i]] = tm[e];
                np = 0;
                ex[x] = tm[e];
            }
        }
    }
    for (int64_t i = e0; i < e1; i++) if (f->eu[i] >= n || f->ev[i] >= n) return -1;
    int active = 0;
    for (int j = 0; j < k; j++) {
        int a = f->ca[c0 + j], c = f->cc[c0 + j];
        if (a >= n || c >= n) return -1;
        w->contingent[c] = 1;
        int64_t lb = weight(f->clb32, f->clb64, c0 + j), ub = weight(f->cub32, f->cub64, c0 + j);
        if (ex[a] != NONE && ex[c] == NONE) {  /* in progress: it has lasted now - T(a) already */
            int64_t el = now - ex[a];
            lb = max64(lb, el);
            ub = max64(ub, el);
        }
        w->lb[j] = lb; w->ub[j] = ub;
        w->fixed[j] = s->rank_by == 1 ? lb : s->rank_by == 2 ? floor_half(lb + ub) : ub;
        if (ex[c] == NONE) active++;
    }
    /* the residual network folded: an executed timepoint is the origin, offset by its time (it is pinned
     * there), so only what is still to happen stays a node (fewer nodes for the checks as a run goes on) */
    w->nn = 1;
    w->unmap[0] = 0;
    for (int x = 0; x < n; x++) {
        if (ex[x] != NONE) { w->map[x] = 0; continue; }
        w->unmap[w->nn] = x;
        w->map[x] = w->nn++;
    }
    return active;
}

/* The folded residual's weight of plan edge u -> v (T(v) - T(u) <= wt), between folded nodes map[u] and
 * map[v]: an executed end is the origin at its time. */
static int64_t folded(const HrcWork *w, int u, int v, int64_t wt) {
    return wt + (w->ex[u] != NONE ? w->ex[u] : 0) - (w->ex[v] != NONE ? w->ex[v] : 0);
}

/* 1 when plan p's residual (w set by prepare) is strongly controllable (see the file's comment), 0 when
 * it is not or this test cannot tell (a chain: a link whose activation is itself a contingent timepoint
 * still to come). Each edge u -> v, T(v) - T(u) <= w, must hold for every duration: with T(x) = T(root x)
 * + d(x), d(x) in [dlo x, dhi x] (0 for a root) and the two durations independent (two links, or a root
 * and a link), the worst case is d(v) = dhi v, d(u) = dlo u: T(root v) - T(root u) <= w - dhi v + dlo u;
 * between one root and itself a condition on nature alone. The roots' earliest schedule (longest paths,
 * executed timepoints and the origin pinned, the rest at now or later) exists iff the residual is SC. */
static int strongly(const HrcForm *f, HrcWork *w, int64_t p, int n) {
    int64_t e0 = f->edges_ptr[p], e1 = f->edges_ptr[p + 1], c0 = f->conts_ptr[p], c1 = f->conts_ptr[p + 1];
    int k = (int)(c1 - c0), nl = 0, strict = 1;
    int64_t *ex = w->ex, *t = w->t, *fx = w->fx;
    int *root = w->root;
    w->strict = 0;
    for (int x = 0; x < n; x++) { root[x] = x; w->dlo[x] = 0; w->dhi[x] = 0; fx[x] = 0; }
    for (int j = 0; j < k; j++) {
        int a = f->ca[c0 + j], c = f->cc[c0 + j];
        if (ex[c] != NONE) {
            if (ex[a] == NONE) return 0;  /* (not in these plans) the strict schedule has this link: not here */
            continue;
        }
        root[c] = a; w->dlo[c] = w->lb[j]; w->dhi[c] = w->ub[j]; fx[c] = w->fixed[j];
    }
    for (int j = 0; j < k; j++) {
        int a = f->ca[c0 + j], c = f->cc[c0 + j];
        if (ex[c] == NONE && root[a] != a) return 0;  /* a chain */
    }
    for (int64_t i = e0; i < e1; i++) {
        int u = f->eu[i], v = f->ev[i];  /* T(v) - T(u) <= wt for every duration */
        if (ex[u] != NONE && ex[v] != NONE) continue;
        int64_t wt0 = weight(f->ew32, f->ew64, i);
        if (v == 0 && wt0 >= 0) continue;  /* (as in schedule) */
        int64_t wt = wt0 - w->dhi[v] + w->dlo[u], wf = wt0 - fx[v] + fx[u];
        int ru = root[u], rv = root[v];
        if (ru == rv) {
            if (wt < 0) return 0;
            if (wf < 0) strict = 0;
            continue;
        }
        w->lu[nl] = rv; w->lv[nl] = ru; w->len[nl] = -wt; w->len2[nl] = -wf; nl++;
    }
    for (int x = 0; x < n; x++) t[x] = ex[x] != NONE ? ex[x] : w->now;
    t[0] = 0;
    memcpy(w->t2, t, sizeof(int64_t) * (size_t)n);
    int second = 1;
    if (longest2(w, n, nl, &second)) return 0;
    if (strict && !second) {  /* the strict schedule on the roots, each contingent timepoint after its root */
        for (int x = 0; x < n; x++) t[x] = w->t2[root[x]] + fx[x];
        w->strict = 1;
    }
    return 1;
}

/* 1 when plan p's residual (w set by prepare) is consistent: a schedule keeps every requirement and puts
 * each contingent duration still to come somewhere in its range now; 0 when none does. In the same sweeps,
 * *loose: 1 when schedule(..., strict 0, w->fixed) has a schedule, left in w->t2 (the same edges but those
 * that are not orderings or lower bounds into timepoints still to come; each link's fixed duration as a
 * lower bound), else 0. The network is the
 * RUL check's without its lower-case edges (hrc/temporal/_rulcore.c, not_dc), unfolded: the executed
 * timepoints pinned instead of merged into the origin; every time is at 0 or later (executed ones are,
 * the rest are at now or after an activation by a lower bound >= 0), so starting from 0 adds nothing. */
static int ranges_consistent(const HrcForm *f, HrcWork *w, int64_t p, int n, int *loose) {
    int64_t e0 = f->edges_ptr[p], e1 = f->edges_ptr[p + 1], c0 = f->conts_ptr[p], c1 = f->conts_ptr[p + 1];
    int k = (int)(c1 - c0), nl = 0;
    int64_t *ex = w->ex, *t = w->t;
    const int64_t never = INT64_MIN / 4;  /* a length that never moves anything: no such edge */
    for (int64_t i = e0; i < e1; i++) {
        int u = f->eu[i], v = f->ev[i];
        if (ex[u] != NONE && ex[v] != NONE) continue;
        int64_t len = -weight(f->ew32, f->ew64, i);
        if (v == 0 && len <= 0) continue;  /* (as in schedule) */
        w->lu[nl] = v; w->lv[nl] = u; w->len[nl] = len;
        w->len2[nl] = ex[u] != NONE || len < 0 ? never : len;  /* (schedule, not strict) */
        nl++;
    }
    for (int j = 0; j < k; j++) {
        int a = f->ca[c0 + j], c = f->cc[c0 + j];
        if (ex[c] != NONE) continue;
        w->lu[nl] = a; w->lv[nl] = c; w->len[nl] = w->lb[j]; w->len2[nl] = w->fixed[j]; nl++;
        w->lu[nl] = c; w->lv[nl] = a; w->len[nl] = -w->ub[j]; w->len2[nl] = never; nl++;
    }
    for (int x = 0; x < n; x++) t[x] = ex[x] != NONE ? ex[x] : w->contingent[x] ? 0 : w->now;
    t[0] = 0;
    memcpy(w->t2, t, sizeof(int64_t) * (size_t)n);
    int ok1, ok2;
    longest_both(w, n, nl, &ok1, &ok2);
    *loose = ok2;
    return ok1;
}

static int evaluate(const HrcForm *f, const HrcState *s, int64_t p, HrcWork *w, int8_t *cls, int64_t *finish,
                    int64_t *idle, int64_t *times) {
    int n = f->n[p];
    int64_t e0 = f->edges_ptr[p], e1 = f->edges_ptr[p + 1], c0 = f->conts_ptr[p], c1 = f->conts_ptr[p + 1];
    int k = (int)(c1 - c0);
    int active = prepare(f, s, p, w);
    if (active < 0) return -1;
    int64_t *ex = w->ex, *t = w->t, now = s->now;
    int G = f->agents, L = f->legs;
    const int16_t *nodes = f->nodes + (int64_t)p * G * L * EVENTS;
    /* strongly controllable: DC; else not consistent: inconsistent (see the file's comment). Else a
     * schedule with every unrevealed duration at its lower bound: if there is one, it is a feasible
     * potential for the DC check's step 1 (hrc/temporal/_rulcore.h), and the residual is DC when no
     * contingent link is left; if there is none, the residual's LO-graph has a negative cycle: not DC
     * (consistent, as the STN check said) */
    int blocked = f->blocked[p], strong = 0, lb_found = 0, consistent = -1, loose = 0;  /* -1: not known */
    if (!blocked && active > 0) {
        strong = strongly(f, w, p, n);
        if (!strong) consistent = ranges_consistent(f, w, p, n, &loose);
    }
    if (!strong && consistent != 0) {
        lb_found = schedule(f, w, p, n, 1, w->lb) == 0;
        if (lb_found) memcpy(w->pot, t, sizeof(int64_t) * (size_t)n);
    }
    if (blocked) {
        *cls = 2;
    } else if (strong) {
        *cls = 0;
    } else if (consistent == 0) {
        *cls = 2;
    } else if (lb_found && active == 0) {
        *cls = 0;
    } else if (!lb_found) {
        if (consistent < 0) consistent = ranges_consistent(f, w, p, n, &loose);
        *cls = consistent ? 1 : 2;
    } else {
        const int *map = w->map;
        if (hrc_rul_begin(w->rul, w->nn, active)) return -1;
        for (int64_t i = e0; i < e1; i++) {
            int u = f->eu[i], v = f->ev[i];
            if (ex[u] != NONE && ex[v] != NONE) continue;
            if (hrc_rul_edge(w->rul, map[u], map[v], folded(w, u, v, weight(f->ew32, f->ew64, i)))) return -1;
        }
        for (int x = 1; x < n; x++) {
            if (ex[x] == NONE && !w->contingent[x] && hrc_rul_edge(w->rul, map[x], 0, -now)) return -1;
        }
        int l = 0;
        for (int j = 0; j < k; j++) {
            int a = f->ca[c0 + j], c = f->cc[c0 + j];
            int64_t shift = ex[a] != NONE ? ex[a] : 0;  /* a link in progress: from the origin */
            if (ex[c] == NONE) hrc_rul_link(w->rul, l++, map[a], map[c], w->lb[j] + shift, w->ub[j] + shift);
        }
        for (int y = 0; y < w->nn; y++) w->pot2[y] = w->pot[w->unmap[y]];  /* (lb_found here) */
        int verdict = hrc_rul_run(w->rul, w->pot2);
        if (verdict < 0) return -1;
        *cls = (int8_t)verdict;
    }
    /* the schedule: strict, then on the orderings and lower bounds still to come; the strict one is
     * known not to exist when the residual is inconsistent (each fixed duration is in its range now) or,
     * for rank_by 1, when the schedule at the lower bounds was not found */
    int found;
    if (strong && w->strict) {
        found = 0;  /* strongly left it in t */
    } else if (consistent == 0) {  /* no strict schedule; ranges_consistent found the other one, or not */
        found = !loose;
        if (loose) memcpy(t, w->t2, sizeof(int64_t) * (size_t)n);
    } else if (s->rank_by == 1 && lb_found) {
        memcpy(t, w->pot, sizeof(int64_t) * (size_t)n);
        found = 0;
    } else {
        found = s->rank_by == 1 && !strong && !lb_found ? 1 : schedule(f, w, p, n, 1, w->fixed);
        if (found) found = schedule(f, w, p, n, 0, w->fixed);
    }
    if (found) {
        *finish = NONE;
        *idle = 0;
        return 0;
    }
    int64_t last = t[0];
    for (int x = 1; x < n; x++) if (t[x] > last) last = t[x];
    *finish = last;
    int64_t total = 0;
    for (int g = 0; g < G; g++) {
        int64_t busy = 0, end = NONE;
        for (int leg = 0; leg < L; leg++) {
            const int16_t *nd = nodes + (g * L + leg) * EVENTS;
            if (nd[0] < 0) break;
            busy += t[nd[3]] - t[nd[0]];
            if (nd[1] >= 0) busy -= t[nd[2]] - t[nd[1]];
            /* a joint phase another agent leads has no start and end of this agent's (the lead's): its
             * part ends with its arrival there, as the compile's idle counts it (hrc.compile.classify) */
            if (nd[5] >= 0) busy += t[nd[5]] - t[nd[4]];
            end = t[nd[5] >= 0 ? nd[5] : nd[3]];
        }
        if (end != NONE) total += max64(0, end - busy);
    }
    *idle = total;
    if (times) memcpy(times, t, sizeof(int64_t) * (size_t)n);
    return 0;
}

/* Evaluate plans[0..count-1] (see the file's comment); returns how many could not be (-1 class: out of
 * memory, or an index out of range in the form). `times`, when set, receives the schedule of the last
 * plan evaluated (its n timepoints' ticks). */
/* Ask the memory for plan p's arrays (its edges, links and leg timepoints), which its evaluation reads
 * first: the form is a memory-mapped file of a few tens of MB, and a message's plans are scattered in it,
 * so without this most of a plan's evaluation waited for the first reads of each of its arrays. */
static void fetch(const HrcForm *f, int64_t p) {
    if (p < 0 || p >= f->plans) return;
    int64_t e0 = f->edges_ptr[p], e1 = f->edges_ptr[p + 1], c0 = f->conts_ptr[p], c1 = f->conts_ptr[p + 1];
    const char *spans[][2] = {
        {(const char *)(f->eu + e0), (const char *)(f->eu + e1)}, {(const char *)(f->ev + e0), (const char *)(f->ev + e1)},
        {f->ew32 ? (const char *)(f->ew32 + e0) : (const char *)(f->ew64 + e0),
         f->ew32 ? (const char *)(f->ew32 + e1) : (const char *)(f->ew64 + e1)},
        {(const char *)(f->ca + c0), (const char *)(f->ca + c1)}, {(const char *)(f->cc + c0), (const char *)(f->cc + c1)},
        {f->clb32 ? (const char *)(f->clb32 + c0) : (const char *)(f->clb64 + c0),
         f->clb32 ? (const char *)(f->clb32 + c1) : (const char *)(f->clb64 + c1)},
        {f->cub32 ? (const char *)(f->cub32 + c0) : (const char *)(f->cub64 + c0),
         f->cub32 ? (const char *)(f->cub32 + c1) : (const char *)(f->cub64 + c1)},
        {(const char *)(f->nodes + p * f->agents * f->legs * EVENTS),
         (const char *)(f->nodes + (p + 1) * f->agents * f->legs * EVENTS)}};
    for (size_t a = 0; a < sizeof spans / sizeof spans[0]; a++)
        for (const char *at = spans[a][0]; at < spans[a][1]; at += 64) __builtin_prefetch(at);
}

int hrc_dispatch_evaluate(const HrcForm *f, const HrcState *s, HrcWork *w, int count, const int64_t *plans,
                          int8_t *cls, int64_t *finish, int64_t *idle, int64_t *times) {
    int failed = 0;
    if (count > 0) fetch(f, plans[0]);
    for (int i = 0; i < count; i++) {
        int64_t p = plans[i];
        if (i + 1 < count) fetch(f, plans[i + 1]);
        if (p < 0 || p >= f->plans || evaluate(f, s, p, w, cls + i, finish + i, idle + i, times) < 0) {
            cls[i] = -1; finish[i] = NONE; idle[i] = 0;
            failed++;
        }
    }
    return failed;
}

/* ================================================================ the decision: execution windows
 *
 * hrc.temporal.execution's RealTimeState.step for the plan the dispatcher follows, on its residual
 * network (the origin is timepoint 0: the residual's own origin and Z, executed at 0, tied by [0, 0]):
 *
 *   - the residual's verdict by the bypass closure (hrc.temporal.bypass: lower-case edges bypassed
 *     round by round, Dijkstra under a potential), after its STN consistency check; the mode asked for
 *     is made stricter when the verdict says so (DC -> STN -> EARLIEST);
 *   - the mode's graph: DC: the residual's ordinary edges, each contingent link's lower bound, its upper
 *     bound unless in progress, its upper-case edge and every derived bypass read as ordinary (AllMax);
 *     STN: contingent links as requirements; EARLIEST: orderings and lower bounds still binding (edges of
 *     weight <= 0 not from an executed timepoint to an unexecuted one; pins kept; contingent lower bounds);
 *   - for each timepoint x asked for: wait for every unexecuted v with d(x, v) < 0 (<= 0 when v is
 *     contingent or uncontrolled), else the window [max(now, -d(x, O)), min over unexecuted v of d(O, v)]
 *     (EARLIEST: [earliest, earliest]); a negative cycle in EARLIEST's graph gives [now, now].
 *
 * Distances are queue-based Bellman-Ford with 64-bit sums: the caller keeps every weight below 2^40.
 */

#define INF INT64_MAX

typedef struct {
    int n, m, cap;
    int *src, *dst, *lab, *nxt, *head;  /* lab: -1 ordinary, else the contingent timepoint of an upper-case edge */
    int64_t *w;
} Arcs;

static void arcs_free(Arcs *g) { free(g->src); free(g->dst); free(g->lab); free(g->nxt); free(g->head); free(g->w); }

static int arcs_init(Arcs *g, int n) {
    memset(g, 0, sizeof *g);
    g->n = n;
    g->head = malloc(sizeof(int) * (size_t)n);
    if (!g->head) return -1;
    for (int v = 0; v < n; v++) g->head[v] = -1;
    return 0;
}

static int arcs_add(Arcs *g, int s, int t, int64_t w, int lab) {
    if (g->m == g->cap) {
        int cap = g->cap ? 2 * g->cap : 256;
        int *a = realloc(g->src, sizeof(int) * (size_t)cap);
        if (!a) return -1;
        g->src = a;
        if (!(a = realloc(g->dst, sizeof(int) * (size_t)cap))) return -1;
        g->dst = a;
        if (!(a = realloc(g->lab, sizeof(int) * (size_t)cap))) return -1;
        g->lab = a;
        if (!(a = realloc(g->nxt, sizeof(int) * (size_t)cap))) return -1;
        g->nxt = a;
        int64_t *b = realloc(g->w, sizeof(int64_t) * (size_t)cap);
        if (!b) return -1;
        g->w = b;
        g->cap = cap;
    }
    int e = g->m++;
    g->src[e] = s; g->dst[e] = t; g->w[e] = w; g->lab[e] = lab;
    g->nxt[e] = g->head[s]; g->head[s] = e;
    return e;
}

/* `g` with every edge turned round (labels dropped). */
static int arcs_reversed(const Arcs *g, Arcs *r) {
    if (arcs_init(r, g->n)) return -1;
    for (int e = 0; e < g->m; e++) if (arcs_add(r, g->dst[e], g->src[e], g->w[e], -1) < 0) return -1;
    return 0;
}

/* Shortest distances from `from` (INF: not reached) by queue-based Bellman-Ford; 1 when a negative cycle
 * is reachable (a path of n edges), -1 out of memory, 0 done. */
static int distances(const Arcs *g, int from, int64_t *dist) {
    int n = g->n, *hops = malloc(sizeof(int) * (size_t)n), *queue = malloc(sizeof(int) * (size_t)(n + 1));
    char *queued = calloc((size_t)n, 1);
    if (!hops || !queue || !queued) { free(hops); free(queue); free(queued); return -1; }
    for (int v = 0; v < n; v++) { dist[v] = INF; hops[v] = 0; }
    dist[from] = 0;
    int qh = 0, qt = 0, count = 1, result = 0;
    queue[qt++] = from; queued[from] = 1;
    while (count && !result) {
        int u = queue[qh]; qh = (qh + 1) % (n + 1); count--;
        queued[u] = 0;
        for (int e = g->head[u]; e >= 0; e = g->nxt[e]) {
            int v = g->dst[e];
            if (dist[u] + g->w[e] < dist[v]) {
                dist[v] = dist[u] + g->w[e];
                hops[v] = hops[u] + 1;
                if (hops[v] >= n) { result = 1; break; }
                if (!queued[v]) { queued[v] = 1; queue[qt] = v; qt = (qt + 1) % (n + 1); count++; }
            }
        }
    }
    free(hops); free(queue); free(queued);
    return result;
}

/* ---------------------------------------------------------------- the bypass closure */
typedef struct {
    Arcs g;                  /* the OU-graph: ordinary and upper-case edges */
    int k, *la, *lc;         /* lower-case edges a --c:x--> c */
    int64_t *lx, *min_lb;    /* min_lb[c]: the lower bound of the link whose contingent timepoint is c */
    int *link_of;            /* contingent timepoint -> its link, -1 */
    int64_t *p;              /* a feasible potential of the OU-graph */
    int64_t *hkeys, *hvals, hcap, hcount;  /* best weight present per (source, target, label) */
} Closure;

static int64_t best_key(const Closure *c, int s, int t, int lab) {
    return ((int64_t)s * c->g.n + t) * (c->g.n + 1) + (lab + 1);
}

static int64_t *best_slot(Closure *c, int64_t key) {
    uint64_t h = (uint64_t)key * 0x9E3779B97F4A7C15ULL;
    int64_t i = (int64_t)(h >> 1) & (c->hcap - 1);
    while (c->hkeys[i] != -1 && c->hkeys[i] != key) i = (i + 1) & (c->hcap - 1);
    return &c->hkeys[i];
}

static int64_t best_get(Closure *c, int s, int t, int lab) {
    int64_t key = best_key(c, s, t, lab);
    int64_t *slot = best_slot(c, key);
    return *slot == key ? c->hvals[slot - c->hkeys] : INF;
}

static int best_grow(Closure *c) {
    int64_t old = c->hcap, *ok = c->hkeys, *ov = c->hvals;
    c->hcap = old ? 2 * old : 1024;
    c->hkeys = malloc(sizeof(int64_t) * (size_t)c->hcap);
    c->hvals = malloc(sizeof(int64_t) * (size_t)c->hcap);
    if (!c->hkeys || !c->hvals) return -1;
    memset(c->hkeys, 0xff, sizeof(int64_t) * (size_t)c->hcap);
    for (int64_t i = 0; i < old; i++) {
        if (ok[i] == -1) continue;
        int64_t *slot = best_slot(c, ok[i]);
        *slot = ok[i];
        c->hvals[slot - c->hkeys] = ov[i];
    }
    free(ok); free(ov);
    return 0;
}

/* bypass.py's _add: the edge unless one at least as strong is present (an ordinary one dominates a
 * labelled one). 1 added, 0 not, -1 memory. */
static int closure_add(Closure *c, int s, int t, int64_t w, int lab) {
    if (w >= best_get(c, s, t, lab) || w >= best_get(c, s, t, -1)) return 0;
    if ((c->hcount + 1) * 2 > c->hcap && best_grow(c)) return -1;
    int64_t key = best_key(c, s, t, lab), *slot = best_slot(c, key);
    if (*slot != key) { *slot = key; c->hcount++; }
    c->hvals[slot - c->hkeys] = w;
    return arcs_add(&c->g, s, t, w, lab) < 0 ? -1 : 1;
}

static void closure_free(Closure *c) {
    arcs_free(&c->g);
    free(c->la); free(c->lc); free(c->lx); free(c->min_lb); free(c->link_of); free(c->p); free(c->hkeys); free(c->hvals);
}

/* Queue-based Bellman-Ford from the current potential, from the `nd` nodes of `dirty`: 0 done, 1 a
 * negative cycle (parent pointers closing a cycle), -1 memory. */
static int relax(Closure *c, const int *dirty, int nd) {
    int n = c->g.n;
    int *pred = malloc(sizeof(int) * (size_t)n), *len = calloc((size_t)n, sizeof(int));
    int *queue = malloc(sizeof(int) * (size_t)(n + 1)), *seen = malloc(sizeof(int) * (size_t)n);
    char *queued = calloc((size_t)n, 1);
    int result = 0;
    if (!pred || !len || !queue || !queued || !seen) { result = -1; goto done; }
    for (int v = 0; v < n; v++) pred[v] = -1;
    int qh = 0, qt = 0, count = 0;
    for (int i = 0; i < nd; i++) {
        if (!queued[dirty[i]]) { queued[dirty[i]] = 1; queue[qt] = dirty[i]; qt = (qt + 1) % (n + 1); count++; }
    }
    int64_t *dist = c->p;
    while (count && !result) {
        int u = queue[qh]; qh = (qh + 1) % (n + 1); count--;
        queued[u] = 0;
        for (int e = c->g.head[u]; e >= 0; e = c->g.nxt[e]) {
            int v = c->g.dst[e];
            if (dist[u] + c->g.w[e] < dist[v]) {
                dist[v] = dist[u] + c->g.w[e];
                pred[v] = e;
                len[v] = len[u] + 1;
                if (len[v] >= n) {
                    /* a cycle among the parent pointers is a negative cycle; none: go on */
                    for (int x = 0; x < n; x++) seen[x] = 0;
                    int x = v, cycle = 0;
                    while (x >= 0 && !seen[x]) { seen[x] = 1; x = pred[x] >= 0 ? c->g.src[pred[x]] : -1; }
                    if (x >= 0) cycle = 1;
                    if (cycle) { result = 1; break; }
                    len[v] = 0;
                }
                if (!queued[v]) { queued[v] = 1; queue[qt] = v; qt = (qt + 1) % (n + 1); count++; }
            }
        }
    }
done:
    free(pred); free(len); free(queue); free(queued); free(seen);
    return result;
}

typedef struct { int64_t key; int node; } HeapItem;

static void heap_push(HeapItem *h, int *size, int64_t key, int node) {
    int i = (*size)++;
    while (i > 0) {
        int parent = (i - 1) / 2;
        if (h[parent].key < key || (h[parent].key == key && h[parent].node <= node)) break;
        h[i] = h[parent];
        i = parent;
    }
    h[i].key = key; h[i].node = node;
}

static HeapItem heap_pop(HeapItem *h, int *size) {
    HeapItem top = h[0], last = h[--(*size)];
    int i = 0, n = *size;
    for (;;) {
        int ch = 2 * i + 1;
        if (ch >= n) break;
        if (ch + 1 < n && (h[ch + 1].key < h[ch].key || (h[ch + 1].key == h[ch].key && h[ch + 1].node < h[ch].node))) ch++;
        if (last.key < h[ch].key || (last.key == h[ch].key && last.node <= h[ch].node)) break;
        h[i] = h[ch];
        i = ch;
    }
    if (n) h[i] = last;
    return top;
}

/* The bypass closure (bypass.py's _Closure.run): 0 DC (the derived edges are in c->g), 1 not DC, -1 memory. */
static int closure_run(Closure *c) {
    int n = c->g.n, k = c->k, result = 0;
    int *all = malloc(sizeof(int) * (size_t)n);
    int64_t *searched = malloc(sizeof(int64_t) * (size_t)(k + 1)), *touched = calloc((size_t)n, sizeof(int64_t));
    char *region = calloc((size_t)(k + 1) * (size_t)n, 1);
    int64_t *dist = malloc(sizeof(int64_t) * (size_t)n);
    int *found = malloc(sizeof(int) * (size_t)n);
    int64_t *uc_t = malloc(sizeof(int64_t) * (size_t)n * (size_t)(k + 1));
    int *uc_list = malloc(sizeof(int) * (size_t)n * (size_t)(k + 1));
    HeapItem *heap = NULL;
    int heap_cap = 0;
    if (!all || !searched || !touched || !region || !dist || !found || !uc_t || !uc_list) { result = -1; goto done; }
    for (int v = 0; v < n; v++) all[v] = v;
    for (int64_t i = 0; i < (int64_t)n * (k + 1); i++) uc_t[i] = INF;
    result = relax(c, all, n);
    if (result) goto done;
    for (int i = 0; i < k; i++) searched[i] = -1;
    int64_t clock = 0;
    int again = 1;
    while (again && !result) {
        again = 0;
        for (int i = 0; i < k && !result; i++) {
            int a = c->la[i], cc = c->lc[i];
            int64_t x = c->lx[i];
            if (searched[i] >= 0) {
                int stale = 0;
                for (int v = 0; v < n && !stale; v++) if (region[(size_t)i * n + v] && touched[v] > searched[i]) stale = 1;
                if (!stale) continue;
            }
            searched[i] = ++clock;
            /* Dijkstra from cc on reduced weights, expanding nodes at a non-negative true distance */
            memset(region + (size_t)i * n, 0, (size_t)n);
            for (int v = 0; v < n; v++) dist[v] = INF;
            int nfound = 0, nuc = 0, size = 0;
            if (heap_cap < c->g.m + 1) {
                heap_cap = 2 * (c->g.m + 1);
                HeapItem *h = realloc(heap, sizeof(HeapItem) * (size_t)heap_cap);
                if (!h) { result = -1; break; }
                heap = h;
            }
            int64_t *p = c->p, pc = p[cc];
            dist[cc] = 0;
            heap_push(heap, &size, 0, cc);
            while (size) {
                HeapItem it = heap_pop(heap, &size);
                int u = it.node;
                if (it.key > dist[u]) continue;
                int64_t true_u = it.key - pc + p[u];
                if (true_u < 0) { found[nfound++] = u; continue; }
                region[(size_t)i * n + u] = 1;
                for (int e = c->g.head[u]; e >= 0; e = c->g.nxt[e]) {
                    int v = c->g.dst[e], lab = c->g.lab[e];
                    int64_t w = c->g.w[e];
                    if (lab >= 0) {
                        int64_t t = true_u + w;
                        if (t < 0) {  /* a negative upper-case ending: a cross-case candidate, never expanded */
                            if (lab != cc) {
                                int l = c->link_of[lab];
                                int64_t *slot = &uc_t[(size_t)v * (k + 1) + l];
                                if (*slot == INF) uc_list[nuc++] = v * (k + 1) + l;
                                if (t < *slot) *slot = t;
                            }
                            continue;
                        }
                    }
                    int64_t nd = it.key + w + p[u] - p[v];
                    if (nd < dist[v]) {
                        dist[v] = nd;
                        if (size + 1 > heap_cap) {
                            heap_cap *= 2;
                            HeapItem *h = realloc(heap, sizeof(HeapItem) * (size_t)heap_cap);
                            if (!h) { result = -1; break; }
                            heap = h;
                        }
                        heap_push(heap, &size, nd, v);
                    }
                }
                if (result) break;
            }
            if (result) break;
            /* the bypasses: ordinary ones to the nodes found, cross-case ones to upper-case endings */
            int changed = 0;
            for (int j = 0; j < nfound + nuc && result >= 0; j++) {
                int v, lab;
                int64_t wv;
                if (j < nfound) {
                    v = found[j]; lab = -1;
                    wv = x + dist[v] - pc + p[v];
                } else {
                    int slot = uc_list[j - nfound];
                    v = slot / (k + 1);
                    int l = slot % (k + 1);
                    lab = c->lc[l];
                    wv = x + uc_t[slot];
                    uc_t[slot] = INF;
                    if (wv >= -c->min_lb[lab]) lab = -1;  /* label removal */
                }
                if (v == a && wv >= 0) continue;
                int added = closure_add(c, a, v, wv, lab);
                if (added < 0) result = -1;
                else if (added) changed = 1;
            }
            if (result) break;
            if (changed) {
                touched[a] = ++clock;
                again = 1;
                result = relax(c, &a, 1);
            }
        }
    }
done:
    free(all); free(searched); free(touched); free(region); free(dist); free(found); free(uc_t); free(uc_list); free(heap);
    return result;
}

/* 0 consistent, 1 a negative cycle, -1 memory: the graph `g` from a virtual source (all potentials 0). */
static int consistent(const Arcs *g) {
    Closure c;
    memset(&c, 0, sizeof c);
    c.g = *g;
    c.p = calloc((size_t)g->n, sizeof(int64_t));
    if (!c.p) return -1;
    int *all = malloc(sizeof(int) * (size_t)g->n);
    if (!all) { free(c.p); return -1; }
    for (int v = 0; v < g->n; v++) all[v] = v;
    int r = relax(&c, all, g->n);
    free(all); free(c.p);
    return r;
}

/* Modes: 0 DC, 1 STN, 2 EARLIEST. For plan p under the state: the mode made stricter where the residual's
 * own checks say so (*mode in and out), then for each of the nq timepoints of `query` either its window
 * [earliest[i], latest[i]] (INT64_MAX: no bound) with waits[i] = 0, or waits[i] > 0 timepoints it must
 * wait for first, listed in until[i * n ...] (n: the plan's timepoints). `uncontrolled[i * n + v]`: 1 when
 * timepoint v is, for query i, a co-worker's own executable (waited for at d <= 0, like a contingent one),
 * so the query's agent never goes together with an event it cannot make happen. Returns 0, or -1 (out of
 * memory, or weights too large for 64-bit sums: the caller uses the Python implementation). */
int hrc_dispatch_windows(const HrcForm *f, const HrcState *s, HrcWork *w, int64_t p, int *mode, int nq,
                         const int *query, const uint8_t *uncontrolled, int64_t *earliest, int64_t *latest,
                         int *waits, int *until) {
    if (p < 0 || p >= f->plans || prepare(f, s, p, w) < 0) return -1;
    int n = f->n[p];
    int64_t e0 = f->edges_ptr[p], e1 = f->edges_ptr[p + 1], c0 = f->conts_ptr[p], c1 = f->conts_ptr[p + 1];
    int k = (int)(c1 - c0);
    int64_t *ex = w->ex, now = s->now;
    const int64_t big = (int64_t)1 << 40;
    for (int64_t i = e0; i < e1; i++) {
        int64_t wt = weight(f->ew32, f->ew64, i);
        if (wt >= big || wt <= -big) return -1;
    }
    for (int j = 0; j < k; j++) if (w->ub[j] >= big || w->lb[j] < 0) return -1;
    for (int x = 0; x < n; x++) if (ex[x] != NONE && (ex[x] >= big || ex[x] <= -big)) return -1;
    if (now >= big || now < 0) return -1;
    for (int i = 0; i < nq; i++) if (query[i] < 1 || query[i] >= n) return -1;
    int result = 0, derived_from = 0, nn = w->nn;
    const int *map = w->map, *unmap = w->unmap;
    Closure c;
    memset(&c, 0, sizeof c);
    Arcs stn, modal, rev;
    memset(&stn, 0, sizeof stn); memset(&modal, 0, sizeof modal); memset(&rev, 0, sizeof rev);
    int64_t *d_to = malloc(sizeof(int64_t) * (size_t)nn), *d_from = malloc(sizeof(int64_t) * (size_t)nn);
    int64_t *d_x = malloc(sizeof(int64_t) * (size_t)nn);
    if (!d_to || !d_from || !d_x || arcs_init(&c.g, nn) || arcs_init(&stn, nn) || arcs_init(&modal, nn) ||
        best_grow(&c)) { result = -1; goto done; }
    c.la = malloc(sizeof(int) * (size_t)(k + 1)); c.lc = malloc(sizeof(int) * (size_t)(k + 1));
    c.lx = malloc(sizeof(int64_t) * (size_t)(k + 1)); c.min_lb = calloc((size_t)nn, sizeof(int64_t));
    c.link_of = malloc(sizeof(int) * (size_t)nn); c.p = calloc((size_t)nn, sizeof(int64_t));
    if (!c.la || !c.lc || !c.lx || !c.min_lb || !c.link_of || !c.p) { result = -1; goto done; }
    for (int v = 0; v < nn; v++) c.link_of[v] = -1;
    /* the residual's labelled graph, folded (`prepare`: an executed timepoint is the origin at its time):
     * its ordinary edges (requirements, "now or later", contingent links as pairs) into the STN check's
     * graph and the closure's, its upper-case edges into the closure's */
#define BOTH(u, v, wt) do { if (arcs_add(&stn, u, v, wt, -1) < 0 || closure_add(&c, u, v, wt, -1) < 0) \
                                { result = -1; goto done; } } while (0)
    for (int64_t i = e0; i < e1; i++) {
        int u = f->eu[i], v = f->ev[i];
        if (ex[u] != NONE && ex[v] != NONE) continue;
        BOTH(map[u], map[v], folded(w, u, v, weight(f->ew32, f->ew64, i)));
    }
    for (int x = 1; x < n; x++) if (ex[x] == NONE && !w->contingent[x]) BOTH(map[x], 0, -now);
    for (int j = 0; j < k; j++) {
        int a = f->ca[c0 + j], cc = f->cc[c0 + j];
        if (ex[cc] != NONE) continue;
        int64_t shift = ex[a] != NONE ? ex[a] : 0, lb = w->lb[j] + shift, ub = w->ub[j] + shift;
        int A = map[a], C = map[cc];
        BOTH(A, C, ub);
        BOTH(C, A, -lb);
        c.la[c.k] = A; c.lc[c.k] = C; c.lx[c.k] = lb; c.link_of[C] = c.k; c.min_lb[C] = lb;
        c.k++;
    }
#undef BOTH
    for (int j = 0; j < k; j++) {
        int a = f->ca[c0 + j], cc = f->cc[c0 + j];
        if (ex[cc] != NONE) continue;
        int64_t shift = ex[a] != NONE ? ex[a] : 0;
        if (closure_add(&c, map[cc], map[a], -(w->ub[j] + shift), map[cc]) < 0) { result = -1; goto done; }
    }
    /* the residual's verdict, as far as the mode asked for needs it */
    if (*mode <= 1) {
        int r = consistent(&stn);
        if (r < 0) { result = -1; goto done; }
        if (r) *mode = 2;
    }
    derived_from = c.g.m;
    if (*mode == 0 && c.k) {
        int r = closure_run(&c);
        if (r < 0) { result = -1; goto done; }
        if (r) *mode = 1;
    }
    /* the mode's graph (EARLIEST keeps orderings and lower bounds: edges of weight <= 0, but those from an
     * executed timepoint to one to come; the pins are the folding itself) */
    for (int64_t i = e0; i < e1; i++) {
        int u = f->eu[i], v = f->ev[i];
        if (ex[u] != NONE && ex[v] != NONE) continue;
        int64_t wt = weight(f->ew32, f->ew64, i);
        if (*mode == 2 && (wt > 0 || (ex[u] != NONE && ex[v] == NONE))) continue;
        if (arcs_add(&modal, map[u], map[v], folded(w, u, v, wt), -1) < 0) { result = -1; goto done; }
    }
    for (int x = 1; x < n; x++) {
        if (ex[x] == NONE && !w->contingent[x] && arcs_add(&modal, map[x], 0, -now, -1) < 0) { result = -1; goto done; }
    }
    for (int j = 0; j < k; j++) {
        int a = f->ca[c0 + j], cc = f->cc[c0 + j];
        if (ex[cc] != NONE) continue;
        int in_progress = ex[a] != NONE;
        int64_t shift = in_progress ? ex[a] : 0, lb = w->lb[j] + shift, ub = w->ub[j] + shift;
        int A = map[a], C = map[cc];
        if (arcs_add(&modal, C, A, -lb, -1) < 0) { result = -1; goto done; }
        if ((*mode == 1 || (*mode == 0 && !in_progress)) && arcs_add(&modal, A, C, ub, -1) < 0) {
            result = -1; goto done;
        }
        if (*mode == 0 && arcs_add(&modal, C, A, -ub, -1) < 0) { result = -1; goto done; }
    }
    if (*mode == 0) {  /* every bypass the closure derived, upper-case ones read as ordinary (AllMax) */
        for (int e = derived_from; e < c.g.m; e++) {
            if (arcs_add(&modal, c.g.src[e], c.g.dst[e], c.g.w[e], -1) < 0) { result = -1; goto done; }
        }
    }
    /* distances to the origin (earliest), from it (latest), from each timepoint asked for (waits) */
    if (arcs_reversed(&modal, &rev)) { result = -1; goto done; }
    int r_to = distances(&rev, 0, d_to);
    if (r_to < 0) { result = -1; goto done; }
    int64_t last = INF;
    if (!r_to && *mode != 2) {
        int r = distances(&modal, 0, d_from);
        if (r < 0) { result = -1; goto done; }
        for (int v = 1; v < nn; v++) if (d_from[v] < last) last = d_from[v];
    }
    for (int i = 0; i < nq; i++) {
        int x = query[i], X = map[x];
        if (X == 0) { result = -1; goto done; }  /* executed already: not the caller's question */
        int r_x = r_to ? 1 : distances(&modal, X, d_x);
        if (r_x < 0) { result = -1; goto done; }
        waits[i] = 0;
        if (r_x) {  /* a negative cycle (EARLIEST only): now */
            earliest[i] = now; latest[i] = now;
            continue;
        }
        for (int V = 1; V < nn; V++) {
            if (V == X || d_x[V] == INF) continue;
            int v = unmap[V];
            int weak = w->contingent[v] || uncontrolled[(int64_t)i * n + v];
            if (d_x[V] < 0 || (weak && d_x[V] <= 0)) until[(int64_t)i * n + waits[i]++] = v;
        }
        earliest[i] = d_to[X] == INF ? now : max64(now, -d_to[X]);
        latest[i] = *mode == 2 ? earliest[i] : last;
    }
done:
    closure_free(&c);
    arcs_free(&stn); arcs_free(&modal); arcs_free(&rev);
    free(d_to); free(d_from); free(d_x);
    return result;
}
