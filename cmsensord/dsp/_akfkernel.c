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
#ifdef __SSE2__
#include <emmintrin.h>
#endif

static int need(Py_buffer *b, Py_ssize_t bytes, const char *name) {
    if (b->len < bytes) {
        PyErr_Format(PyExc_ValueError, "%s: buffer has %zd bytes, expected %zd",
                     name, b->len, bytes);
        return 0;
    }
    return 1;
}

/*
 * One step of filter i of a channel with its observation yk (eqs. 3-15): state xc, Pc, Qc,
 * rings r2, d2 (length Nc; the new entry at ``slot``, the f newest summed from ``oldest`` on,
 * oldest first); returns the outlier flag, and with ``full`` writes x̂⁻, x̂, Y, Q̂ at o[0..3].
 */
static inline uint8_t step1(double yk, double *xc, double *Pc, double *Qc, double Rc, double zc,
                            double *r2, double *d2, int64_t Nc, int64_t slot, int64_t oldest, int64_t f,
                            int scaling, int full, double *oxp, double *oxh, double *oY, double *oQ) {
    const double xp = *xc;                                   /* (3) */
    const double Pp = *Pc + *Qc;                             /* (4) */
    const double innov = yk - xp;                            /* (5) */
    const double Yv = Pp + Rc;                               /* (6) */
    const double K = Pp / Yv;                                /* (7) */
    const double dx = K * innov;
    const double xn = xp + dx;                               /* (8) */
    *Pc = (1.0 - K) * Pp;                                    /* (9) */
    *xc = xn;
    const double e = yk - xn;
    r2[slot] = e * e;
    d2[slot] = dx * dx;
    double sm = 0.0, sg = 0.0;
    int64_t idx = oldest;
    for (int64_t j = 0; j < f; j++) {                        /* chronological */
        sm += r2[idx];
        sg += d2[idx];
        if (++idx == Nc) idx = 0;
    }
    const double M = sm / (double)f;                         /* (11) */
    const double Gh = sg / (double)f;                        /* (14) */
    const double Gt = K * K * Yv;                            /* (13) */
    double S = 1.0;
    if (scaling) { const double q = Gh / Gt; S = q > 1.0 ? q : 1.0; }   /* (12) */
    *Qc = S * M;                                             /* (10) */
    const double z = innov / sqrt(Yv);                       /* (15) */
    if (full) { *oxp = xp; *oxh = xn; *oY = Yv; *oQ = *Qc; }
    return fabs(z) > zc;
}

#ifdef __SSE2__
/*
 * step1 of filters i and i + 1 at once, in the two lanes of SSE2 registers: every lane does
 * step1's IEEE operations in step1's order (no contraction: -ffp-contract=off), so each
 * filter's values have step1's bits; the divisions and the square root, most of a step's
 * time, go two at a time.  max(q, 1) is MAXPD (q if q > 1, else 1: also for a NaN q, as
 * step1).  The flags of the two filters go to fl[0], fl[1].
 */
