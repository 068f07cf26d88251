/*
 * What the files of the order tracker's compiled kernel share (_trackerkernel.c lists the
 * functions): the buffer-size check, numpy's pairwise sum, and the functions one file defines
 * for another (hidden: the extension module exports only its PyInit).
 */
#ifndef CMSENSORD_TRACKERKERNEL_H
#define CMSENSORD_TRACKERKERNEL_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>

#define TK_HIDDEN __attribute__((visibility("hidden")))

static inline int need(Py_buffer *b, Py_ssize_t n_doubles, const char *name) {
    if (b->len < n_doubles * (Py_ssize_t)sizeof(double)) {
        PyErr_Format(PyExc_ValueError, "%s: buffer has %zd bytes, expected %zd",
                     name, b->len, n_doubles * (Py_ssize_t)sizeof(double));
        return 0;
    }
    return 1;
}

/* numpy's pairwise sum of n doubles a[0], a[stride], ... (numpy/_core/src/umath/loops_utils.h:
 * below 8 one by one from 0., up to 128 in 8 accumulators, above halves), the order in which
 * ndarray.sum adds a contiguous row: the same bits. */
static inline double pairwise_sum(const double *a, Py_ssize_t n, Py_ssize_t stride) {
    if (n < 8) {
        double res = 0.;
        for (Py_ssize_t i = 0; i < n; i++) res += a[i * stride];
        return res;
    }
    if (n <= 128) {
        double r[8];
        Py_ssize_t i;
        for (int j = 0; j < 8; j++) r[j] = a[j * stride];
        for (i = 8; i < n - (n % 8); i += 8)
            for (int j = 0; j < 8; j++) r[j] += a[(i + j) * stride];
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) res += a[i * stride];
        return res;
    }
    Py_ssize_t n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise_sum(a, n2, stride) + pairwise_sum(a + n2 * stride, n - n2, stride);
}

/* _trackerkernel_filter.c */
TK_HIDDEN void sos_all(const double *sos, Py_ssize_t S, const double *x, Py_ssize_t T, Py_ssize_t C, double *zi, double *out, Py_ssize_t skip, Py_ssize_t D);
/* _trackerkernel_filter.c */
TK_HIDDEN PyObject *sosfilt(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *riccati(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *forward(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *backward(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *envelope(PyObject *self, PyObject *args);
/* _trackerkernel_blocks.c */
TK_HIDDEN PyObject *lerp_rows(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *lerp_at(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *block_stats(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *model_omega(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *forward_blocks(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *live_in(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *live_out(PyObject *self, PyObject *args);
/* _trackerkernel_tacho.c */
TK_HIDDEN PyObject *tacho_eval(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *causal_fit(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *knot_fit(PyObject *self, PyObject *args);
TK_HIDDEN PyObject *causal_rpm(PyObject *self, PyObject *args);
/* _trackerkernel_edges.c: its functions added to the module m */
TK_HIDDEN int add_tacho_edge_functions(PyObject *m);

#endif
