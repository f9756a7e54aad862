/* Dense strictly convex QP by the dual active-set method of Goldfarb & Idnani (1983).
 *
 *   min 0.5 x'Hx + g'x   s.t.  lba <= A x <= uba,  lbx <= x <= ubx
 *
 * H (n x n, symmetric positive definite) and A (m x n) dense, column-major. A bound or row with
 * lb == ub is an equality; an infinite bound (|b| >= GT_QP_INF) is absent. H, g and A must be
 * finite and no bound nan (else GT_QP_NOT_FINITE). No allocation: the
 * caller passes gt_qp_work_size(n, m) doubles and gt_qp_iwork_size(n, m) ints.
 */
#ifndef GT_QP_H
#define GT_QP_H

/* Every refusal of the controller (a NaN or infinite input, measurement or QP data: gt_qp.c,
 * gt_controller.c, which include this) rests on isfinite and isnan, which -ffast-math, -Ofast and
 * -ffinite-math-only let the compiler drop: built -Ofast, a NaN feed was estimated and stepped on
 * with status OK and both inputs at their upper bounds. Such a build is refused here. */
#if defined(__FAST_MATH__) || (defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__)
#error "grindtwin's controller checks for NaN and infinity: build it without -ffast-math, -Ofast or -ffinite-math-only"
#endif

#define GT_QP_INF 1e20

enum gt_qp_status {
    GT_QP_OK = 0,
    GT_QP_INFEASIBLE = 1,   /* no step reduces a violated constraint (the QP has no solution) */
    GT_QP_NOT_CONVEX = 2,   /* the Cholesky factorisation of H failed (H not positive definite) */
    GT_QP_MAX_ITER = 3,     /* iteration limit */
    GT_QP_DEPENDENT = 4,    /* an equality constraint is linearly dependent on the active ones */
    GT_QP_REGULARISED = 5,  /* solved, but H's Cholesky failed (H semi-definite to rounding) and
                               H + GT_QP_REG max(diag H) I was factorised instead */
    GT_QP_NOT_FINITE = 6    /* H, g or A holds a nan or an infinity, or a bound a nan: nothing solved
                               (checked first: a nan in H failed its Cholesky as if H were indefinite) */
};

#define GT_QP_REG 1e-10

long gt_qp_work_size(int n, int m);
long gt_qp_iwork_size(int n, int m);

/* Solves the QP; x (n) is the solution, lam (n + m) the multipliers of the bounds then rows
 * (> 0 at a lower bound, < 0 at an upper one), *iter the active-set changes. */
int gt_qp_solve(int n, int m, const double *H, const double *g, const double *A,
                const double *lba, const double *uba, const double *lbx, const double *ubx,
                double *x, double *lam, int *iter, int max_iter, double *work, int *iwork);

#endif
