/*
 * The verdict of hrc.temporal.rul's RUL2021-family DC check, in C (loaded with ctypes; no Python headers).
 *
 * It follows hrc/temporal/rul.py step by step (see that module's docstring for the algorithm and its
 * sources: Cairo, Hunsberger & Rizzi, TIME 2018; Hunsberger & Posenato, AAAI 2022; potentials by
 * Goldberg & Radzik 1993) and only decides the verdict: the explaining cycle and the derived edges are
 * rebuilt by the Python implementation when they are asked for. Weights are 128-bit integers, passed as
 * signed 64-bit arrays (the high arrays NULL) or as (low, high) word pairs; the Python side only calls this
 * when max |weight| * (nodes + 2) < 2^120, so no sum can overflow.
 *
 * Memory: O(n + m + derived edges); every search reuses the same n-long arrays, told apart by stamps.
 *
 * Returns 0 DC, 1 not DC, 2 inconsistent, -1 out of memory.
 */
#include <limits.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "_rulcore.h"

typedef __int128 W;

enum { ORD = 0, LC = 1, PAIR = 2, DERIVED = 3 };
enum { UNSTARTED = 0, STARTED = 1, DONE = 2 };

typedef struct { W key; int node; } Item;

struct HrcRul {
    int n, k;
    int ncap, kcap; /* the node and link arrays' sizes (a reused workspace grows, never shrinks) */
    /* edges: growable */
    int m, cap;
    int *src, *dst, *in_next, *out_next;
    W *w;
    char *kind;
    int *in_head, *out_head;
    /* links */
    const int *act, *ctg;
    W *x, *y;
    int *lc;
    int *act_first, *act_next; /* links activated at a node: act_first[node] -> link -> act_next[link] */
    int *status;
    W *p;
    /* searches */
    int sid;
    int *stamp, *done, *pred;
    W *key, *dist;
    int fsid;
    int *fstamp, *fdone;
    W *fkey;
    Item *heap;
    int hsize, hcap;
    int *moat, *touched, *order, *stack_node, *stack_pos, *color, *negs, *pedge, *pnode, *cand, *mark;
    int nmoat, ntouched;
    /* best ordinary or derived edge per (source, activation): open addressing */
    int64_t *hkeys;
    W *hvals;
    int64_t hcap2, hcount;
    /* links in their order of processing, their keys, and the stack of started links */
    int *links, *lkeys_tmp, *stack;
    W *lkeys;
    int *own_act, *own_ctg; /* the links' ends when the workspace owns them (hrc_rul_link) */
};
typedef struct HrcRul Net;

static int grow_edges(Net *g) {
    if (g->m < g->cap) return 0;
    int cap = g->cap ? g->cap * 2 : 64;
    void *a = realloc(g->src, sizeof(int) * cap); if (!a) return -1; g->src = a;
    a = realloc(g->dst, sizeof(int) * cap); if (!a) return -1; g->dst = a;
    a = realloc(g->in_next, sizeof(int) * cap); if (!a) return -1; g->in_next = a;
    a = realloc(g->out_next, sizeof(int) * cap); if (!a) return -1; g->out_next = a;
    a = realloc(g->w, sizeof(W) * cap); if (!a) return -1; g->w = a;
    a = realloc(g->kind, cap); if (!a) return -1; g->kind = a;
    g->cap = cap;
    return 0;
}

static int add_edge(Net *g, int s, int t, W w, char kind) {
    if (grow_edges(g)) return -1;
    int e = g->m++;
    g->src[e] = s; g->dst[e] = t; g->w[e] = w; g->kind[e] = kind;
    g->out_next[e] = g->out_head[s]; g->out_head[s] = e;
    if (kind != PAIR) { g->in_next[e] = g->in_head[t]; g->in_head[t] = e; }
    else g->in_next[e] = -1;
    return e;
}

/* ---------------------------------------------------------------- best-edge table (source, activation) */
static int64_t hslot(Net *g, int64_t key) {
    uint64_t h = (uint64_t)key * 0x9E3779B97F4A7C15ULL;
    int64_t i = (int64_t)(h >> 1) & (g->hcap2 - 1);
    while (g->hkeys[i] != -1 && g->hkeys[i] != key) i = (i + 1) & (g->hcap2 - 1);
    return i;
}

