/* boxorder.c — front-to-back order of the ranks' boxes (boxorder.h). */
#include "boxorder.h"

#include <math.h>
#include <string.h>

void bo_boxes(const float *pos, uint64_t n, const uint16_t *part, int nparts,
              bo_box *box)
{
    for (int p = 0; p < nparts; p++)
        for (int a = 0; a < 3; a++) box[p].lo[a] = INFINITY, box[p].hi[a] = -INFINITY;
    for (uint64_t i = 0; i < n; i++) {
        if (part[i] >= nparts) continue;
        bo_box *b = &box[part[i]];
        for (int a = 0; a < 3; a++) {
            float v = pos[3 * i + (uint64_t)a];
            if (v < b->lo[a]) b->lo[a] = v;
            if (v > b->hi[a]) b->hi[a] = v;
        }
    }
}

static int empty(const bo_box *b)
{
    return !(b->lo[0] <= b->hi[0]);
}

/* dist2: squared distance from eye to the nearest point of b. */
static double dist2(const bo_box *b, const double eye[3])
{
    double s = 0;
    for (int a = 0; a < 3; a++) {
        double d = eye[a] < b->lo[a] ? b->lo[a] - eye[a] : eye[a] > b->hi[a] ? eye[a] - b->hi[a]
                                                                             : 0;
        s += d * d;
    }
    return s;
}

/* split: finds a plane along some axis with every box of idx[0..n) on one side; moves the
 * boxes on the eye's side to the front of idx and returns how many they are (0 < k < n), or 0
 * when no plane separates them. tmp: n ints. */
static int split(const bo_box *box, int *idx, int n, const double eye[3], int *tmp)
{
    for (int a = 0; a < 3; a++) {
        /* candidate planes: each box's upper face; c separates when every box lies below it
         * (hi <= c) or above it (lo >= c), with some on each side */
        for (int j = 0; j < n; j++) {
            double c = box[idx[j]].hi[a];
            int below = 0, ok = 1;
            for (int i = 0; i < n && ok; i++) {
                const bo_box *b = &box[idx[i]];
                if (b->hi[a] <= c) below++;
                else if (!(b->lo[a] >= c)) ok = 0;
            }
            if (!ok || below == 0 || below == n) continue;
            int eye_below = eye[a] < c;
            int k = 0, m = 0;
            for (int i = 0; i < n; i++) {
                int is_below = box[idx[i]].hi[a] <= c;
                if (is_below == eye_below) idx[k++] = idx[i];
                else tmp[m++] = idx[i];
            }
            memcpy(idx + k, tmp, (size_t)m * sizeof *idx);
            return k;
        }
    }
    return 0;
}

static int order_rec(const bo_box *box, int *idx, int n, const double eye[3], int *tmp)
{
    if (n <= 1) return 1;
    int k = split(box, idx, n, eye, tmp);
    if (k == 0) {
        /* no separating plane: nearest first (insertion sort, a handful of parts) */
        for (int i = 1; i < n; i++)
            for (int j = i; j > 0 && dist2(&box[idx[j]], eye) < dist2(&box[idx[j - 1]], eye);
                 j--) {
                int t = idx[j];
                idx[j] = idx[j - 1], idx[j - 1] = t;
            }
        return 0;
    }
    int e1 = order_rec(box, idx, k, eye, tmp);
    int e2 = order_rec(box, idx + k, n - k, eye, tmp);
    return e1 && e2;
}

int bo_order(const bo_box *box, int n, const double eye[3], int *order, int *scratch)
{
    /* the parts with points first, the empty ones (nothing to composite) after them */
    int k = 0;
    for (int p = 0; p < n; p++)
        if (!empty(&box[p])) order[k++] = p;
    for (int p = 0; p < n; p++)
        if (empty(&box[p])) order[k++] = p;
    int nonempty = 0;
    for (int p = 0; p < n; p++) nonempty += !empty(&box[p]);
    return order_rec(box, order, nonempty, eye, scratch);
}
