/*
 * The RUL2021-family DC verdict of _rulcore.c as a reusable workspace, for C callers in the same
 * library (the dispatcher's batch evaluation, hrc/dispatch/_dispatchcore.c) that check many small
 * networks in a row: one workspace, its arrays grown to the largest network seen and reused.
 *
 *     HrcRul *g = hrc_rul_new();
 *     hrc_rul_begin(g, n, k);                 n timepoints, k contingent links
 *     hrc_rul_edge(g, s, t, w);               T(t) - T(s) <= w, as often as there are edges
 *     hrc_rul_link(g, l, a, c, x, y);         link l: a --[x, y]--> c, for l = 0 .. k-1
 *     int verdict = hrc_rul_run(g, p0);       0 DC, 1 not DC, 2 inconsistent, -1 out of memory
 *     ...                                     begin again for the next network
 *     hrc_rul_free(g);
 *
 * p0: a starting potential, one value per timepoint, or NULL (all 0). The verdict does not depend on it;
 * a feasible one (p0[t] - p0[s] <= w on every edge, p0[c] - p0[a] = x on every link: a schedule with each
 * contingent duration at its lower bound) spares the check its first Bellman-Ford.
 * Weights are 64-bit here (the core computes in 128 bits, so no sum overflows). A workspace is not
 * shared between threads; several workspaces may run at once.
 */
#ifndef HRC_RULCORE_H
#define HRC_RULCORE_H

#include <stdint.h>

typedef struct HrcRul HrcRul;

HrcRul *hrc_rul_new(void);
void hrc_rul_free(HrcRul *g);
int hrc_rul_begin(HrcRul *g, int n, int k);
int hrc_rul_edge(HrcRul *g, int s, int t, int64_t w);
void hrc_rul_link(HrcRul *g, int l, int a, int c, int64_t x, int64_t y);
int hrc_rul_run(HrcRul *g, const int64_t *p0);

#endif
