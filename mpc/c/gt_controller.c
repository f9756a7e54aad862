/* grindtwin's exported NMPC (gt_controller.h): the same arithmetic as mpc.Ekf.make_step and
 * mpc.Controller.make_step with qpsol "condensed" (the warm start shifted by the periods since the
 * last step, make_step's samples, the real-time iterations of gt_rti.c, the plan clipped to the input
 * bounds, the shifted-plan and hold-input fallbacks, the target_unreachable status), on the
 * CasADi-generated ekf_step, stage functions (gt_cond.c) and gt_plan_passing. */
#include "gt_controller.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gt_controller_config.h"
#include "gt_ekf_data.h"
#include "gt_qp.h"
#include "gt_rti.h"
#include "gt_rti_data.h" /* generated: gt_plan_passing (and gt_cond.c's stage functions) */

#define GT_STRIDE (GT_NXL + GT_NUL) /* variables of one stage: X~_k then U~_k */

struct gt_controller {
    gt_rti *rti;
    double z[GT_NZ], P[GT_NZ * GT_NZ], P_next[GT_NZ * GT_NZ], innovation[3];
    double w[GT_NW], w_prev[GT_NW], w_next[GT_NW], p[GT_NP], wpass[GT_NPASS];
    double plan[GT_N * 2], plan_prev[GT_N * 2], passing_end;
    double t_prev; /* the caller's time [h] of the last estimate (have_t: one was made since new/reset) */
    int have_w_prev, have_plan, plan_age, qp_iter, qp_status, have_t;
    int estimated; /* an estimate was made since the last step (or new/reset): the step may plan */
    /* the periods the estimates predicted since the plan last moved on (mpc.Controller.make_step's samples,
     * grindtwin serve's samples since the last step), at most GT_N: a plan that old is spent either way */
    int periods;
    /* the work of the generated ekf_step and gt_plan_passing (called one at a time) */
    const casadi_real **ekf_arg;
    casadi_real **ekf_res;
    casadi_int *ekf_iw;
    casadi_real *ekf_w;
};

/* the larger of ekf_step's and gt_plan_passing's work sizes */
static void work_sizes(casadi_int *a, casadi_int *r, casadi_int *i, casadi_int *w) {
    casadi_int a2, r2, i2, w2;
    ekf_step_work(a, r, i, w);
    gt_plan_passing_work(&a2, &r2, &i2, &w2);
    if (a2 > *a) *a = a2;
    if (r2 > *r) *r = r2;
    if (i2 > *i) *i = i2;
    if (w2 > *w) *w = w2;
}

static long ekf_bytes(void) {
    casadi_int a, r, i, w;
    work_sizes(&a, &r, &i, &w);
    return (long)(sizeof(casadi_real *) * (size_t)(a + r) + sizeof(casadi_int) * (size_t)i +
                  sizeof(casadi_real) * (size_t)w) + 16;
}

/* the EKF alone back to the exported initial estimate (CountingEstimator's reset) */
static void reset_estimate(gt_controller *c) {
    int i;
    memcpy(c->z, gt_z0, sizeof(c->z));
    memcpy(c->P, gt_p0, sizeof(c->P));
    for (i = 0; i < 3; ++i) c->innovation[i] = NAN;
}