static int hgrow(Net *g) {
    int64_t old = g->hcap2;
    int64_t *ok = g->hkeys; W *ov = g->hvals;
    g->hcap2 = old ? old * 2 : 1024;
    g->hkeys = malloc(sizeof(int64_t) * g->hcap2);
    g->hvals = malloc(sizeof(W) * g->hcap2);
    if (!g->hkeys || !g->hvals) return -1;
    for (int64_t i = 0; i < g->hcap2; i++) g->hkeys[i] = -1;
    for (int64_t i = 0; i < old; i++)
        if (ok[i] != -1) { int64_t j = hslot(g, ok[i]); g->hkeys[j] = ok[i]; g->hvals[j] = ov[i]; }
    free(ok); free(ov);
    return 0;
}

/* 1 if stored (better than what was there), 0 if not, -1 on memory failure */
static int hput_if_better(Net *g, int s, int t, W w) {
    if ((g->hcount + 1) * 2 > g->hcap2 && hgrow(g)) return -1;
    int64_t key = (int64_t)s * g->n + t;
    int64_t i = hslot(g, key);
    if (g->hkeys[i] == key) {
        if (g->hvals[i] <= w) return 0;
        g->hvals[i] = w;
        return 1;
    }
    g->hkeys[i] = key; g->hvals[i] = w; g->hcount++;
    return 1;
}

/* ---------------------------------------------------------------- binary heap of (key, node) */
static int hpush(Net *g, W key, int node) {
    if (g->hsize == g->hcap) {
        int cap = g->hcap ? g->hcap * 2 : 256;
        Item *a = realloc(g->heap, sizeof(Item) * cap);
        if (!a) return -1;
        g->heap = a; g->hcap = cap;
    }
    int i = g->hsize++;
    while (i > 0) {
        int parent = (i - 1) / 2;
        Item *q = &g->heap[parent];
        if (q->key < key || (q->key == key && q->node <= node)) break;
        g->heap[i] = *q;
        i = parent;
    }
    g->heap[i].key = key; g->heap[i].node = node;
    return 0;
}

static Item hpop(Net *g) {
    Item top = g->heap[0];
    Item last = g->heap[--g->hsize];
    int i = 0, n = g->hsize;
    for (;;) {
        int c = 2 * i + 1;
        if (c >= n) break;
        if (c + 1 < n && (g->heap[c + 1].key < g->heap[c].key ||
                          (g->heap[c + 1].key == g->heap[c].key && g->heap[c + 1].node < g->heap[c].node))) c++;
        if (last.key < g->heap[c].key || (last.key == g->heap[c].key && last.node <= g->heap[c].node)) break;
        g->heap[i] = g->heap[c];
        i = c;
    }
    if (n) g->heap[i] = last;
    return top;
}

/* ---------------------------------------------------------------- potentials (Goldberg-Radzik) */
/* Lower p until p[v] <= p[u] + w on every out-edge (skipping kind `skip`, or none if skip < 0).
 * 0 success, 1 negative cycle, -1 memory. */