static inline void step2(double yk, double *xc, double *Pc, double *Qc, const double *Rc, double zc,
                         double *r2, double *d2, Py_ssize_t Nmax, int64_t Nc, int64_t slot,
                         int64_t oldest, int64_t f, int scaling, int full, double *oxp, double *oxh,
                         double *oY, double *oQ, uint8_t *fl) {
    const __m128d y2 = _mm_set1_pd(yk), one = _mm_set1_pd(1.0);
    const __m128d xp = _mm_loadu_pd(xc);                                  /* (3) */
    const __m128d Pp = _mm_add_pd(_mm_loadu_pd(Pc), _mm_loadu_pd(Qc));    /* (4) */
    const __m128d innov = _mm_sub_pd(y2, xp);                             /* (5) */
    const __m128d Yv = _mm_add_pd(Pp, _mm_loadu_pd(Rc));                  /* (6) */
    const __m128d K = _mm_div_pd(Pp, Yv);                                 /* (7) */
    const __m128d dx = _mm_mul_pd(K, innov);
    const __m128d xn = _mm_add_pd(xp, dx);                                /* (8) */
    _mm_storeu_pd(Pc, _mm_mul_pd(_mm_sub_pd(one, K), Pp));               /* (9) */
    _mm_storeu_pd(xc, xn);
    const __m128d e = _mm_sub_pd(y2, xn);
    const __m128d e2 = _mm_mul_pd(e, e), dx2 = _mm_mul_pd(dx, dx);
    double *ra = r2, *rb = r2 + Nmax, *da = d2, *db = d2 + Nmax;
    _mm_storel_pd(ra + slot, e2); _mm_storeh_pd(rb + slot, e2);
    _mm_storel_pd(da + slot, dx2); _mm_storeh_pd(db + slot, dx2);
    __m128d sm = _mm_setzero_pd(), sg = _mm_setzero_pd();
    /* chronological: from the oldest entry to the ring's end, then on from its start */
    const int64_t first = oldest + f <= Nc ? oldest + f : Nc, wrapped = f - (first - oldest);
    for (int64_t idx = oldest; idx < first; idx++) {
        sm = _mm_add_pd(sm, _mm_loadh_pd(_mm_load_sd(ra + idx), rb + idx));
        sg = _mm_add_pd(sg, _mm_loadh_pd(_mm_load_sd(da + idx), db + idx));
    }
    for (int64_t idx = 0; idx < wrapped; idx++) {
        sm = _mm_add_pd(sm, _mm_loadh_pd(_mm_load_sd(ra + idx), rb + idx));
        sg = _mm_add_pd(sg, _mm_loadh_pd(_mm_load_sd(da + idx), db + idx));
    }
    const __m128d fd = _mm_set1_pd((double)f);
    const __m128d M = _mm_div_pd(sm, fd);                                 /* (11) */
    const __m128d Gh = _mm_div_pd(sg, fd);                                /* (14) */
    const __m128d Gt = _mm_mul_pd(_mm_mul_pd(K, K), Yv);                  /* (13) */
    const __m128d S = scaling ? _mm_max_pd(_mm_div_pd(Gh, Gt), one) : one;   /* (12) */
    const __m128d Qn = _mm_mul_pd(S, M);                                  /* (10) */
    _mm_storeu_pd(Qc, Qn);
    const __m128d z = _mm_div_pd(innov, _mm_sqrt_pd(Yv));                 /* (15) */
    if (full) {
        _mm_storeu_pd(oxp, xp); _mm_storeu_pd(oxh, xn); _mm_storeu_pd(oY, Yv); _mm_storeu_pd(oQ, Qn);
    }
    const __m128d absz = _mm_andnot_pd(_mm_set1_pd(-0.0), z);
    const int m = _mm_movemask_pd(_mm_cmpgt_pd(absz, _mm_set1_pd(zc)));
    fl[0] = m & 1;
    fl[1] = (m >> 1) & 1;
}
#endif

/*
 * The recursion over T steps.  ``full``: the per-observation outputs (x̂⁻, x̂, Y, Q̂) are
 * written; else only the outlier flags (oxp..oQ are not touched and may be NULL).
 */
static void recursion(Py_ssize_t T, Py_ssize_t C, Py_ssize_t n, Py_ssize_t Nmax, int scaling, int full,
                      const double *y, const uint8_t *valid, const double *R, const double *zc,
                      const int64_t *N, double *x, double *P, double *Q, double *res2, double *dx2,
                      int64_t *pos, int64_t *fill, uint8_t *started, uint8_t *outl,
                      double *oxp, double *oxh, double *oY, double *oQ) {
    double *no = NULL;
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
                        if (full) { oxp[o + i] = NAN; oxh[o + i] = NAN; oY[o + i] = NAN; oQ[o + i] = NAN; }
                        outl[o + i] = 0;
                    }
                    continue;
                }
                for (Py_ssize_t i = 0; i < n; i++) xc[i] = yk;   /* x̂(0) = first observation */
                started[c] = 1;
            }
            if (!v) {               /* missing observation: time update only */
                for (Py_ssize_t i = 0; i < n; i++) {
                    const double Pp = Pc[i] + Qc[i];                 /* (4) */
                    if (full) { oxp[o + i] = xc[i]; oxh[o + i] = xc[i]; oY[o + i] = Pp + Rc[i]; oQ[o + i] = Qc[i]; }
                    outl[o + i] = 0;
                    Pc[i] = Pp;
                }
                continue;
            }
            const int64_t Nc = N[c];
            const int64_t slot = pos[c];
            const int64_t f = fill[c] + 1 < Nc ? fill[c] + 1 : Nc;
            const int64_t np_ = (slot + 1) % Nc;
            const int64_t oldest = ((np_ - f) % Nc + Nc) % Nc;
            double *r2 = res2 + c * n * Nmax, *d2 = dx2 + c * n * Nmax;
            Py_ssize_t i = 0;
#ifdef __SSE2__
            for (; i + 2 <= n; i += 2)
                step2(yk, xc + i, Pc + i, Qc + i, Rc + i, zc[c], r2 + i * Nmax, d2 + i * Nmax, Nmax, Nc,
                      slot, oldest, f, scaling, full, full ? oxp + o + i : no, full ? oxh + o + i : no,
                      full ? oY + o + i : no, full ? oQ + o + i : no, outl + o + i);
