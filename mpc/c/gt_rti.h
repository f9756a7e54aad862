/* One real-time iteration of grindtwin's NMPC on the condensed QP: the QP data condensed by the
 * loop over the stages of gt_cond.c (mpc/condense.py), the dense QP by gt_qp_solve
 * (Goldfarb & Idnani), the full step w + Gw dV + hw. gt_rti_new allocates everything once;
 * gt_rti_step allocates nothing. */
#ifndef GT_RTI_H
#define GT_RTI_H

typedef struct gt_rti gt_rti;

gt_rti *gt_rti_new(void);
void gt_rti_free(gt_rti *r);
/* bytes gt_rti_new allocates (one block) */
long gt_rti_bytes(void);
/* sizes: variables w, parameters p, condensed variables, condensed rows */
void gt_rti_sizes(const gt_rti *r, int *nw, int *np, int *nv, int *m);
/* w_out = w + step; returns the QP status (gt_qp.h: 0 = solved, GT_QP_REGULARISED = solved with
 * a regularised Hessian, w_out set for both), *iter its active-set changes */
int gt_rti_step(gt_rti *r, const double *w, const double *p, double *w_out, int *iter);
/* wall time of the last step's QP data and QP solve [s] */
void gt_rti_last_seconds(const gt_rti *r, double *data_s, double *qp_s);

#endif
