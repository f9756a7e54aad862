/* One real-time iteration on the condensed QP (gt_rti.h). */
#include "gt_rti.h"

#define _POSIX_C_SOURCE 199309L
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gt_cond.h"
#include "gt_qp.h"

#define GT_QP_MAX_ITER 1000

enum { O_H, O_G, O_A, O_LBA, O_UBA, O_LBX, O_UBX, N_OUT };

struct gt_rti {
    int nw, np, nv, m;
    gt_cond *cond;
    double *out[N_OUT];
    double *dv, *lam, *qp_w;
    int *qp_iw;
    double data_s, qp_s; /* wall time of the last step's QP data and QP solve [s] */
};

static double now_s(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

void gt_rti_last_seconds(const gt_rti *r, double *data_s, double *qp_s) {
    *data_s = r->data_s;
    *qp_s = r->qp_s;
}

#define ALIGN8(off) (((off) + 7) & ~7L)

/* the block of gt_rti_new: the struct, the condensing's block, the QP data, the solver's work;
 * with r, the pointers into mem are set (the sizes from r->cond) */
static long layout(gt_rti *r, char *mem, int nv, int m) {
    long off = ALIGN8((long)sizeof(gt_rti)), cond = gt_cond_bytes(), n_out[N_OUT];
    int i;
    n_out[O_H] = (long)nv * nv; n_out[O_G] = nv; n_out[O_A] = (long)m * nv;
    n_out[O_LBA] = n_out[O_UBA] = m; n_out[O_LBX] = n_out[O_UBX] = nv;
    off = ALIGN8(off + cond);
    for (i = 0; i < N_OUT; ++i) {
        if (r) r->out[i] = (double *)(mem + off);
        off += (long)sizeof(double) * n_out[i];
    }
    if (r) r->dv = (double *)(mem + off);
    off += (long)sizeof(double) * nv;
    if (r) r->lam = (double *)(mem + off);
    off += (long)sizeof(double) * (nv + m);
    if (r) r->qp_w = (double *)(mem + off);
    off += (long)sizeof(double) * gt_qp_work_size(nv, m);
    if (r) r->qp_iw = (int *)(mem + off);
    off += (long)sizeof(int) * gt_qp_iwork_size(nv, m);
    return off + 8;
}

static long block_bytes(int *nv, int *m) {
    int nw, np;
    if (gt_cond_bytes() < 0 || gt_cond_dims(&nw, &np, nv, m)) return -1;
    return layout(NULL, NULL, *nv, *m);
}

long gt_rti_bytes(void) {
    int nv, m;
    return block_bytes(&nv, &m);
}

gt_rti *gt_rti_new(void) {
    int nv, m;
    long bytes = block_bytes(&nv, &m);
    char *mem;
    gt_rti *r;
    if (bytes < 0) return NULL;
    mem = (char *)calloc(1, (size_t)bytes); /* the only allocation */
    if (!mem) return NULL;
    r = (gt_rti *)mem;
    r->cond = gt_cond_init(mem + ALIGN8((long)sizeof(gt_rti)));
    if (!r->cond) { free(mem); return NULL; }
    gt_cond_sizes(r->cond, &r->nw, &r->np, &r->nv, &r->m);
    layout(r, mem, r->nv, r->m);
    return r;
}

void gt_rti_free(gt_rti *r) { free(r); }

void gt_rti_sizes(const gt_rti *r, int *nw, int *np, int *nv, int *m) {
    *nw = r->nw; *np = r->np; *nv = r->nv; *m = r->m;
}

int gt_rti_step(gt_rti *r, const double *w, const double *p, double *w_out, int *iter) {
    double **o = r->out;
    int st;
    double t0 = now_s(), t1;
    if (gt_cond_eval(r->cond, w, p, o[O_H], o[O_G], o[O_A], o[O_LBA], o[O_UBA], o[O_LBX], o[O_UBX])) return -1;
    t1 = now_s();
    st = gt_qp_solve(r->nv, r->m, o[O_H], o[O_G], o[O_A], o[O_LBA], o[O_UBA], o[O_LBX], o[O_UBX],
                     r->dv, r->lam, iter, GT_QP_MAX_ITER, r->qp_w, r->qp_iw);
    r->data_s = t1 - t0;
    r->qp_s = now_s() - t1;
    if (st != GT_QP_OK && st != GT_QP_REGULARISED) return st;
    gt_cond_expand(r->cond, w, r->dv, w_out);
    return st;
}
