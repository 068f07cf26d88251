/*
 * The AKF bank recursion of Kim et al. 2023, eqs. (3)-(15), in C.
 *
 * Same semantics, same order of floating-point operations as ScalarAKF and
 * _run_numpy in akf.py (which document the equations); tested against them to
 * 1e-12.  The loop is sequential in time (the adaptation makes the filter
 * nonlinear in the data) and runs over (channel, filter) inside each step.
 *
 * Arrays are passed as C-contiguous buffers; akf.py checks dtypes and shapes,
 * this file checks the buffer sizes so that a mistake cannot write out of bounds.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

static int need(Py_buffer *b, Py_ssize_t bytes, const char *name) {
    if (b->len < bytes) {
        PyErr_Format(PyExc_ValueError, "%s: buffer has %zd bytes, expected %zd",
                     name, b->len, bytes);
        return 0;
    }
    return 1;
}

static PyObject *run(PyObject *self, PyObject *args) {
    Py_buffer by, bvalid, bR, bzc, bN, bx, bP, bQ, bres2, bdx2, bpos, bfill, bstarted,
        bxp, bxh, bY, bQo, bout;
    int scaling;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*iw*w*w*w*w*w*w*w*w*w*w*w*w*",
                          &by, &bvalid, &bR, &bzc, &bN, &scaling, &bx, &bP, &bQ,
                          &bres2, &bdx2, &bpos, &bfill, &bstarted, &bxp, &bxh, &bY, &bQo, &bout))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t C = bzc.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t n = C ? bR.len / (Py_ssize_t)sizeof(double) / C : 0;
    const Py_ssize_t T = C ? by.len / (Py_ssize_t)sizeof(double) / C : 0;
    const Py_ssize_t Nmax = (C && n) ? bres2.len / (Py_ssize_t)sizeof(double) / (C * n) : 0;
    if (C <= 0 || n <= 0 || Nmax <= 0) {
        PyErr_SetString(PyExc_ValueError, "empty bank");
        goto done;
    }
    if (!need(&bvalid, T * C, "valid") || !need(&bN, C * 8, "N") ||
        !need(&bx, C * n * 8, "x") || !need(&bP, C * n * 8, "P") || !need(&bQ, C * n * 8, "Q") ||
        !need(&bdx2, C * n * Nmax * 8, "dx2") || !need(&bpos, C * 8, "pos") ||
        !need(&bfill, C * 8, "fill") || !need(&bstarted, C, "started") ||
        !need(&bxp, T * C * n * 8, "x_prior") || !need(&bxh, T * C * n * 8, "x_hat") ||
        !need(&bY, T * C * n * 8, "Y") || !need(&bQo, T * C * n * 8, "Q_out") ||
        !need(&bout, T * C * n, "outlier"))
        goto done;

    const double *y = by.buf, *R = bR.buf, *zc = bzc.buf;
    const uint8_t *valid = bvalid.buf;
    const int64_t *N = bN.buf;
    double *x = bx.buf, *P = bP.buf, *Q = bQ.buf, *res2 = bres2.buf, *dx2 = bdx2.buf;
    int64_t *pos = bpos.buf, *fill = bfill.buf;
    uint8_t *started = bstarted.buf, *outl = bout.buf;
    double *oxp = bxp.buf, *oxh = bxh.buf, *oY = bY.buf, *oQ = bQo.buf;
    for (Py_ssize_t c = 0; c < C; c++) {
        if (N[c] < 1 || N[c] > Nmax) {
            PyErr_Format(PyExc_ValueError, "N[%zd] = %lld out of 1..%zd", c, (long long)N[c], Nmax);
            goto done;
        }
    }

    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t t = 0; t < T; t++) {
        for (Py_ssize_t c = 0; c < C; c++) {
            const int v = valid[t * C + c];
            const double yk = y[t * C + c];
            const Py_ssize_t o = (t * C + c) * n;   /* output row */
            double *xc = x + c * n, *Pc = P + c * n, *Qc = Q + c * n;
            const double *Rc = R + c * n;
            if (!started[c]) {
                if (!v) {           /* nothing happens before the first observation */
                    for (Py_ssize_t i = 0; i < n; i++) {
                        oxp[o + i] = NAN; oxh[o + i] = NAN; oY[o + i] = NAN; oQ[o + i] = NAN; outl[o + i] = 0;
                    }
                    continue;
                }
                for (Py_ssize_t i = 0; i < n; i++) xc[i] = yk;   /* x̂(0) = first observation */
                started[c] = 1;
            }
            if (!v) {               /* missing observation: time update only */
                for (Py_ssize_t i = 0; i < n; i++) {
                    const double Pp = Pc[i] + Qc[i];                 /* (4) */
                    oxp[o + i] = xc[i]; oxh[o + i] = xc[i];
                    oY[o + i] = Pp + Rc[i]; oQ[o + i] = Qc[i]; outl[o + i] = 0;
                    Pc[i] = Pp;
                }
                continue;
            }
            const int64_t Nc = N[c];
            const int64_t slot = pos[c];
            const int64_t f = fill[c] + 1 < Nc ? fill[c] + 1 : Nc;
            const int64_t np_ = (slot + 1) % Nc;
            const int64_t oldest = ((np_ - f) % Nc + Nc) % Nc;
            for (Py_ssize_t i = 0; i < n; i++) {
                const double xp = xc[i];                             /* (3) */
                const double Pp = Pc[i] + Qc[i];                     /* (4) */
                const double innov = yk - xp;                        /* (5) */
                const double Yv = Pp + Rc[i];                        /* (6) */
                const double K = Pp / Yv;                            /* (7) */
                const double dx = K * innov;
                const double xn = xp + dx;                           /* (8) */
                Pc[i] = (1.0 - K) * Pp;                              /* (9) */
                xc[i] = xn;
                double *r2 = res2 + (c * n + i) * Nmax, *d2 = dx2 + (c * n + i) * Nmax;
                const double e = yk - xn;
                r2[slot] = e * e;
                d2[slot] = dx * dx;
                double sm = 0.0, sg = 0.0;
                int64_t idx = oldest;
                for (int64_t j = 0; j < f; j++) {                    /* chronological */
                    sm += r2[idx];
                    sg += d2[idx];
                    if (++idx == Nc) idx = 0;
                }
                const double M = sm / (double)f;                     /* (11) */
                const double Gh = sg / (double)f;                    /* (14) */
                const double Gt = K * K * Yv;                        /* (13) */
                double S = 1.0;
                if (scaling) { const double q = Gh / Gt; S = q > 1.0 ? q : 1.0; }   /* (12) */
                Qc[i] = S * M;                                       /* (10) */
                const double z = innov / sqrt(Yv);                   /* (15) */
                oxp[o + i] = xp; oxh[o + i] = xn; oY[o + i] = Yv; oQ[o + i] = Qc[i];
                outl[o + i] = fabs(z) > zc[c];
            }
            pos[c] = np_;
            fill[c] = f;
        }
    }
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&by); PyBuffer_Release(&bvalid); PyBuffer_Release(&bR);
    PyBuffer_Release(&bzc); PyBuffer_Release(&bN); PyBuffer_Release(&bx);
    PyBuffer_Release(&bP); PyBuffer_Release(&bQ); PyBuffer_Release(&bres2);
    PyBuffer_Release(&bdx2); PyBuffer_Release(&bpos); PyBuffer_Release(&bfill);
    PyBuffer_Release(&bstarted); PyBuffer_Release(&bxp); PyBuffer_Release(&bxh);
    PyBuffer_Release(&bY); PyBuffer_Release(&bQo); PyBuffer_Release(&bout);
    return ret;
}

static PyMethodDef methods[] = {
    {"run", run, METH_VARARGS, "Run a block of observations through an AKF bank (Kim et al. 2023, eqs. 3-15)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_akfkernel",
                                     "Compiled AKF bank recursion (see akf.py).", -1, methods};

PyMODINIT_FUNC PyInit__akfkernel(void) { return PyModule_Create(&module); }