static int potential(Net *g, W *p, int skip) {
    int n = g->n;
    int *cand = g->cand, *mark = g->mark, *color = g->color, *negs = g->negs;
    int *order = g->order, *sn = g->stack_node, *sp = g->stack_pos, *pe = g->pedge, *pn = g->pnode;
    int ncand = n, passes = 0;
    for (int v = 0; v < n; v++) { cand[v] = v; color[v] = 0; pe[v] = -1; pn[v] = -1; mark[v] = 0; }
    while (ncand > 0) {
        passes++;
        int nroots = 0;
        for (int i = 0; i < ncand; i++) {
            int u = cand[i];
            for (int e = g->out_head[u]; e >= 0; e = g->out_next[e]) {
                if (g->kind[e] == skip) continue;
                if (p[u] + g->w[e] < p[g->dst[e]]) { cand[nroots++] = u; break; }
            }
        }
        if (!nroots) return 0;
        int norder = 0, ntouch = 0;
        int *touch = g->touched;
        for (int r = 0; r < nroots; r++) {
            int root = cand[r];
            if (color[root]) continue;
            int top = 0;
            sn[0] = root; sp[0] = g->out_head[root]; color[root] = 1; negs[root] = 0; touch[ntouch++] = root;
            while (top >= 0) {
                int u = sn[top];
                int e = sp[top], pushed = 0;
                while (e >= 0) {
                    int next = g->out_next[e];
                    if (g->kind[e] != skip) {
                        int v = g->dst[e];
                        W reduced = p[u] + g->w[e] - p[v];
                        if (reduced <= 0) {
                            if (color[v] == 0) {
                                sp[top] = next;
                                color[v] = 1; touch[ntouch++] = v;
                                negs[v] = negs[u] + (reduced < 0);
                                top++; sn[top] = v; sp[top] = g->out_head[v];
                                pushed = 1;
                                break;
                            }
                            if (color[v] == 1 && (reduced < 0 || negs[u] > negs[v])) return 1;
                        }
                    }
                    e = next;
                }
                if (!pushed) { color[u] = 2; order[norder++] = u; top--; }
            }
        }
        for (int i = 0; i < ntouch; i++) color[touch[i]] = 0;
        int nchanged = 0;
        for (int i = norder - 1; i >= 0; i--) {
            int u = order[i];
            for (int e = g->out_head[u]; e >= 0; e = g->out_next[e]) {
                if (g->kind[e] == skip) continue;
                int v = g->dst[e];
                if (p[u] + g->w[e] < p[v]) {
                    p[v] = p[u] + g->w[e];
                    pe[v] = e; pn[v] = u;
                    if (mark[v] != passes) { mark[v] = passes; cand[nchanged++] = v; }
                }
            }
        }
        ncand = nchanged;
        if (passes > n + 1) {
            /* parent pointers close a cycle only if there is a negative one */
            for (int i = 0; i < ncand; i++) {
                int v = cand[i], steps = 0;
                while (v >= 0 && steps <= n) { v = pn[v]; steps++; }
                if (steps > n) return 1;
            }
        }
    }
    return 0;
}

/* ---------------------------------------------------------------- back-propagation and friends */
enum { OK = 0, NEED = 1, STARTED_HIT = 2 };

static int backprop(Net *g, int link, int *other) {
    int c = g->ctg[link], lc = g->lc[link];
    W delta = g->y[link] - g->x[link];
    W *p = g->p;
    W pc = p[c];
    int sid = ++g->sid;
    g->hsize = 0; g->nmoat = 0;
    g->stamp[c] = sid; g->key[c] = 0;
    if (hpush(g, 0, c)) return -1;
    while (g->hsize) {
        Item it = hpop(g);
        int v = it.node;
        if (g->done[v] == sid) continue;
        g->done[v] = sid;
        W d = it.key - p[v] + pc;
        g->dist[v] = d;
        if (d >= delta) { g->moat[g->nmoat++] = v; continue; }
        for (int l2 = g->act_first[v]; l2 >= 0; l2 = g->act_next[l2]) {
            if (g->status[l2] == STARTED) { *other = l2; return STARTED_HIT; }
            if (g->status[l2] == UNSTARTED) { *other = l2; return NEED; }
        }
        W pv = p[v];
        for (int e = g->in_head[v]; e >= 0; e = g->in_next[e]) {
            if (e == lc) continue;
            int u = g->src[e];
            W nk = it.key + g->w[e] + p[u] - pv;
            if (g->stamp[u] != sid || nk < g->key[u]) {
                g->stamp[u] = sid; g->key[u] = nk; g->pred[u] = e;
                if (hpush(g, nk, u)) return -1;
            }
        }
    }
    return OK;
}

static int internal(Net *g, int v, W delta) { return g->done[v] == g->sid && g->dist[v] < delta; }

/* 1 if the forward check finds the negative cycle, 0 if not, -1 memory */
static int forward_check(Net *g, int link) {
    int c = g->ctg[link];
    W delta = g->y[link] - g->x[link];
    int any = 0;
    for (int e = g->out_head[c]; e >= 0; e = g->out_next[e]) {
        int v = g->dst[e];
        if (v != c && internal(g, v, delta)) { any = 1; break; }
    }
    if (!any) return 0;
    W *p = g->p;
    W pc = p[c];
    int sid = ++g->fsid;
    g->hsize = 0;
    g->fstamp[c] = sid; g->fkey[c] = 0;
    if (hpush(g, 0, c)) return -1;
    while (g->hsize) {
        Item it = hpop(g);
        int v = it.node;
        if (g->fdone[v] == sid) continue;
        g->fdone[v] = sid;
        if (!internal(g, v, delta)) continue;
        if (it.key + p[v] - pc < 0) return 1;
        W pv = p[v];
        for (int e = g->out_head[v]; e >= 0; e = g->out_next[e]) {
            int u = g->dst[e];
            W nk = it.key + g->w[e] + pv - p[u];
            if (g->fstamp[u] != sid || nk < g->fkey[u]) {
                g->fstamp[u] = sid; g->fkey[u] = nk;
                if (hpush(g, nk, u)) return -1;
            }
        }
    }
    return 0;
}

