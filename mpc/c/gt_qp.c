/* Dense strictly convex QP: the dual active-set method of
 *   D. Goldfarb & A. Idnani (1983), "A numerically stable dual method for solving strictly
 *   convex quadratic programs", Mathematical Programming 27, 1-33,
 * in the factorised form of their section 4: H = L L', J = L^-T Q, R upper triangular with
 * J' N = [R; 0] for the active normals N; constraints are added and dropped by Givens rotations
 * (Gill, Golub, Murray & Saunders 1974, Math. Comp. 28, 505-535). Each step: pick the most
 * violated constraint p (violation over its normal's norm), step in the primal direction
 * z = J2 J2' n_p and the dual direction r = R^-1 J1' n_p, full step when no active multiplier
 * reaches zero first, else drop that constraint and retry (the paper's steps 1-3).
 * Equality constraints are added first and never dropped. No allocation.
 */
#include "gt_qp.h"

#include <math.h>
#include <string.h>

/* violation test: c'x - b < -GT_QP_TOL (1 + |b|), on the normal scaled to unit length */
#define GT_QP_TOL 1e-10
/* a new normal whose part outside the active span is below this is dependent */
#define GT_QP_DEP_TOL 1e-12

typedef struct {
    int n, m;
    const double *A, *lba, *uba, *lbx, *ubx;
} prob_t;

long gt_qp_work_size(int n, int m) { return 2L * n * n + 6L * n + 2L * m + 2L * (n + m) + 2; }
long gt_qp_iwork_size(int n, int m) { return 2L * n + 2L * (n + m) + 2; }

/* constraint c in [0, 2(n+m)): bound or row c/2, lower side (c even, normal +a, b = lb) or
 * upper side (c odd, normal -a, b = -ub) */
static double cons_b(const prob_t *P, int c) {
    int i = c / 2, up = c % 2;
    double lb = i < P->n ? P->lbx[i] : P->lba[i - P->n];
    double ub = i < P->n ? P->ubx[i] : P->uba[i - P->n];
    return up ? -ub : lb;
}

static int cons_present(const prob_t *P, int c) {
    int i = c / 2, up = c % 2;
    double lb = i < P->n ? P->lbx[i] : P->lba[i - P->n];
    double ub = i < P->n ? P->ubx[i] : P->uba[i - P->n];
    if (up && lb == ub) return 0; /* an equality is its lower side only */
    return fabs(up ? ub : lb) < GT_QP_INF;
}

static int cons_is_eq(const prob_t *P, int c) {
    int i = c / 2;
    double lb = i < P->n ? P->lbx[i] : P->lba[i - P->n];
    double ub = i < P->n ? P->ubx[i] : P->uba[i - P->n];
    return c % 2 == 0 && lb == ub;
}

static void cons_normal(const prob_t *P, int c, double *v) {
    int i = c / 2, k;
    double sgn = c % 2 ? -1.0 : 1.0;
    if (i < P->n) {
        memset(v, 0, sizeof(double) * P->n);
        v[i] = sgn;
    } else {
        for (k = 0; k < P->n; ++k) v[k] = sgn * P->A[(i - P->n) + (long)P->m * k];
    }
}

/* s = c'x - b for every constraint (ax: A x, precomputed) */
static double cons_slack(const prob_t *P, int c, const double *x, const double *ax) {
    int i = c / 2;
    double v = i < P->n ? x[i] : ax[i - P->n];
    return (c % 2 ? -v : v) - cons_b(P, c);
}

/* Cholesky H + reg I = L L' (lower, column-major in l); returns 0 unless not positive definite */
static int cholesky(int n, const double *H, double reg, double *l) {
    int i, j, k;
    for (j = 0; j < n; ++j) {
        double s = H[j + n * j] + reg;
        for (k = 0; k < j; ++k) s -= l[j + n * k] * l[j + n * k];
        if (!(s > 0.0)) return 1;
        l[j + n * j] = sqrt(s);
        for (i = j + 1; i < n; ++i) {
            double t = H[i + n * j];
            for (k = 0; k < j; ++k) t -= l[i + n * k] * l[j + n * k];
            l[i + n * j] = t / l[j + n * j];
        }
        for (i = 0; i < j; ++i) l[i + n * j] = 0.0;
    }
    return 0;
}

/* J = L^-T in place of L (L^-1 by forward substitution, column by column, then transposed) */
static void inverse_transpose(int n, double *l, double *tmp) {
    int i, j, k;
    for (j = 0; j < n; ++j) { /* column j of L^-1 into tmp (n x n) */
        for (i = 0; i < n; ++i) {
            double s = (i == j) ? 1.0 : 0.0;
            for (k = j; k < i; ++k) s -= l[i + n * k] * tmp[k + n * j];
            tmp[i + n * j] = i < j ? 0.0 : s / l[i + n * i];
        }
    }
    for (j = 0; j < n; ++j)
        for (i = 0; i < n; ++i) l[i + n * j] = tmp[j + n * i];
}

