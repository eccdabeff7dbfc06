/* scrapcut's compiled kernels: the neighbour searches of the per-frame perception, on clouds
 * of a few thousand points, where a k-d tree's per-query cost dominates.
 *
 * Points are hashed into a uniform grid of cubic cells. For the k nearest neighbours, the
 * points of one cell share one candidate list, the points of the 27 cells around it; a point
 * whose k-th nearest candidate is no farther than that block's nearest open face has its k
 * nearest, the others search shell by shell (Chebyshev shells of cells around their own) until
 * the same holds, or scan every point when that would take many shells (an outlier far from
 * the rest). The neighbours are exact whatever the cell size, which only sets the speed; when
 * an eighth of the points need the shells (a dense knot in a sparse cloud: no one cell size
 * suits both) the kernel declines and the caller uses a k-d tree.
 *
 * Built by pip with the package (setup.py: an optional extension); scrapcut_cli/_kernels.py
 * is the Python interface and falls back to open3d / scipy when this did not build.
 *
 * Floating point: every distance is computed as ((dx*dx + dy*dy) + dz*dz) in double precision
 * and setup.py builds with -ffp-contract=off, so no fused multiply-add changes a rounding.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* Shells beyond this many are not searched: the query scans every point instead. */
#define MAX_SHELLS 3

typedef struct {
    int64_t x, y, z;
    Py_ssize_t start, count;
    int used;
} Cell;

typedef struct {
    Cell *cells;
    size_t mask; /* capacity - 1, capacity a power of two */
    double origin[3];
    double size;
    int64_t lo[3], hi[3]; /* occupied cell range */
    double *sorted;       /* the points, cell by cell, (N, 3) */
    Py_ssize_t n;
} Grid;

static size_t cell_hash(int64_t x, int64_t y, int64_t z) {
    uint64_t h = (uint64_t)x * 0x9E3779B97F4A7C15ULL;
    h ^= (uint64_t)y * 0xC2B2AE3D27D4EB4FULL;
    h ^= (uint64_t)z * 0x165667B19E3779F9ULL;
    h ^= h >> 29;
    return (size_t)h;
}

/* The slot of cell (x, y, z): the cell's, or the empty slot where it would go. */
static Cell *grid_slot(const Grid *g, int64_t x, int64_t y, int64_t z) {
    size_t i = cell_hash(x, y, z) & g->mask;
    for (;;) {
        Cell *c = &g->cells[i];
        if (!c->used || (c->x == x && c->y == y && c->z == z)) {
            return c;
        }
        i = (i + 1) & g->mask;
    }
}

/* The cell of p. Indices are clamped to +-2^62 (a cell tiny against the spread): clamping is
 * monotonic, so points within a cell of each other stay within a cell. */
static void cell_of(const Grid *g, const double *p, int64_t out[3]) {
    for (int a = 0; a < 3; a++) {
        double t = floor((p[a] - g->origin[a]) / g->size);
        out[a] = (int64_t)fmax(fmin(t, 4611686018427387904.0), -4611686018427387904.0);
    }
}

static void grid_free(Grid *g) {
    free(g->cells);
    free(g->sorted);
    g->cells = NULL;
    g->sorted = NULL;
}

