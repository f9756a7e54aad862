/* LD_PRELOAD shim counting calls of malloc, calloc and realloc (gt_malloc_calls), to show that
 * the exported controller's steps allocate nothing after gt_controller_new. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stddef.h>

static long calls;
long gt_malloc_calls(void) { return calls; }

/* dlsym may itself call calloc: serve that from a small static pool */
static char pool[4096];
static size_t pool_used;
static void *pool_alloc(size_t n) {
    void *p = pool + pool_used;
    pool_used += (n + 15) & ~(size_t)15;
    return pool_used <= sizeof pool ? p : NULL;
}

void *malloc(size_t n) {
    static void *(*real)(size_t);
    if (!real) real = (void *(*)(size_t))dlsym(RTLD_NEXT, "malloc");
    ++calls;
    return real(n);
}

void *calloc(size_t k, size_t n) {
    static void *(*real)(size_t, size_t);
    static int resolving;
    if (!real) {
        if (resolving) return pool_alloc(k * n);
        resolving = 1;
        real = (void *(*)(size_t, size_t))dlsym(RTLD_NEXT, "calloc");
        resolving = 0;
    }
    ++calls;
    return real(k, n);
}

void *realloc(void *p, size_t n) {
    static void *(*real)(void *, size_t);
    if (!real) real = (void *(*)(void *, size_t))dlsym(RTLD_NEXT, "realloc");
    ++calls;
    return real(p, n);
}

void free(void *p) {
    static void (*real)(void *);
    if ((char *)p >= pool && (char *)p < pool + sizeof pool) return;
    if (!real) real = (void (*)(void *))dlsym(RTLD_NEXT, "free");
    real(p);
}