#endif
            for (; i < n; i++)
                outl[o + i] = step1(yk, xc + i, Pc + i, Qc + i, Rc[i], zc[c], r2 + i * Nmax, d2 + i * Nmax,
                                    Nc, slot, oldest, f, scaling, full, full ? oxp + o + i : no,
                                    full ? oxh + o + i : no, full ? oY + o + i : no, full ? oQ + o + i : no);
            pos[c] = np_;
            fill[c] = f;
        }
    }
}

/* The bank's parameters and state, as both entry points take them first. */
#define STATE_FORMAT "y*y*y*y*y*iw*w*w*w*w*w*w*w*"

static PyObject *call(PyObject *args, int full) {
    Py_buffer by, bvalid, bR, bzc, bN, bx, bP, bQ, bres2, bdx2, bpos, bfill, bstarted,
        bxp, bxh, bY, bQo, bout;
    int scaling;
    Py_buffer *outs[] = {&bxp, &bxh, &bY, &bQo};
    int ok = full ?
        PyArg_ParseTuple(args, STATE_FORMAT "w*w*w*w*w*", &by, &bvalid, &bR, &bzc, &bN, &scaling,
                         &bx, &bP, &bQ, &bres2, &bdx2, &bpos, &bfill, &bstarted,
                         &bxp, &bxh, &bY, &bQo, &bout) :
        PyArg_ParseTuple(args, STATE_FORMAT "w*", &by, &bvalid, &bR, &bzc, &bN, &scaling,
                         &bx, &bP, &bQ, &bres2, &bdx2, &bpos, &bfill, &bstarted, &bout);
    if (!ok)
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
        !need(&bout, T * C * n, "outlier"))
        goto done;
    if (full && (!need(&bxp, T * C * n * 8, "x_prior") || !need(&bxh, T * C * n * 8, "x_hat") ||
                 !need(&bY, T * C * n * 8, "Y") || !need(&bQo, T * C * n * 8, "Q_out")))
        goto done;

    const int64_t *N = bN.buf;
    for (Py_ssize_t c = 0; c < C; c++) {
        if (N[c] < 1 || N[c] > Nmax) {
            PyErr_Format(PyExc_ValueError, "N[%zd] = %lld out of 1..%zd", c, (long long)N[c], Nmax);
            goto done;
        }
    }

    Py_BEGIN_ALLOW_THREADS
    recursion(T, C, n, Nmax, scaling, full, by.buf, bvalid.buf, bR.buf, bzc.buf, N, bx.buf, bP.buf,
              bQ.buf, bres2.buf, bdx2.buf, bpos.buf, bfill.buf, bstarted.buf, bout.buf,
              full ? bxp.buf : NULL, full ? bxh.buf : NULL, full ? bY.buf : NULL, full ? bQo.buf : NULL);
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&by); PyBuffer_Release(&bvalid); PyBuffer_Release(&bR);
    PyBuffer_Release(&bzc); PyBuffer_Release(&bN); PyBuffer_Release(&bx);
    PyBuffer_Release(&bP); PyBuffer_Release(&bQ); PyBuffer_Release(&bres2);
    PyBuffer_Release(&bdx2); PyBuffer_Release(&bpos); PyBuffer_Release(&bfill);
    PyBuffer_Release(&bstarted); PyBuffer_Release(&bout);
    if (full)
        for (int i = 0; i < 4; i++) PyBuffer_Release(outs[i]);
    return ret;
}

/* run(y, valid, R, z_c, N, scaling, x, P, Q, res2, dx2, pos, fill, started,
 *     x_prior, x_hat, Y, Q_out, outlier): every output of every step */
static PyObject *run(PyObject *self, PyObject *args) { return call(args, 1); }

/* flags(y, valid, R, z_c, N, scaling, x, P, Q, res2, dx2, pos, fill, started, outlier):
 * the same recursion, only the outlier flags written */
static PyObject *flags(PyObject *self, PyObject *args) { return call(args, 0); }

static PyMethodDef methods[] = {
    {"run", run, METH_VARARGS, "Run a block of observations through an AKF bank (Kim et al. 2023, eqs. 3-15)."},
    {"flags", flags, METH_VARARGS, "The same recursion as run(), writing only the outlier flags."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_akfkernel",
                                     "Compiled AKF bank recursion (see akf.py).", -1, methods};

PyMODINIT_FUNC PyInit__akfkernel(void) { return PyModule_Create(&module); }