/* Build the grid of n points (n, 3) with cubic cells of side size. 0, or -1 out of memory. */
static int grid_build(Grid *g, const double *pts, Py_ssize_t n, double size,
                      Py_ssize_t *index) {
    size_t capacity = 16;
    while (capacity < 2 * (size_t)n) {
        capacity <<= 1;
    }
    memset(g, 0, sizeof(*g));
    g->n = n;
    g->size = size;
    g->mask = capacity - 1;
    g->cells = calloc(capacity, sizeof(Cell));
    g->sorted = malloc(sizeof(double) * 3 * (size_t)(n > 0 ? n : 1));
    Cell **slot_of = malloc(sizeof(Cell *) * (size_t)(n > 0 ? n : 1));
    if (g->cells == NULL || g->sorted == NULL || slot_of == NULL) {
        free(slot_of);
        grid_free(g);
        return -1;
    }
    for (int a = 0; a < 3; a++) {
        g->origin[a] = n > 0 ? pts[a] : 0.0;
    }
    for (Py_ssize_t i = 1; i < n; i++) {
        for (int a = 0; a < 3; a++) {
            if (pts[3 * i + a] < g->origin[a]) {
                g->origin[a] = pts[3 * i + a];
            }
        }
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        int64_t c[3];
        cell_of(g, &pts[3 * i], c);
        Cell *cell = grid_slot(g, c[0], c[1], c[2]);
        if (!cell->used) {
            cell->used = 1;
            cell->x = c[0];
            cell->y = c[1];
            cell->z = c[2];
        }
        cell->count++;
        slot_of[i] = cell;
        for (int a = 0; a < 3; a++) {
            if (i == 0 || c[a] < g->lo[a]) {
                g->lo[a] = c[a];
            }
            if (i == 0 || c[a] > g->hi[a]) {
                g->hi[a] = c[a];
            }
        }
    }
    Py_ssize_t start = 0;
    for (size_t s = 0; s < capacity; s++) {
        if (g->cells[s].used) {
            g->cells[s].start = start;
            start += g->cells[s].count;
            g->cells[s].count = 0; /* refilled below */
        }
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        Cell *cell = slot_of[i];
        Py_ssize_t at = cell->start + cell->count;
        double *dst = &g->sorted[3 * at];
        if (index != NULL) {
            index[at] = i;
        }
        dst[0] = pts[3 * i];
        dst[1] = pts[3 * i + 1];
        dst[2] = pts[3 * i + 2];
        cell->count++;
    }
    free(slot_of);
    return 0;
}

static double squared_distance(const double *a, const double *b) {
    double dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
    return (dx * dx + dy * dy) + dz * dz;
}

/* Keep the k smallest values offered in best[0..*count), ascending. */
static inline void offer(double *best, int k, int *count, double d2) {
    int n = *count, at = 0;
    for (int j = 0; j < n; j++) {
        at += best[j] <= d2; /* no branch: the place among the values kept */
    }
    if (n == k) {
        if (at == k) {
            return;
        }
        n = k - 1;
    } else {
        (*count)++;
    }
    memmove(&best[at + 1], &best[at], sizeof(double) * (size_t)(n - at));
    best[at] = d2;
}

/* How far q (in cell c) is from the nearest face of the block of cells within r of c behind
 * which the grid has points, less the cell index's rounding; INFINITY when the block holds
 * every point. */
static double block_reach(const Grid *g, const double *q, const int64_t c[3], int r) {
    double reach = INFINITY;
    for (int a = 0; a < 3; a++) {
        if (c[a] - r > g->lo[a]) {
            reach = fmin(reach, q[a] - (g->origin[a] + (double)(c[a] - r) * g->size));
        }
        if (c[a] + r < g->hi[a]) {
            reach = fmin(reach, (g->origin[a] + (double)(c[a] + r + 1) * g->size) - q[a]);
        }
    }
    return isfinite(reach) ? reach - 1e-7 * g->size : reach;
}

/* The k nearest squared distances of q among the grid's points (q itself included when it is
 * one of them), ascending, into best; returns how many (min(k, n)). Shell by shell. */
