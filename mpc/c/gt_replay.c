/* Replays a recorded sequence of estimator and controller calls through the exported controller
 * (a test and timing harness; a DCS calls gt_controller.h itself). Input lines on stdin:
 *   E t_h y0 y1 y2 u0 u1 b_1 .. b_NB     gt_controller_estimate at time t_h [h] (nan for an absent y)
 *   C u0 u1 b_1 .. b_(NB*N)              gt_controller_step with u_applied = (u0, u1)
 * Output on stdout, one line per C: "U status u_feed u_speed qp_iterations step_s step_cpu_s
 * qp_status" (status: gt_controller.h's gt_step_status; %.17g; u is nan when the step wrote nothing
 * into it: GT_STEP_BAD_INPUT, GT_STEP_NO_ESTIMATE), and at the end
 * "M allocations_during_calls" (counted when gt_malloc_count.so is preloaded, else -1),
 * "B bytes_allocated_by_new" and "R estimates_not_ok" (E lines whose gt_controller_estimate status
 * was not GT_ESTIMATE_OK, each also named on stderr with its line and status). A line with fewer or
 * more numbers than its kind takes, or any other line but a blank one or a # comment, is an error. */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gt_controller.h"
#include "gt_controller_config.h"

extern long gt_malloc_calls(void) __attribute__((weak));

static double clock_s(clockid_t id) {
    struct timespec t;
    clock_gettime(id, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* exactly n numbers: a longer line (a preview of another horizon) was read in part, silently */
static int read_doubles(char *s, double *v, int n) {
    int i;
    char *end;
    for (i = 0; i < n; ++i) {
        v[i] = strtod(s, &end);
        if (end == s) return 0;
        s = end;
    }
    while (*s == ' ' || *s == '\t' || *s == '\r' || *s == '\n') ++s;
    return *s == '\0';
}

int main(void) {
    static char line[1 << 16];
    static double v[1 + 3 + 2 + GT_NB * GT_N]; /* an E line's t_h, y, u and blend, or a C line's u and preview */
    long allocs = 0, n_line = 0, not_ok = 0;
    int counted = gt_malloc_calls != NULL;
    int abi;
    gt_controller *c = GT_CONTROLLER_NEW(&abi);
    if (!c) {
        fprintf(stderr, "gt_controller_new failed (abi status %d: 0 out of memory, else gt_abi_status)\n", abi);
        return 1;
    }
    while (fgets(line, sizeof line, stdin)) {
        long before;
        ++n_line;
        if (line[0] == 'E') {
            int est;
            if (!read_doubles(line + 1, v, 6 + GT_NB)) {
                fprintf(stderr, "bad E line %ld (E and %d numbers)\n", n_line, 6 + GT_NB);
                return 1;
            }
            before = counted ? gt_malloc_calls() : 0;
            est = gt_controller_estimate(c, v[0], v + 1, v + 4, v + 6);
            allocs += counted ? gt_malloc_calls() - before : 0;
            if (est != GT_ESTIMATE_OK) {
                ++not_ok;
                fprintf(stderr, "E line %ld: gt_controller_estimate status %d\n", n_line, est);
            }
        } else if (line[0] == 'C') {
            double u[2] = {strtod("nan", NULL), strtod("nan", NULL)}, t0, c0, dt, dc;
            int st;
            if (!read_doubles(line + 1, v, 2 + GT_NB * GT_N)) {
                fprintf(stderr, "bad C line %ld (C and %d numbers)\n", n_line, 2 + GT_NB * GT_N);
                return 1;
            }
            before = counted ? gt_malloc_calls() : 0;
            t0 = clock_s(CLOCK_MONOTONIC);
            c0 = clock_s(CLOCK_PROCESS_CPUTIME_ID);
            st = gt_controller_step(c, v + 2, v, u);
            dc = clock_s(CLOCK_PROCESS_CPUTIME_ID) - c0;
            dt = clock_s(CLOCK_MONOTONIC) - t0;
            allocs += counted ? gt_malloc_calls() - before : 0;
            printf("U %d %.17g %.17g %d %.9g %.9g %d\n", st, u[0], u[1], gt_controller_qp_iterations(c), dt, dc,
                   gt_controller_qp_status(c));
            fflush(stdout); /* one answer per C line: the harness can be driven through a pipe */
        } else if (line[0] != '\n' && line[0] != '#') { /* a line it does not know was skipped silently */
            fprintf(stderr, "unknown line (E, C or # comment): %.40s\n", line);
            return 1;
        }
    }
    printf("M %ld\nB %ld\nR %ld\n", counted ? allocs : -1L, gt_controller_bytes(), not_ok);
    gt_controller_free(c);
    return 0;
}
