/* The RTI's Gauss-Newton QP condensed onto the inputs (mpc/condense.py) by a loop over the stages
 * in C: the generated stage functions of mpc.condense.stage_functions (gt_cond_point, the RK4
 * stages' sparse factors; gt_cond_terms0/terms/termsN, the stage terms; gt_cond_consts) called
 * once per stage or RK4 stage, the forward propagation of dx_k = T_k dV + t_k and the dense QP
 * formed here. gt_cond_init lays its memory out in a block the caller allocates once;
 * gt_cond_eval and gt_cond_expand allocate nothing. */
#ifndef GT_COND_H
#define GT_COND_H

typedef struct gt_cond gt_cond;

/* bytes of the block gt_cond_init needs (zeroed, 8-byte aligned); < 0 on a size error */
long gt_cond_bytes(void);
gt_cond *gt_cond_init(void *mem);
/* the sizes of gt_cond_sizes before an init; 0, or 1 on an error */
int gt_cond_dims(int *nw, int *np, int *nv, int *m);
/* sizes: variables w, parameters p, condensed variables nv, condensed rows m */
void gt_cond_sizes(const gt_cond *c, int *nw, int *np, int *nv, int *m);
/* the dense QP at (w, p): min 0.5 dV' H dV + g' dV, lba <= A dV <= uba, lbx <= dV <= ubx;
 * H (nv x nv) and A (m x nv) column-major. Returns 0, or 1 if a generated function failed. */
int gt_cond_eval(gt_cond *c, const double *w, const double *p, double *H, double *g, double *A,
                 double *lba, double *uba, double *lbx, double *ubx);
/* w_out = w + dw with dw = Gw dV + hw of the last gt_cond_eval */
void gt_cond_expand(const gt_cond *c, const double *w, const double *dv, double *w_out);

#endif