static int nearest(const Grid *g, const double *q, int k, double *best) {
    int64_t c[3];
    int count = 0;
    cell_of(g, q, c);
    for (int r = 0; r <= MAX_SHELLS; r++) {
        for (int64_t x = c[0] - r; x <= c[0] + r; x++) {
            if (x < g->lo[0] || x > g->hi[0]) {
                continue;
            }
            for (int64_t y = c[1] - r; y <= c[1] + r; y++) {
                if (y < g->lo[1] || y > g->hi[1]) {
                    continue;
                }
                /* on the shell: every z where x or y is on it, else its two ends */
                int64_t step = (llabs(x - c[0]) == r || llabs(y - c[1]) == r) ? 1 : 2 * r;
                for (int64_t z = c[2] - r; z <= c[2] + r; z += step) {
                    if (z < g->lo[2] || z > g->hi[2]) {
                        continue;
                    }
                    const Cell *cell = grid_slot(g, x, y, z);
                    const double *p = &g->sorted[3 * cell->start];
                    for (Py_ssize_t j = 0; cell->used && j < cell->count; j++, p += 3) {
                        offer(best, k, &count, squared_distance(q, p));
                    }
                }
            }
        }
        double reach = block_reach(g, q, c, r);
        if (!isfinite(reach) || (count == k && reach > 0 && best[k - 1] <= reach * reach)) {
            return count;
        }
    }
    count = 0; /* far from the rest: scan everything */
    for (Py_ssize_t j = 0; j < g->n; j++) {
        offer(best, k, &count, squared_distance(q, &g->sorted[3 * j]));
    }
    return count;
}

/* The 27 cells of a block around a cell: the cell itself first. */
static const int BLOCK[27][3] = {
    {0, 0, 0},    {-1, 0, 0},  {1, 0, 0},   {0, -1, 0},  {0, 1, 0},   {0, 0, -1},  {0, 0, 1},
    {-1, -1, 0},  {-1, 0, -1}, {-1, 0, 1},  {-1, 1, 0},  {0, -1, -1}, {0, -1, 1},  {0, 1, -1},
    {0, 1, 1},    {1, -1, 0},  {1, 0, -1},  {1, 0, 1},   {1, 1, 0},   {-1, -1, -1}, {-1, -1, 1},
    {-1, 1, -1},  {-1, 1, 1},  {1, -1, -1}, {1, -1, 1},  {1, 1, -1},  {1, 1, 1},
};

/* Exchange d[a] with d[b] and idx[a] with idx[b]. */
static inline void swap_pair(double *d, int *idx, Py_ssize_t a, Py_ssize_t b) {
    double t = d[a];
    int u = idx[a];
    d[a] = d[b];
    idx[a] = idx[b];
    d[b] = t;
    idx[b] = u;
}

/* Rearrange d[0..m) (and idx alike) so that d[0..k) holds its k smallest values, in any
 * order: quickselect with a median-of-three pivot. */
static void select_smallest(double *d, int *idx, Py_ssize_t m, Py_ssize_t k) {
    Py_ssize_t lo = 0, hi = m - 1;
    while (hi > lo) {
        Py_ssize_t mid = lo + (hi - lo) / 2;
        if (d[mid] < d[lo]) swap_pair(d, idx, mid, lo);
        if (d[hi] < d[lo]) swap_pair(d, idx, hi, lo);
        if (d[hi] < d[mid]) swap_pair(d, idx, hi, mid);
        double pivot = d[mid];
        Py_ssize_t i = lo, j = hi;
        while (i <= j) {
            while (d[i] < pivot) i++;
            while (d[j] > pivot) j--;
            if (i <= j) {
                swap_pair(d, idx, i, j);
                i++;
                j--;
            }
        }
        if (k - 1 <= j) {
            hi = j;
        } else if (k - 1 >= i) {
            lo = i;
        } else {
            return;
        }
    }
}

/* Sort v[0..n) ascending (insertion: n is k, a few tens). */
static void sort_small(double *v, int n) {
    for (int i = 1; i < n; i++) {
        double x = v[i];
        int j = i;
        while (j > 0 && v[j - 1] > x) {
            v[j] = v[j - 1];
            j--;
        }
        v[j] = x;
    }
}

/* Every grid point's mean distance to its k nearest grid points (itself among them), summed
 * in ascending order as open3d does, into means[index[i]] (index: grid_build's). 0; -1 out
 * of memory; 1 when too many points (an eighth) lie too far apart for the cell, which a cloud
 * of dense and sparse parts does (a k-d tree is then faster: the caller takes one). */