/* 0 ok, 1 negative cycle, -1 memory; commits the new potential only on success */
static int update_potential(Net *g, int a) {
    W *p = g->p;
    W start = p[a];
    for (int e = g->in_head[a]; e >= 0; e = g->in_next[e]) {
        W cand = p[g->src[e]] + g->w[e];
        if (cand < start) start = cand;
    }
    if (start == p[a]) return 0;
    int sid = ++g->fsid;
    g->hsize = 0; g->ntouched = 0;
    g->fstamp[a] = sid; g->fkey[a] = start - p[a]; g->touched[g->ntouched++] = a;
    if (hpush(g, g->fkey[a], a)) return -1;
    while (g->hsize) {
        Item it = hpop(g);
        int v = it.node;
        if (g->fdone[v] == sid) continue;
        g->fdone[v] = sid;
        W pv = p[v];
        for (int e = g->out_head[v]; e >= 0; e = g->out_next[e]) {
            int u = g->dst[e];
            W nd = it.key + g->w[e] + pv - p[u];
            if (u == a) { if (nd < g->fkey[a]) return 1; continue; }
            W old = g->fstamp[u] == sid ? g->fkey[u] : 0;
            if (nd < old) {
                if (g->fstamp[u] != sid) { g->fstamp[u] = sid; g->touched[g->ntouched++] = u; }
                g->fkey[u] = nd;
                if (hpush(g, nd, u)) return -1;
            }
        }
    }
    for (int i = 0; i < g->ntouched; i++) p[g->touched[i]] += g->fkey[g->touched[i]];
    return 0;
}

/* 0 ok (link done), 1 not DC, -1 memory */
static int finish(Net *g, int link) {
    int a = g->act[link];
    W y = g->y[link];
    int added = 0;
    for (int i = 0; i < g->nmoat; i++) {
        int v = g->moat[i];
        W w = g->dist[v] - y;
        if (v == a) { if (w < 0) return 1; continue; }
        int better = hput_if_better(g, v, a, w);
        if (better < 0) return -1;
        if (better) { if (add_edge(g, v, a, w, DERIVED) < 0) return -1; added = 1; }
    }
    if (added) return update_potential(g, a);
    return 0;
}

/* links by decreasing key, then increasing index: a bottom-up merge sort (no global state, so calls from
 * several threads at once are safe; ctypes releases the GIL) */
static void sort_links(int *links, int *tmp, const W *keys, int k) {
    for (int width = 1; width < k; width *= 2) {
        for (int lo = 0; lo < k; lo += 2 * width) {
            int mid = lo + width < k ? lo + width : k, hi = lo + 2 * width < k ? lo + 2 * width : k;
            int i = lo, j = mid, o = lo;
            while (i < mid && j < hi) {
                int a = links[i], b = links[j];
                int first = keys[a] > keys[b] || (keys[a] == keys[b] && a < b);
                tmp[o++] = first ? links[i++] : links[j++];
            }
            while (i < mid) tmp[o++] = links[i++];
            while (j < hi) tmp[o++] = links[j++];
        }
        memcpy(links, tmp, sizeof(int) * (size_t)k);
    }
}

/* value i of a (low, high) pair of 64-bit arrays; without a high array the low one holds signed values */
static W join(const int64_t *lo, const int64_t *hi, int i) {
    if (!hi) return (W)lo[i];
    return (W)(((unsigned __int128)(uint64_t)hi[i] << 64) | (uint64_t)lo[i]);
}

static void free_nodes(Net *g) {
    free(g->in_head); free(g->out_head); free(g->act_first); free(g->p); free(g->stamp); free(g->done);
    free(g->pred); free(g->key); free(g->dist); free(g->fstamp); free(g->fdone); free(g->fkey); free(g->moat);
    free(g->touched); free(g->order); free(g->stack_node); free(g->stack_pos); free(g->color); free(g->negs);
    free(g->pedge); free(g->pnode); free(g->cand); free(g->mark);
}