static void givens(double a, double b, double *c, double *s, double *h) {
    *h = hypot(a, b);
    if (*h == 0.0) { *c = 1.0; *s = 0.0; return; }
    *c = a / *h;
    *s = b / *h;
}

/* columns j0, j1 of J (n rows) <- (c J0 + s J1, -s J0 + c J1) */
static void rotate_cols(int n, double *J, int j0, int j1, double c, double s) {
    int i;
    double *a = J + (long)n * j0, *b = J + (long)n * j1;
    for (i = 0; i < n; ++i) {
        double t = a[i];
        a[i] = c * t + s * b[i];
        b[i] = -s * t + c * b[i];
    }
}

/* add the normal with d = J' n as active column q: zero d[q+1..n-1] by rotations of J */
static int add_constraint(int n, double *J, double *R, double *d, int q) {
    int j, i;
    double c, s, h;
    for (j = n - 1; j > q; --j) {
        if (d[j] == 0.0) continue;
        givens(d[j - 1], d[j], &c, &s, &h);
        d[j - 1] = h;
        d[j] = 0.0;
        rotate_cols(n, J, j - 1, j, c, s);
    }
    for (i = 0; i <= q; ++i) R[i + n * q] = d[i];
    return fabs(d[q]) > GT_QP_DEP_TOL;
}

/* drop active column l of q: shift R's columns, restore the triangle by rotations of rows
 * (l, l+1), ... and the same rotations of J's columns */
static void drop_constraint(int n, double *J, double *R, int *act, int *flip, double *u, int q, int l) {
    int j, k;
    double c, s, h;
    for (j = l; j < q - 1; ++j) {
        act[j] = act[j + 1];
        flip[j] = flip[j + 1];
        u[j] = u[j + 1];
        for (k = 0; k < n; ++k) R[k + n * j] = R[k + n * (j + 1)];
    }
    u[q - 1] = u[q]; /* the multiplier of the constraint being added moves down */
    for (j = l; j < q - 1; ++j) {
        givens(R[j + n * j], R[(j + 1) + n * j], &c, &s, &h);
        R[j + n * j] = h;
        R[(j + 1) + n * j] = 0.0;
        for (k = j + 1; k < q - 1; ++k) {
            double a = R[j + n * k], b = R[(j + 1) + n * k];
            R[j + n * k] = c * a + s * b;
            R[(j + 1) + n * k] = -s * a + c * b;
        }
        rotate_cols(n, J, j, j + 1, c, s);
    }
    for (k = 0; k < n; ++k) R[k + n * (q - 1)] = 0.0;
}

/* d = J' v (J: n x n, column-major) */
static void jt_times(int n, const double *J, const double *v, double *d) {
    int i, j;
    for (j = 0; j < n; ++j) {
        double s = 0.0;
        for (i = 0; i < n; ++i) s += J[i + n * j] * v[i];
        d[j] = s;
    }
}

/* out = J[:, q:] d[q:] */
static void j_times_from(int n, const double *J, const double *d, int q, double *out) {
    int i, j;
    for (i = 0; i < n; ++i) {
        double s = 0.0;
        for (j = q; j < n; ++j) s += J[i + n * j] * d[j];
        out[i] = s;
    }
}

/* 0 unless H, g or A holds a nan or an infinity or a bound is nan (an infinite bound is absent) */
static int data_not_finite(int n, int m, const double *H, const double *g, const double *A,
                           const double *lba, const double *uba, const double *lbx, const double *ubx) {
    long i;
    for (i = 0; i < (long)n * n; ++i) if (!isfinite(H[i])) return 1;
    for (i = 0; i < (long)m * n; ++i) if (!isfinite(A[i])) return 1;
    for (i = 0; i < n; ++i) if (!isfinite(g[i]) || isnan(lbx[i]) || isnan(ubx[i])) return 1;
    for (i = 0; i < m; ++i) if (isnan(lba[i]) || isnan(uba[i])) return 1;
    return 0;
}