static int mean_distances(const Grid *g, int k, const Py_ssize_t *index, double *means) {
    Py_ssize_t far = 0, far_limit = g->n / 8 + 16;
    Py_ssize_t capacity = 0;
    double *cand = NULL, *dist = NULL, *best = malloc(sizeof(double) * (size_t)k);
    int *idx = NULL, *prev_best = malloc(sizeof(int) * (size_t)k);
    int failed = best == NULL || prev_best == NULL;
    for (size_t s = 0; s <= g->mask && !failed; s++) {
        const Cell *home = &g->cells[s];
        if (!home->used) {
            continue;
        }
        /* The candidates: the points of the 27 cells around this one. */
        const Cell *block[27];
        Py_ssize_t m = 0;
        for (int o = 0; o < 27; o++) {
            block[o] = grid_slot(g, home->x + BLOCK[o][0], home->y + BLOCK[o][1],
                                 home->z + BLOCK[o][2]);
            m += block[o]->used ? block[o]->count : 0;
        }
        if (m > capacity) {
            free(cand);
            free(dist);
            free(idx);
            capacity = 2 * m;
            cand = malloc(sizeof(double) * 3 * (size_t)capacity);
            dist = malloc(sizeof(double) * (size_t)capacity);
            idx = malloc(sizeof(int) * (size_t)capacity);
            if (cand == NULL || dist == NULL || idx == NULL) {
                failed = 1;
                break;
            }
        }
        m = 0;
        for (int o = 0; o < 27; o++) {
            if (block[o]->used) {
                memcpy(&cand[3 * m], &g->sorted[3 * block[o]->start],
                       sizeof(double) * 3 * (size_t)block[o]->count);
                m += block[o]->count;
            }
        }
        int64_t c[3] = {home->x, home->y, home->z};
        int have_prev = 0; /* prev_best: the previous point's k nearest candidates */
        for (Py_ssize_t i = home->start; i < home->start + home->count; i++) {
            const double *q = &g->sorted[3 * i];
            /* The previous point's k nearest are k points: q's k-th nearest is no farther
             * than the farthest of them from q, and nothing farther needs sorting. */
            double bound = INFINITY;
            if (have_prev) {
                bound = 0.0;
                for (int j = 0; j < k; j++) {
                    bound = fmax(bound, squared_distance(q, &cand[3 * prev_best[j]]));
                }
            }
            Py_ssize_t nd = 0;
            for (Py_ssize_t j = 0; j < m; j++) {
                double d2 = squared_distance(q, &cand[3 * j]);
                dist[nd] = d2;
                idx[nd] = (int)j;
                nd += d2 <= bound;
            }
            int count = nd < k ? (int)nd : k;
            if (nd > k) {
                select_smallest(dist, idx, nd, k);
            }
            memcpy(best, dist, sizeof(double) * (size_t)count);
            sort_small(best, count);
            have_prev = count == k;
            if (have_prev) {
                memcpy(prev_best, idx, sizeof(int) * (size_t)k);
            }
            double reach = block_reach(g, q, c, 1);
            if (isfinite(reach) && !(count == k && reach > 0 && best[k - 1] <= reach * reach)) {
                if (++far > far_limit) {
                    failed = 1;
                    break;
                }
                count = nearest(g, q, k, best);
            }
            double sum = 0.0;
            for (int j = 0; j < count; j++) {
                sum += sqrt(best[j]);
            }
            means[index[i]] = count > 0 ? sum / count : -1.0;
        }
    }
    free(cand);
    free(dist);
    free(idx);
    free(best);
    free(prev_best);
    return failed ? (far > far_limit ? 1 : -1) : 0;
}

/* A grid cell for the k-nearest search of these n points: 1.25 times the median distance to
 * the k-th nearest of 5 of them spread through the array (found by scanning every point), so
 * that most points' k nearest lie in the 27 cells around their own (1 to 2 times the median
 * measured alike on frames' paint clouds; more samples cost more than they gain). Only the
 * speed depends on it. dist (n) and idx (n) are scratch. */