static void free_links(Net *g) {
    free(g->x); free(g->y); free(g->lc); free(g->act_next); free(g->status); free(g->links); free(g->lkeys_tmp);
    free(g->stack); free(g->lkeys); free(g->own_act); free(g->own_ctg);
}

static void release(Net *g) {
    free_nodes(g);
    free_links(g);
    free(g->src); free(g->dst); free(g->in_next); free(g->out_next); free(g->w); free(g->kind); free(g->heap);
    free(g->hkeys); free(g->hvals);
}

/* Room for n nodes and k links: arrays made afresh (zeroed, so every stamp is older than any search)
 * when they are too small, kept otherwise. 0, or -1 when out of memory. */
static int reserve(Net *g, int n, int k) {
    int ok = 1;
#define ALLOC(field, count) do { g->field = calloc((size_t)(count) + 1, sizeof *g->field); if (!g->field) ok = 0; } while (0)
    if (n > g->ncap || !g->in_head) {
        free_nodes(g);
        int c = n > 16 ? n : 16;
        ALLOC(in_head, c); ALLOC(out_head, c); ALLOC(act_first, c); ALLOC(p, c); ALLOC(stamp, c); ALLOC(done, c);
        ALLOC(pred, c); ALLOC(key, c); ALLOC(dist, c); ALLOC(fstamp, c); ALLOC(fdone, c); ALLOC(fkey, c);
        ALLOC(moat, c); ALLOC(touched, c); ALLOC(order, c); ALLOC(stack_node, c); ALLOC(stack_pos, c);
        ALLOC(color, c); ALLOC(negs, c); ALLOC(pedge, c); ALLOC(pnode, c); ALLOC(cand, c); ALLOC(mark, c);
        g->ncap = c; g->sid = 0; g->fsid = 0;
    }
    if (ok && (k > g->kcap || !g->x)) {
        free_links(g);
        int c = k > 8 ? k : 8;
        ALLOC(x, c); ALLOC(y, c); ALLOC(lc, c); ALLOC(act_next, c); ALLOC(status, c); ALLOC(links, c);
        ALLOC(lkeys_tmp, c); ALLOC(stack, c); ALLOC(lkeys, c); ALLOC(own_act, c); ALLOC(own_ctg, c);
        g->kcap = c;
    }
#undef ALLOC
    if (!ok) return -1;
    if (!g->hcap2 && hgrow(g)) return -1;
    return 0;
}

HrcRul *hrc_rul_new(void) { return calloc(1, sizeof(Net)); }

void hrc_rul_free(HrcRul *g) {
    if (g) { release(g); free(g); }
}

int hrc_rul_begin(HrcRul *g, int n, int k) {
    if (n < 1 || k < 0 || reserve(g, n, k)) return -1;
    g->n = n; g->k = k; g->m = 0;
    for (int v = 0; v < n; v++) { g->in_head[v] = -1; g->out_head[v] = -1; g->act_first[v] = -1; }
    for (int l = 0; l < k; l++) g->status[l] = UNSTARTED;
    if (g->sid > INT_MAX / 2 || g->fsid > INT_MAX / 2) {  /* stamps wrap: start them again */
        memset(g->stamp, 0, sizeof *g->stamp * (size_t)(g->ncap + 1));
        memset(g->done, 0, sizeof *g->done * (size_t)(g->ncap + 1));
        memset(g->fstamp, 0, sizeof *g->fstamp * (size_t)(g->ncap + 1));
        memset(g->fdone, 0, sizeof *g->fdone * (size_t)(g->ncap + 1));
        g->sid = 0; g->fsid = 0;
    }
    memset(g->hkeys, 0xff, sizeof(int64_t) * (size_t)g->hcap2);  /* every slot -1: empty */
    g->hcount = 0;
    g->act = g->own_act; g->ctg = g->own_ctg;
    return 0;
}

int hrc_rul_edge(HrcRul *g, int s, int t, int64_t w) {
    if (add_edge(g, s, t, (W)w, ORD) < 0 || hput_if_better(g, s, t, (W)w) < 0) return -1;
    return 0;
}