static int all_finite(const double *v, int n) {
    int i;
    for (i = 0; i < n; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

long gt_controller_bytes(void) { return (long)sizeof(gt_controller) + ekf_bytes() + gt_rti_bytes(); }

/* generated (gt_exported.c): gt_controller_config.h's constants as exported */
extern const int gt_exported_constants_len;
extern const double gt_exported_constants[];

#define GT_PART(a) {(a), (int)(sizeof(a) / sizeof((a)[0]))}

/* 1 if the library's gt_controller_config.h holds the constants exported with the QP's and the EKF's
 * data, in the order of GT_CONFIG_SCALARS and then mpc.export.CHECKED_ARRAYS; 0 if one was edited */
static int config_as_exported(void) {
    static const double scalars[] = GT_CONFIG_SCALARS;
    static const struct {
        const double *v;
        int n;
    } parts[] = {GT_PART(scalars), GT_PART(gt_x_scale), GT_PART(gt_u_lo), GT_PART(gt_u_hi), GT_PART(gt_du_max),
                 GT_PART(gt_wpass), GT_PART(gt_upper_um), GT_PART(gt_z0), GT_PART(gt_p0), GT_PART(gt_u0),
                 GT_PART(gt_y_lo), GT_PART(gt_y_hi)};
    int p, i, k = 0;
    for (p = 0; p < (int)(sizeof(parts) / sizeof(parts[0])); ++p)
        for (i = 0; i < parts[p].n; ++i, ++k)
            if (k >= gt_exported_constants_len || parts[p].v[i] != gt_exported_constants[k]) return 0;
    return k == gt_exported_constants_len;
}

int gt_controller_check_abi(unsigned long abi_hash, int nx, int nu, int ny, int nb, int n, int nz,
                            int preview_len) {
    if (nx != GT_NX || nu != GT_NU || ny != GT_NY || nb != GT_NB || n != GT_N || nz != GT_NZ ||
        preview_len != GT_PREVIEW_LEN)
        return GT_ABI_SIZES_DIFFER;
    if (abi_hash != GT_ABI_HASH) return GT_ABI_LAYOUT_DIFFERS;
    return config_as_exported() ? GT_ABI_OK : GT_ABI_CONFIG_EDITED;
}

unsigned long gt_controller_abi_hash(void) { return GT_ABI_HASH; }

gt_controller *gt_controller_new_checked(int *abi_status, unsigned long abi_hash, int nx, int nu, int ny,
                                         int nb, int n, int nz, int preview_len) {
    int st = gt_controller_check_abi(abi_hash, nx, nu, ny, nb, n, nz, preview_len);
    if (abi_status) *abi_status = st;
    return st == GT_ABI_OK ? gt_controller_new() : NULL;
}

gt_controller *gt_controller_new(void) {
    casadi_int a, r, i, w;
    char *mem;
    gt_controller *c;
    long off = (long)sizeof(gt_controller);
    if (!config_as_exported()) return NULL; /* an edited gt_controller_config.h: GT_ABI_CONFIG_EDITED */
    mem = (char *)calloc(1, (size_t)(gt_controller_bytes() - gt_rti_bytes()));
    c = (gt_controller *)mem;
    if (!c) return NULL;
    c->rti = gt_rti_new();
    if (!c->rti) { free(mem); return NULL; }
    work_sizes(&a, &r, &i, &w);
    off = (off + 7) & ~7L;
    c->ekf_arg = (const casadi_real **)(mem + off); off += (long)sizeof(casadi_real *) * a;
    c->ekf_res = (casadi_real **)(mem + off); off += (long)sizeof(casadi_real *) * r;
    c->ekf_w = (casadi_real *)(mem + off); off += (long)sizeof(casadi_real) * w;
    c->ekf_iw = (casadi_int *)(mem + off);
    gt_controller_reset(c);
    return c;
}

void gt_controller_free(gt_controller *c) {
    if (!c) return;
    gt_rti_free(c->rti);
    free(c);
}

void gt_controller_reset(gt_controller *c) {
    if (!c) return;
    reset_estimate(c);
    c->have_w_prev = c->have_plan = c->plan_age = 0;
    c->have_t = c->estimated = c->periods = 0;
    c->t_prev = NAN;
    c->qp_iter = 0;
    c->qp_status = 0;
    c->passing_end = NAN;
}

/* the sum of a blend's GT_NB fractions */
static double blend_sum(const double *b) {
    double sum = 0.0;
    int i;
    for (i = 0; i < GT_NB; ++i) sum += b[i];
    return sum;
}

/* mpc.errors.is_blend: finite fractions in [0, 1] summing to 1 within GT_BLEND_SUM_TOL (its end included, as
 * twin.ore.blend_sum_ok) */
static int blend_ok(const double *b) {
    int i;
    for (i = 0; i < GT_NB; ++i)
        if (!isfinite(b[i]) || b[i] < -1e-9 || b[i] > 1.0 + 1e-9) return 0;
    return fabs(blend_sum(b) - 1.0) <= GT_BLEND_SUM_TOL * (1.0 + 1e-9);
}

/* the sample periods from the last estimate to t_h: k (1 to GT_MAX_PREDICT_PERIODS) when t_h - t_prev is
 * within GT_DT_TOL x GT_DT_H of k GT_DT_H, 1 for the first estimate since new/reset (any finite t_h); 0
 * otherwise (GT_ESTIMATE_BAD_TIME: not finite, not later, or not near a whole number of periods) */
static int periods_elapsed(const gt_controller *c, double t_h) {
    double elapsed = t_h - c->t_prev, k = floor(elapsed / GT_DT_H + 0.5);
    if (!isfinite(t_h)) return 0;
    if (!c->have_t) return 1;
    if (!(k >= 1.0 && k <= GT_MAX_PREDICT_PERIODS && fabs(elapsed - k * GT_DT_H) <= GT_DT_TOL * GT_DT_H)) return 0;
    return (int)k;
}

int gt_controller_estimate(gt_controller *c, double t_h, const double *y, const double *u_applied,
                           const double *blend) {
    static const double absent[3] = {0.0, 0.0, 0.0}; /* the values and mask of a sample without measurements */
    double yy[3], mask[3], z[GT_NZ], bn[GT_NB], sum;
    int i, j, k, failed, reset = 0, implausible = 0;
    /* mpc.Ekf.make_step refuses these: a NaN input once made the clipped update an empty mill, a feed of
     * -100 t/h emptied it, a blend of [5, -4] drove the hardness to its bound */
    if (!c || !y || !u_applied || !blend || !all_finite(u_applied, GT_NU) || !blend_ok(blend) ||
        !(u_applied[0] >= 0.0 && u_applied[0] <= GT_FEED_MAX_TPH && u_applied[1] > 0.0 && u_applied[1] < 1.0))
        return GT_ESTIMATE_BAD_INPUT;
    k = periods_elapsed(c, t_h);
    if (!k) return GT_ESTIMATE_BAD_TIME;
    sum = blend_sum(blend);
    for (i = 0; i < GT_NB; ++i) bn[i] = blend[i] / sum; /* rescaled to sum to 1, as mpc.Ekf.make_step does */
    for (i = 0; i < 3; ++i) { /* outside its physical range: a fault of units or instrument, as absent */
        int ok = isfinite(y[i]) && y[i] >= gt_y_lo[i] && y[i] <= gt_y_hi[i];
        implausible |= isfinite(y[i]) && !ok;
        yy[i] = ok ? y[i] : 0.0;
        mask[i] = ok ? 1.0 : 0.0;
    }
    c->t_prev = t_h;
    c->have_t = 1;
    c->estimated = 1;
    c->periods = c->periods + k < GT_N ? c->periods + k : GT_N;
    /* k periods as the Python loop's k samples: k - 1 without measurements (NaN, absent), then this one's;
     * the input and blend held over all of them, a reset at one continued from the initial estimate */
    for (j = 1; j <= k; ++j) {
        memcpy(z, c->z, sizeof(z));
        c->ekf_arg[0] = z;
        c->ekf_arg[1] = c->P;
        c->ekf_arg[2] = u_applied;
        c->ekf_arg[3] = bn;
        c->ekf_arg[4] = j == k ? yy : absent;
        c->ekf_arg[5] = j == k ? mask : absent;
        c->ekf_res[0] = c->z;
        c->ekf_res[1] = c->P_next;
        c->ekf_res[2] = c->innovation;
        failed = ekf_step(c->ekf_arg, c->ekf_res, c->ekf_iw, c->ekf_w, 0);
        memcpy(c->P, c->P_next, sizeof(c->P));
        if (failed || !all_finite(c->z, GT_NZ) || !all_finite(c->P, GT_NZ * GT_NZ)) {
            reset_estimate(c); /* as the scene's closed loop resets its EKF (CountingEstimator) */
            reset = 1;
        }
    }
    for (i = 0; i < 3; ++i)
        if (!mask[i]) c->innovation[i] = NAN;
    return reset ? GT_ESTIMATE_RESET : implausible ? GT_ESTIMATE_IMPLAUSIBLE : GT_ESTIMATE_OK;
}

/* mpc.Controller._initial_guess: the previous solution shifted by the periods since the last step (its
 * last stage held), its first lifted state replaced by [x/scale; u_prev; 0]; cold: everything at (x, u_prev) */
static void initial_guess(gt_controller *c, const double *x0s, const double *u_prev, int periods) {
    double first[GT_NXL];
    int k, i;
    for (i = 0; i < GT_NX; ++i) first[i] = x0s[i];
    for (i = 0; i < GT_NU; ++i) first[GT_NX + i] = u_prev[i];
    for (i = GT_NX + GT_NU; i < GT_NXL; ++i) first[i] = 0.0;
    if (GT_WARM_START && c->have_w_prev) {
        for (k = 0; k <= GT_N; ++k) {
            int src = (k + periods < GT_N ? k + periods : GT_N);
            memcpy(c->w + k * GT_STRIDE, c->w_prev + src * GT_STRIDE, sizeof(double) * GT_NXL);
        }
        for (k = 0; k < GT_N; ++k) {
            int src = (k + periods < GT_N - 1 ? k + periods : GT_N - 1);
            memcpy(c->w + k * GT_STRIDE + GT_NXL, c->w_prev + src * GT_STRIDE + GT_NXL,
                   sizeof(double) * GT_NUL);
        }
        memcpy(c->w, first, sizeof(first));
        return;
    }
    for (k = 0; k <= GT_N; ++k) memcpy(c->w + k * GT_STRIDE, first, sizeof(first));
    for (k = 0; k < GT_N; ++k) {
        double *uk = c->w + k * GT_STRIDE + GT_NXL;
        for (i = 0; i < GT_NU; ++i) uk[i] = u_prev[i];
        for (i = GT_NU; i < GT_NUL; ++i) uk[i] = 0.0;
    }
}

/* twin.sizes.SizeGrid.passing_weights: w with sum(w * mass_fraction) = the fraction passing
 * size_um (> 0), by linear interpolation of cumulative passing in log size between class upper
 * sizes; inside the sink, passing falls by one class per grid ratio */
static void passing_weights(double size_um, double *w) {
    const double *up = gt_upper_um;
    int i, k = 0;
    for (i = 0; i < GT_NPASS; ++i) w[i] = 0.0;
    if (size_um >= up[0]) {
        for (i = 0; i < GT_NPASS; ++i) w[i] = 1.0;
        return;
    }
    if (size_um <= up[GT_NPASS - 1]) {
        double frac = 1.0 - log(up[GT_NPASS - 1] / size_um) / log(GT_GRID_RATIO);
        w[GT_NPASS - 1] = frac > 0.0 ? frac : 0.0;
        return;
    }
    while (!(up[k + 1] < size_um)) ++k; /* up[k] >= size_um > up[k + 1] */
    for (i = k + 1; i < GT_NPASS; ++i) w[i] = 1.0;
    w[k] = log(size_um / up[k + 1]) / log(up[k] / up[k + 1]);
}

/* mpc.Ekf.controller_p80_bias_um: the bias that holds the plant (not the model) at the target */
static double controller_p80_bias(const gt_controller *c) {
    double b = GT_HAS_P80_BIAS ? c->z[GT_NZ - 1] : 0.0;
    if (GT_P80_GAIN == 1.0) return b;
    return GT_TARGET_P80_UM - (GT_P80_REFERENCE_UM + (GT_TARGET_P80_UM - b - GT_P80_REFERENCE_UM) / GT_P80_GAIN);
}

static double clip(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* mpc.Controller._plan_info's passing_end: the product's fraction passing the size of wpass (the
 * target the step held, biased or not) at the plan's last state X_N, with its last move and the
 * last stage's disturbances; NaN if the generated function fails */
static double plan_passing_end(gt_controller *c, const double *wpass) {
    double x[GT_NX], passing = NAN;
    int i;
    for (i = 0; i < GT_NX; ++i) x[i] = c->w[GT_N * GT_STRIDE + i] * gt_x_scale[i];
    c->ekf_arg[0] = x;
    c->ekf_arg[1] = c->plan + 2 * (GT_N - 1);
    c->ekf_arg[2] = c->p + GT_NX + (GT_N - 1) * GT_ND;
    c->ekf_arg[3] = wpass;
    c->ekf_res[0] = &passing;
    if (gt_plan_passing(c->ekf_arg, c->ekf_res, c->ekf_iw, c->ekf_w, 0)) return NAN;
    return passing;
}

/* mpc.Controller._fallback: the last plan moved on by the periods since the last step while it lasts */
static int fallback(gt_controller *c, const double *u_prev, int periods, double *u) {
    int k, i;
    c->have_w_prev = 0;
    if (c->have_plan && c->plan_age + periods < GT_N) {
        c->plan_age += periods;
        for (k = 0; k < GT_N; ++k) {
            int src = k + c->plan_age < GT_N ? k + c->plan_age : GT_N - 1;
            for (i = 0; i < 2; ++i) c->plan[2 * k + i] = c->plan_prev[2 * src + i];
        }
        for (i = 0; i < 2; ++i) u[i] = clip(c->plan[i], u_prev[i] - gt_du_max[i], u_prev[i] + gt_du_max[i]);
        return GT_STEP_SHIFTED_PLAN;
    }
    c->have_plan = 0;
    for (k = 0; k < GT_N; ++k)
        for (i = 0; i < 2; ++i) c->plan[2 * k + i] = u_prev[i];
    u[0] = u_prev[0];
    u[1] = u_prev[1];
    return GT_STEP_HOLD_INPUT;
}

/* mpc.Controller._d_traj's check of the stages read (GT_PREVIEW 0: the first, held): each a blend
 * (blend_ok); a plan on [5, -4] was a plan on nothing */
static int preview_ok(const double *preview) {
    int k;
    for (k = 0; k < (GT_PREVIEW ? GT_N : 1); ++k)
        if (!blend_ok(preview + k * GT_NB)) return 0;
    return 1;
}

int gt_controller_step(gt_controller *c, const double *preview, const double *u_given, double *u) {
    double x0s[GT_NX], h, *p, bias, u_applied[GT_NU];
    const double *wpass = gt_wpass;
    int k, i, it, n_it = GT_RTI_ITERATIONS, ok = n_it > 0, projected = 0, periods;
    if (!c) return GT_STEP_BAD_INPUT;
    h = GT_HAS_HARDNESS ? c->z[GT_NX] : GT_HARDNESS0;
    p = c->p;
    bias = controller_p80_bias(c);
    c->passing_end = NAN;
    c->qp_iter = 0; /* a refused step solved no QP: not the last one's counts */
    c->qp_status = 0;
    if (!preview || !u_given || !u) return GT_STEP_BAD_INPUT;
    for (i = 0; i < GT_NU; ++i) { /* mpc.Controller.make_step: refused, or projected onto the bounds */
        if (!isfinite(u_given[i])) return GT_STEP_BAD_INPUT;
        u_applied[i] = clip(u_given[i], gt_u_lo[i], gt_u_hi[i]);
        projected |= u_applied[i] != u_given[i];
    }
    if (!preview_ok(preview)) return GT_STEP_BAD_INPUT;
    if (!c->estimated) return GT_STEP_NO_ESTIMATE; /* it would plan again from the estimate it planned from */
    c->estimated = 0;
    if (!isfinite(bias) || bias >= GT_TARGET_P80_UM) { /* mpc.Controller.make_step refuses it */
        u[0] = u_applied[0];
        u[1] = u_applied[1];
        return GT_STEP_BAD_BIAS; /* the plan not moved: its periods kept, as serve keeps its samples */
    }
    periods = c->periods; /* the plan and the warm start move on by them now, solved or not */
    c->periods = 0;
    if (bias != 0.0) { /* the model held at target - bias (mpc.Controller.make_step) */
        passing_weights(GT_TARGET_P80_UM - bias, c->wpass);
        wpass = c->wpass;
    }
    /* p = [x; vec(D); u_prev; wpass], D = [blend preview; hardness] per stage */
    for (i = 0; i < GT_NX; ++i) {
        p[i] = c->z[i];
        x0s[i] = c->z[i] / gt_x_scale[i];
    }
    for (k = 0; k < GT_N; ++k) {
        const double *b = preview + (GT_PREVIEW ? k : 0) * GT_NB;
        double sum = blend_sum(b); /* rescaled to sum to 1, as mpc.Controller._d_traj and the twin do */
        for (i = 0; i < GT_NB; ++i) p[GT_NX + k * GT_ND + i] = b[i] / sum;
        p[GT_NX + k * GT_ND + GT_NB] = h;
    }
    for (i = 0; i < GT_NU; ++i) p[GT_NX + GT_N * GT_ND + i] = u_applied[i];
    for (i = 0; i < GT_NPASS; ++i) p[GT_NX + GT_N * GT_ND + GT_NU + i] = wpass[i];
    initial_guess(c, x0s, u_applied, periods);
    c->qp_iter = 0;
    c->qp_status = 0;
    for (it = 1; it <= n_it; ++it) { /* mpc.Controller._rti_solve */
        double step_max = 0.0;
        int qi = 0, st = gt_rti_step(c->rti, c->w, p, c->w_next, &qi);
        c->qp_iter += qi;
        if (st) c->qp_status = st; /* a regularised QP stays reported after a clean one */
        if (st && st != GT_QP_REGULARISED) { ok = 0; break; }
        for (i = 0; i < GT_NW; ++i) {
            double s = c->w_next[i] - c->w[i];
            c->w[i] += s;
            if (fabs(s) > step_max) step_max = fabs(s);
        }
        if (step_max < GT_TOL) break;
    }
    for (i = 0; ok && i < GT_NW; ++i)
        if (!isfinite(c->w[i])) ok = 0;
    if (!ok) return fallback(c, u_applied, periods, u);
    memcpy(c->w_prev, c->w, sizeof(c->w));
    c->have_w_prev = 1;
    for (k = 0; k < GT_N; ++k)
        for (i = 0; i < 2; ++i)
            c->plan[2 * k + i] = clip(c->w[k * GT_STRIDE + GT_NXL + i], gt_u_lo[i], gt_u_hi[i]);
    memcpy(c->plan_prev, c->plan, sizeof(c->plan));
    c->have_plan = 1;
    c->plan_age = 0;
    u[0] = c->plan[0];
    u[1] = c->plan[1];
    /* mpc.Controller.make_step: the plan's end misses the target (the plan is applied all the same) */
    c->passing_end = plan_passing_end(c, wpass);
    if (projected) return GT_STEP_INPUT_PROJECTED; /* mpc.Controller.make_step: input_outside_bounds */
    return fabs(c->passing_end - GT_PASSING_TARGET) > GT_UNREACHABLE_TOL ? GT_STEP_TARGET_UNREACHABLE : GT_STEP_OK;
}

/* NULL (NaN, -1) for no controller rather than a crash */
const double *gt_controller_plan(const gt_controller *c) { return c ? c->plan : NULL; }
const double *gt_controller_estimate_state(const gt_controller *c) { return c ? c->z : NULL; }
int gt_controller_qp_iterations(const gt_controller *c) { return c ? c->qp_iter : -1; }
int gt_controller_qp_status(const gt_controller *c) { return c ? c->qp_status : -1; }
double gt_controller_passing_end(const gt_controller *c) { return c ? c->passing_end : NAN; }