static double cell_for(const double *pts, Py_ssize_t n, int k, double *dist, int *idx) {
    double kth[5];
    int samples = 0;
    Py_ssize_t want = k < n ? k : n;
    for (Py_ssize_t s = 0; s < n && samples < 5; s += n / 5 + 1) {
        for (Py_ssize_t j = 0; j < n; j++) {
            dist[j] = squared_distance(&pts[3 * s], &pts[3 * j]);
            idx[j] = 0;
        }
        select_smallest(dist, idx, n, want);
        double worst = 0.0;
        for (Py_ssize_t j = 0; j < want; j++) {
            worst = fmax(worst, dist[j]);
        }
        kth[samples++] = sqrt(worst);
    }
    sort_small(kth, samples);
    double cell = samples > 0 ? 1.25 * kth[samples / 2] : 0.0;
    /* The cloud's extent bounds the cell below, keeping cell indices far inside 64 bits. */
    double extent = 0.0;
    for (int a = 0; a < 3; a++) {
        double lo = INFINITY, hi = -INFINITY;
        for (Py_ssize_t i = 0; i < n; i++) {
            lo = fmin(lo, pts[3 * i + a]);
            hi = fmax(hi, pts[3 * i + a]);
        }
        extent = fmax(extent, hi - lo);
    }
    cell = fmax(cell, extent * 1e-9);
    return cell > 0 ? cell : 1.0;
}

/* statistical_inliers(points, k, std_ratio, out) -> kept, or -1 declined (mean_distances)
 *
 * points: C-contiguous float64 (N, 3), finite; out: writable uint8 (N,), set to 1 for a kept
 * point. open3d's statistical outlier removal: the mean distance of each point to its k
 * nearest points (itself included), the cloud's mean m of those means (the positive ones
 * summed, divided by N) and their deviation s (divided by N - 1); a point is kept when its
 * mean is positive and below m + std_ratio * s.
 */