void hrc_rul_link(HrcRul *g, int l, int a, int c, int64_t x, int64_t y) {
    g->own_act[l] = a; g->own_ctg[l] = c; g->x[l] = (W)x; g->y[l] = (W)y;
}

/* The check on the edges and links given since hrc_rul_begin (g->x, g->y, g->act, g->ctg set), step 1
 * starting from the potential p0 (NULL: all 0). Any start gives the same verdict; a feasible one (no edge
 * of the LO-graph and the pairs violated) makes step 1 a single pass over the edges. */
/* The links' edges (lower-case, and the pair of each link's bounds) and the links by activation. 0, or -1
 * out of memory. */
static int add_links(Net *g) {
    int k = g->k;
    const int *act = g->act, *ctg = g->ctg;
    for (int l = k - 1; l >= 0; l--) {
        g->act_next[l] = g->act_first[act[l]];
        g->act_first[act[l]] = l;
    }
    for (int l = 0; l < k; l++) {
        g->lc[l] = add_edge(g, act[l], ctg[l], g->x[l], LC);
        if (g->lc[l] < 0 || add_edge(g, act[l], ctg[l], g->y[l], PAIR) < 0 ||
            add_edge(g, ctg[l], act[l], -g->x[l], PAIR) < 0) return -1;
    }
    return 0;
}

/* Step 1 failed (the LO-graph and the pairs have a negative cycle): not DC; inconsistent when the
 * network without its lower-case edges has a negative cycle too. 1 or 2, -1 out of memory. */
static int not_dc(Net *g) {
    for (int v = 0; v < g->n; v++) g->p[v] = 0;
    int stn = potential(g, g->p, LC);
    return stn < 0 ? -1 : (stn ? 2 : 1);
}

static int run(Net *g, const int64_t *p0) {
    int n = g->n, k = g->k;
    const int *act = g->act;
    if (add_links(g)) return -1;
    /* step 1: one potential for the LO-graph and the pairs */
    for (int v = 0; v < n; v++) g->p[v] = p0 ? (W)p0[v] : 0;
    int r = potential(g, g->p, -1);
    if (r) return r < 0 ? -1 : not_dc(g);
    /* steps 2-5, links by decreasing potential of their activation */
    int *links = g->links, *stack = g->stack;
    for (int l = 0; l < k; l++) { links[l] = l; g->lkeys[l] = g->p[act[l]]; }
    sort_links(links, g->lkeys_tmp, g->lkeys, k);
    int result = 0;
    for (int i = 0; i < k && result == 0; i++) {
        int first = links[i];
        if (g->status[first] != UNSTARTED) continue;
        int top = 0;
        stack[0] = first; g->status[first] = STARTED;
        while (top >= 0 && result == 0) {
            int link = stack[top], other = -1;
            int out = backprop(g, link, &other);
            if (out < 0) { result = -1; break; }
            if (out == NEED) { g->status[other] = STARTED; stack[++top] = other; continue; }
            if (out == STARTED_HIT) { result = 1; break; }
            int f = forward_check(g, link);
            if (f) { result = f; break; }
            f = finish(g, link);
            if (f) { result = f; break; }
            g->status[link] = DONE;
            top--;
        }
    }
    return result;
}

int hrc_rul_run(HrcRul *g, const int64_t *p0) { return run(g, p0); }


int hrc_rul_verdict(int n, int m, const int *src, const int *dst, const int64_t *w_lo, const int64_t *w_hi,
                    int k, const int *act, const int *ctg, const int64_t *x_lo, const int64_t *x_hi,
                    const int64_t *y_lo, const int64_t *y_hi) {
    Net g;
    memset(&g, 0, sizeof g);
    int result = hrc_rul_begin(&g, n, k);
    g.act = act; g.ctg = ctg;
    for (int e = 0; e < m && result == 0; e++) {
        W w = join(w_lo, w_hi, e);
        if (add_edge(&g, src[e], dst[e], w, ORD) < 0 || hput_if_better(&g, src[e], dst[e], w) < 0) result = -1;
    }
    for (int l = 0; l < k && result == 0; l++) {
        g.x[l] = join(x_lo, x_hi, l);
        g.y[l] = join(y_lo, y_hi, l);
    }
    if (result == 0) result = run(&g, NULL);
    release(&g);
    return result;
}