int gt_qp_solve(int n, int m, const double *H, const double *g, const double *A,
                const double *lba, const double *uba, const double *lbx, const double *ubx,
                double *x, double *lam, int *iter, int max_iter, double *work, int *iwork) {
    prob_t P = {n, m, A, lba, uba, lbx, ubx};
    int nc = 2 * (n + m), q = 0, i, j, k, status = GT_QP_OK, it = 0;
    double *J = work, *R = J + (long)n * n, *d = R + (long)n * n, *z = d + n, *r = z + n;
    double *np_ = r + n, *u = np_ + n, *ax = u + n + 1, *cnorm = ax + m;
    int *act = iwork, *act_flip = act + n, *is_active = act_flip + n;
    if (data_not_finite(n, m, H, g, A, lba, uba, lbx, ubx)) {
        if (iter) *iter = 0;
        return GT_QP_NOT_FINITE;
    }
    if (cholesky(n, H, 0.0, J)) { /* semi-definite to rounding: regularise once, reported */
        double dmax = 0.0;
        for (i = 0; i < n; ++i) dmax = H[i + n * i] > dmax ? H[i + n * i] : dmax;
        if (!(dmax > 0.0) || cholesky(n, H, GT_QP_REG * dmax, J)) {
            if (iter) *iter = 0;
            return GT_QP_NOT_CONVEX;
        }
        status = GT_QP_REGULARISED;
    }
    inverse_transpose(n, J, R); /* R's space is the scratch of the inverse */
    memset(R, 0, sizeof(double) * n * n);
    /* unconstrained minimum x = -J J' g */
    jt_times(n, J, g, d);
    j_times_from(n, J, d, 0, x);
    for (i = 0; i < n; ++i) x[i] = -x[i];
    for (k = 0; k < nc; ++k) {
        is_active[k] = 0;
        if (k / 2 < n) cnorm[k] = 1.0;
        else {
            double s = 0.0;
            for (i = 0; i < n; ++i) s += A[(k / 2 - n) + (long)m * i] * A[(k / 2 - n) + (long)m * i];
            cnorm[k] = s > 0.0 ? sqrt(s) : 1.0;
        }
    }
    for (;;) {
        /* step 1: the most violated constraint (equalities first, in order) */
        int p = -1, eq = 0, flip = 1;
        double smin = 0.0, sp, bp;
        for (j = 0; j < m; ++j) {
            double s = 0.0;
            for (i = 0; i < n; ++i) s += A[j + (long)m * i] * x[i];
            ax[j] = s;
        }
        for (k = 0; k < nc && p < 0; ++k)
            if (cons_present(&P, k) && cons_is_eq(&P, k) && !is_active[k]) { p = k; eq = 1; }
        if (p < 0) {
            for (k = 0; k < nc; ++k) {
                double s;
                if (is_active[k] || !cons_present(&P, k)) continue;
                s = cons_slack(&P, k, x, ax) / cnorm[k];
                if (s < -GT_QP_TOL * (1.0 + fabs(cons_b(&P, k)) / cnorm[k]) && s < smin) { smin = s; p = k; }
            }
        }
        if (p < 0) break; /* every constraint holds: optimal */
        cons_normal(&P, p, np_);
        sp = cons_slack(&P, p, x, ax);
        bp = cons_b(&P, p);
        if (eq && sp > 0.0) { /* approach an equality from its violated side */
            for (i = 0; i < n; ++i) np_[i] = -np_[i];
            sp = -sp;
            bp = -bp;
            flip = -1;
        }
        u[q] = 0.0;
        for (;;) { /* step 2 */
            double t1 = INFINITY, t2 = INFINITY, t, zn = 0.0;
            int l = -1;
            if (++it > max_iter) { status = GT_QP_MAX_ITER; goto done; }
            jt_times(n, J, np_, d);
            j_times_from(n, J, d, q, z); /* primal direction z = J2 J2' n+ */
            for (j = q - 1; j >= 0; --j) { /* r = R^-1 d[0..q) */
                double s = d[j];
                for (k = j + 1; k < q; ++k) s -= R[j + n * k] * r[k];
                r[j] = s / R[j + n * j];
            }
            for (j = 0; j < q; ++j) /* partial step: an inequality's multiplier reaches zero */
                if (!cons_is_eq(&P, act[j]) && r[j] > 0.0 && u[j] / r[j] < t1) { t1 = u[j] / r[j]; l = j; }
            for (i = 0; i < n; ++i) zn += z[i] * np_[i];
            if (fabs(zn) > GT_QP_DEP_TOL * (1.0 + fabs(sp))) t2 = -sp / zn;
            else if (eq) { status = GT_QP_DEPENDENT; goto done; }
            t = t1 < t2 ? t1 : t2;
            if (!isfinite(t)) { status = GT_QP_INFEASIBLE; goto done; }
            if (!isfinite(t2)) { /* dual step only, then drop */
                for (j = 0; j < q; ++j) u[j] -= t * r[j];
                u[q] += t;
                is_active[act[l]] = 0;
                drop_constraint(n, J, R, act, act_flip, u, q, l);
                --q;
                continue;
            }
            for (i = 0; i < n; ++i) x[i] += t * z[i];
            for (j = 0; j < q; ++j) u[j] -= t * r[j];
            u[q] += t;
            if (t == t2) { /* full step: add p */
                if (!add_constraint(n, J, R, d, q)) { status = GT_QP_DEPENDENT; goto done; }
                act[q] = p;
                act_flip[q] = flip;
                is_active[p] = 1;
                ++q;
                break;
            }
            is_active[act[l]] = 0; /* partial step: drop l, then retry p */
            drop_constraint(n, J, R, act, act_flip, u, q, l);
            --q;
            sp = -bp;
            for (i = 0; i < n; ++i) sp += np_[i] * x[i];
        }
    }
done:
    if (lam) {
        memset(lam, 0, sizeof(double) * (n + m));
        for (j = 0; j < q; ++j) {
            int c = act[j];
            lam[c / 2] += (c % 2 ? -1.0 : 1.0) * act_flip[j] * u[j];
        }
    }
    if (iter) *iter = it;
    return status;
}