static PyObject *statistical_inliers(PyObject *self, PyObject *args) {
    Py_buffer points, out;
    int k;
    double std_ratio;
    if (!PyArg_ParseTuple(args, "y*idw*", &points, &k, &std_ratio, &out)) {
        return NULL;
    }
    PyObject *result = NULL;
    Py_ssize_t n = points.len / (Py_ssize_t)(3 * sizeof(double));
    double *means = NULL;
    int *idx = NULL;
    Py_ssize_t *index = NULL;
    Grid grid;
    memset(&grid, 0, sizeof(grid));
    if (points.len != n * (Py_ssize_t)(3 * sizeof(double)) || out.len != n) {
        PyErr_SetString(PyExc_ValueError, "points must be (N, 3) float64 and out (N,) uint8");
        goto done;
    }
    if (k < 1) {
        PyErr_SetString(PyExc_ValueError, "k must be positive");
        goto done;
    }
    if (n == 0) {
        result = PyLong_FromSsize_t(0);
        goto done;
    }
    const double *pts = (const double *)points.buf;
    unsigned char *keep = (unsigned char *)out.buf;
    means = malloc(sizeof(double) * (size_t)n);
    idx = malloc(sizeof(int) * (size_t)n);
    index = malloc(sizeof(Py_ssize_t) * (size_t)n);
    if (means == NULL || idx == NULL || index == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    Py_ssize_t kept = 0;
    int status = 0;
    Py_BEGIN_ALLOW_THREADS;
    double size = cell_for(pts, n, k, means, idx);
    status = grid_build(&grid, pts, n, size, index);
    if (status == 0) {
        status = mean_distances(&grid, k, index, means);
    }
    if (status == 0) {
        double mean = 0.0, squares = 0.0;
        for (Py_ssize_t i = 0; i < n; i++) {
            if (means[i] > 0) {
                mean += means[i];
            }
        }
        mean /= (double)n;
        for (Py_ssize_t i = 0; i < n; i++) {
            if (means[i] > 0) {
                squares += (means[i] - mean) * (means[i] - mean);
            }
        }
        double threshold = mean + std_ratio * sqrt(squares / (double)(n - 1));
        for (Py_ssize_t i = 0; i < n; i++) {
            keep[i] = means[i] > 0 && means[i] < threshold;
            kept += keep[i];
        }
    }
    Py_END_ALLOW_THREADS;
    if (status < 0) {
        PyErr_NoMemory();
        goto done;
    }
    result = PyLong_FromSsize_t(status == 0 ? kept : -1);
done:
    grid_free(&grid);
    free(means);
    free(idx);
    free(index);
    PyBuffer_Release(&points);
    PyBuffer_Release(&out);
    return result;
}

/* within_distance(points, targets, radius, out) -> count
 *
 * points (N, 3) and targets (M, 3): C-contiguous float64; out: writable uint8 (N,), set to 1
 * for a point closer than radius to some target (squared distance < radius * radius, as
 * scipy's cKDTree.query with distance_upper_bound), else 0. Returns how many are set.
 */
static PyObject *within_distance(PyObject *self, PyObject *args) {
    Py_buffer points, targets, out;
    double radius;
    if (!PyArg_ParseTuple(args, "y*y*dw*", &points, &targets, &radius, &out)) {
        return NULL;
    }
    PyObject *result = NULL;
    Py_ssize_t n = points.len / (Py_ssize_t)(3 * sizeof(double));
    Py_ssize_t m = targets.len / (Py_ssize_t)(3 * sizeof(double));
    Grid grid;
    memset(&grid, 0, sizeof(grid));
    if (points.len != n * (Py_ssize_t)(3 * sizeof(double)) ||
        targets.len != m * (Py_ssize_t)(3 * sizeof(double)) || out.len != n) {
        PyErr_SetString(PyExc_ValueError,
                        "points and targets must be (N, 3) float64 and out (N,) uint8");
        goto done;
    }
    if (!(radius > 0) || !isfinite(radius)) {
        PyErr_SetString(PyExc_ValueError, "radius must be a positive size");
        goto done;
    }
    const double *pts = (const double *)points.buf;
    unsigned char *hit = (unsigned char *)out.buf;
    memset(hit, 0, (size_t)n);
    if (m == 0) {
        result = PyLong_FromSsize_t(0);
        goto done;
    }
    double r2 = radius * radius;
    Py_ssize_t count = 0;
    int failed = 0;
    Py_BEGIN_ALLOW_THREADS;
    if (grid_build(&grid, (const double *)targets.buf, m, radius, NULL) != 0) {
        failed = 1;
    } else {
        for (Py_ssize_t i = 0; i < n; i++) {
            const double *q = &pts[3 * i];
            int64_t c[3];
            cell_of(&grid, q, c);
            int near = 1;
            for (int a = 0; a < 3; a++) {
                near &= c[a] >= grid.lo[a] - 1 && c[a] <= grid.hi[a] + 1;
            }
            /* a target closer than radius lies in the 27 cells around the point's */
            for (int o = 0; near && o < 27 && !hit[i]; o++) {
                const Cell *cell =
                    grid_slot(&grid, c[0] + BLOCK[o][0], c[1] + BLOCK[o][1], c[2] + BLOCK[o][2]);
                if (!cell->used) {
                    continue;
                }
                const double *p = &grid.sorted[3 * cell->start];
                for (Py_ssize_t j = 0; j < cell->count; j++, p += 3) {
                    if (squared_distance(q, p) < r2) {
                        hit[i] = 1;
                        break;
                    }
                }
            }
            count += hit[i];
        }
    }
    Py_END_ALLOW_THREADS;
    if (failed) {
        PyErr_NoMemory();
        goto done;
    }
    result = PyLong_FromSsize_t(count);
done:
    grid_free(&grid);
    PyBuffer_Release(&points);
    PyBuffer_Release(&targets);
    PyBuffer_Release(&out);
    return result;
}

static PyMethodDef methods[] = {
    {"statistical_inliers", statistical_inliers, METH_VARARGS,
     "statistical_inliers(points, k, std_ratio, out) -> number kept, -1 declined"},
    {"within_distance", within_distance, METH_VARARGS,
     "within_distance(points, targets, radius, out) -> number within"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_native", "scrapcut's compiled kernels (see _kernels.py).", -1,
    methods,
};

PyMODINIT_FUNC PyInit__native(void) { return PyModule_Create(&module); }
