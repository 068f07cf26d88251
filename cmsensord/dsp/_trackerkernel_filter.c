/*
 * The order tracker's recursions (Yeh, Pan & Le, eqs. 10-25): the anti-alias SOS cascade,
 * the exact gains (riccati), the filter (forward), the MBF smoother (backward) and the
 * state pairs' peak amplitudes (envelope).  _trackerkernel.c lists the functions.
 */
#include "_trackerkernel.h"

/* One channel (column ch of x, T x C) through the S sections, every D-th output from skip
 * on into column ch of out; the state (zi, S x 2 x C) read and written back.  Section by
 * section the arithmetic of scipy.signal.sosfilt (direct form II transposed), in its order. */
static void sos_channel_any(const double *sos, Py_ssize_t S, const double *x, Py_ssize_t T,
                            Py_ssize_t C, Py_ssize_t ch, double *zi, double *out,
                            Py_ssize_t skip, Py_ssize_t D) {
    Py_ssize_t next = skip, j = 0;
    for (Py_ssize_t n = 0; n < T; n++) {
        double x_cur = x[n * C + ch];
        for (Py_ssize_t s = 0; s < S; s++) {
            const double *q = sos + 6 * s;
            double *z0 = zi + (2 * s) * C + ch, *z1 = zi + (2 * s + 1) * C + ch;
            const double x_new = q[0] * x_cur + *z0;
            *z0 = q[1] * x_cur - q[4] * x_new + *z1;
            *z1 = q[2] * x_cur - q[5] * x_new;
            x_cur = x_new;
        }
        if (n == next) { out[j * C + ch] = x_cur; j++; next += D; }
    }
}

/* sos_channel_any for a cascade of NS sections (a constant): the loop over the sections
 * unrolled, the state in locals (registers) for the whole call, not loaded and stored at
 * every sample; the same operations in the same order, so the same bits. */
#define SOS_CHANNEL(NS)                                                                      \
static void sos_channel_##NS(const double *sos, const double *x, Py_ssize_t T, Py_ssize_t C, \
                             Py_ssize_t ch, double *zi, double *out, Py_ssize_t skip,       \
                             Py_ssize_t D) {                                                \
    double z0[NS], z1[NS], q[NS][6];                                                        \
    _Pragma("GCC unroll 8") for (int s = 0; s < NS; s++) {                                  \
        z0[s] = zi[(2 * s) * C + ch]; z1[s] = zi[(2 * s + 1) * C + ch];                     \
        _Pragma("GCC unroll 6") for (int i = 0; i < 6; i++) q[s][i] = sos[6 * s + i];       \
    }                                                                                       \
    Py_ssize_t next = skip, j = 0;                                                          \
    for (Py_ssize_t n = 0; n < T; n++) {                                                    \
        double x_cur = x[n * C + ch];                                                       \
        _Pragma("GCC unroll 8") for (int s = 0; s < NS; s++) {                              \
            const double x_new = q[s][0] * x_cur + z0[s];                                   \
            z0[s] = q[s][1] * x_cur - q[s][4] * x_new + z1[s];                              \
            z1[s] = q[s][2] * x_cur - q[s][5] * x_new;                                      \
            x_cur = x_new;                                                                  \
        }                                                                                   \
        if (n == next) { out[j * C + ch] = x_cur; j++; next += D; }                         \
    }                                                                                       \
    _Pragma("GCC unroll 8") for (int s = 0; s < NS; s++) {                                  \
        zi[(2 * s) * C + ch] = z0[s]; zi[(2 * s + 1) * C + ch] = z1[s];                     \
    }                                                                                       \
}
SOS_CHANNEL(1)
SOS_CHANNEL(2)
SOS_CHANNEL(3)
SOS_CHANNEL(4)
SOS_CHANNEL(5)
SOS_CHANNEL(6)
SOS_CHANNEL(7)
SOS_CHANNEL(8)

/* Every channel of x (T x C) through the S sections (sos_channel_*), the kept outputs to out. */
void sos_all(const double *sos, Py_ssize_t S, const double *x, Py_ssize_t T, Py_ssize_t C,
                    double *zi, double *out, Py_ssize_t skip, Py_ssize_t D) {
    for (Py_ssize_t ch = 0; ch < C; ch++) {
        switch (S) {        /* the state in registers for the usual cascades (S a constant) */
        case 1: sos_channel_1(sos, x, T, C, ch, zi, out, skip, D); break;
        case 2: sos_channel_2(sos, x, T, C, ch, zi, out, skip, D); break;
        case 3: sos_channel_3(sos, x, T, C, ch, zi, out, skip, D); break;
        case 4: sos_channel_4(sos, x, T, C, ch, zi, out, skip, D); break;
        case 5: sos_channel_5(sos, x, T, C, ch, zi, out, skip, D); break;
        case 6: sos_channel_6(sos, x, T, C, ch, zi, out, skip, D); break;
        case 7: sos_channel_7(sos, x, T, C, ch, zi, out, skip, D); break;
        case 8: sos_channel_8(sos, x, T, C, ch, zi, out, skip, D); break;
        default: sos_channel_any(sos, S, x, T, C, ch, zi, out, skip, D);
        }
    }
}

/* The decimator's low-pass: S second-order sections (rows b0 b1 b2 1 a1 a2) in
 * direct form II transposed, the same arithmetic in the same order as
 * scipy.signal.sosfilt, over x (T x C) with the state zi (S x 2 x C, scipy's
 * layout for axis=0) carried in place.  out (rows of C) receives the filtered
 * samples skip, skip + D, skip + 2D, ... < T: the decimation in the same pass.
 * C (channels) is the size of zi over 2S. */
PyObject *sosfilt(PyObject *self, PyObject *args) {
    Py_buffer bsos, bx, bzi, bout;
    Py_ssize_t skip, D;
    if (!PyArg_ParseTuple(args, "y*y*w*w*nn", &bsos, &bx, &bzi, &bout, &skip, &D))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t S = bsos.len / (Py_ssize_t)sizeof(double) / 6;
    const Py_ssize_t C = S > 0 ? bzi.len / (Py_ssize_t)sizeof(double) / (2 * S) : 0;
    if (C <= 0 || D <= 0 || skip < 0 || S <= 0 || bsos.len != S * 6 * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "sosfilt: expected sos (S x 6), C > 0, D > 0, skip >= 0");
        goto done;
    }
    const Py_ssize_t T = bx.len / (Py_ssize_t)sizeof(double) / C;
    const Py_ssize_t nout = skip < T ? (T - skip + D - 1) / D : 0;
    if (bx.len != T * C * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "sosfilt: x is not T x C");
        goto done;
    }
    if (!need(&bout, nout * C, "out"))
        goto done;
    const double *sos = bsos.buf, *x = bx.buf;
    double *zi = bzi.buf, *out = bout.buf;
    /* other threads run meanwhile only when the call is long (a replay's read): a live call's
     * tenth of a second is some microseconds, less than handing the interpreter over costs */
    PyThreadState *save = T * C * S > (1 << 17) ? PyEval_SaveThread() : NULL;
    sos_all(sos, S, x, T, C, zi, out, skip, D);
    if (save != NULL)
        PyEval_RestoreThread(save);
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&bsos); PyBuffer_Release(&bx); PyBuffer_Release(&bzi); PyBuffer_Release(&bout);
    return ret;
}

/* k, S (and P(n|n-1) if want_p) for T samples; P is updated to P(T|T-1). */
PyObject *riccati(PyObject *self, PyObject *args) {
    Py_buffer bc, bqd, bq2, bP, bk, bS, bPo, bm = {0};
    int want_p;
    if (!PyArg_ParseTuple(args, "y*y*y*w*w*w*w*i|y*", &bc, &bqd, &bq2, &bP, &bk, &bS, &bPo, &want_p,
                          &bm))
        return NULL;
    PyObject *ret = NULL;
    double *M = NULL, *ph = NULL;
    const Py_ssize_t T = bq2.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t d2 = bP.len / (Py_ssize_t)sizeof(double);
    Py_ssize_t d = 0;
    while ((d + 1) * (d + 1) <= d2) d++;
    if (d < 2 || d * d != d2 || d % 2) {
        PyErr_SetString(PyExc_ValueError, "P: expected a 2K x 2K matrix");
        goto done;
    }
    const Py_ssize_t K = d / 2;
    if (!need(&bc, T * K, "c") || !need(&bqd, T * d, "qd") || !need(&bk, T * d, "k") ||
        !need(&bS, T, "S") || (want_p && !need(&bPo, T * d * d, "Pout")))
        goto done;
    if (bm.buf != NULL && bm.len != 0 && bm.len < T) {
        PyErr_SetString(PyExc_ValueError, "riccati: miss has fewer than T entries");
        goto done;
    }
    const unsigned char *miss = (bm.buf != NULL && bm.len != 0) ? bm.buf : NULL;
    M = malloc(sizeof(double) * d * d);
    ph = malloc(sizeof(double) * d);
    if (!M || !ph) { PyErr_NoMemory(); goto done; }
    const double *c = bc.buf, *qd = bqd.buf, *q2 = bq2.buf;
    double *P = bP.buf, *k = bk.buf, *S = bS.buf, *Po = bPo.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t n = 0; n < T; n++) {
        const double *cn = c + n * K;
        double *kn = k + n * d;
        if (want_p)
            for (Py_ssize_t i = 0; i < d * d; i++) Po[n * d * d + i] = P[i];
        for (Py_ssize_t i = 0; i < d; i++) {          /* P hᵀ */
            double s = 0.0;
            for (Py_ssize_t j = 1; j < d; j += 2) s += P[i * d + j];
            ph[i] = s;
        }
        double s = 0.0;                                /* S = h P hᵀ + Q2 */
        for (Py_ssize_t i = 1; i < d; i += 2) s += ph[i];
        s += q2[n];
        S[n] = s;
        if (miss && miss[n]) {                         /* no measurement: k = 0, P(n|n) = P */
            for (Py_ssize_t i = 0; i < d; i++) kn[i] = 0.0;
        } else {
            for (Py_ssize_t i = 0; i < d; i++) kn[i] = ph[i] / s;    /* k = P hᵀ / S */
            for (Py_ssize_t i = 0; i < d; i++)        /* P(n|n) = P - k (P hᵀ)ᵀ, in P */
                for (Py_ssize_t j = 0; j < d; j++) P[i * d + j] -= kn[i] * ph[j];
        }
        for (Py_ssize_t a = 0; a < K; a++)             /* M = F P(n|n) */
            for (Py_ssize_t j = 0; j < d; j++) {
                M[2 * a * d + j] = P[(2 * a + 1) * d + j];
                M[(2 * a + 1) * d + j] = -P[2 * a * d + j] + cn[a] * P[(2 * a + 1) * d + j];
            }
        for (Py_ssize_t i = 0; i < d; i++)             /* P(n+1|n) = M Fᵀ + Q1 */
            for (Py_ssize_t b = 0; b < K; b++) {
                P[i * d + 2 * b] = M[i * d + 2 * b + 1];
                P[i * d + 2 * b + 1] = -M[i * d + 2 * b] + cn[b] * M[i * d + 2 * b + 1];
            }
        for (Py_ssize_t i = 0; i < d; i++) P[i * d + i] += qd[n * d + i];
        for (Py_ssize_t i = 0; i < d; i++)             /* P <- (P + Pᵀ)/2 */
            for (Py_ssize_t j = i + 1; j < d; j++) {
                const double m = 0.5 * (P[i * d + j] + P[j * d + i]);
                P[i * d + j] = m;
                P[j * d + i] = m;
            }
    }
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    free(M); free(ph);
    PyBuffer_Release(&bc); PyBuffer_Release(&bqd); PyBuffer_Release(&bq2); PyBuffer_Release(&bP);
    PyBuffer_Release(&bk); PyBuffer_Release(&bS); PyBuffer_Release(&bPo);
    if (bm.buf != NULL) PyBuffer_Release(&bm);
    return ret;
}

/* The filter: z (C x d) holds X̂(n|n-1) per channel and is updated.  A missing
 * sample (miss[n, ch]) has no innovation: e = 0, X̂(n|n) = X̂(n|n-1). */
PyObject *forward(PyObject *self, PyObject *args) {
    Py_buffer by, bc, bk, bz, bzp, be, bxf, bm = {0};
    Py_ssize_t K;
    if (!PyArg_ParseTuple(args, "y*y*y*w*w*w*w*n|y*", &by, &bc, &bk, &bz, &bzp, &be, &bxf, &K, &bm))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t d = 2 * K;
    const Py_ssize_t C = K > 0 ? bz.len / (Py_ssize_t)sizeof(double) / d : 0;
    const Py_ssize_t T = K > 0 ? bc.len / (Py_ssize_t)sizeof(double) / K : 0;
    if (K <= 0 || C <= 0) {
        PyErr_SetString(PyExc_ValueError, "forward: no components or no channels");
        goto done;
    }
    if (!need(&by, T * C, "y") || !need(&bk, T * d, "k") || !need(&bzp, T * C * d, "zp") ||
        !need(&be, T * C, "e") || !need(&bxf, T * C * d, "xf"))
        goto done;
    if (bm.buf != NULL && bm.len != 0 && bm.len < T * C) {
        PyErr_SetString(PyExc_ValueError, "forward: miss has fewer than T x C entries");
        goto done;
    }
    const unsigned char *miss = (bm.buf != NULL && bm.len != 0) ? bm.buf : NULL;
    const double *y = by.buf, *c = bc.buf, *k = bk.buf;
    double *z = bz.buf, *zp = bzp.buf, *e = be.buf, *xf = bxf.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t n = 0; n < T; n++) {
        const double *cn = c + n * K, *kn = k + n * d;
        for (Py_ssize_t ch = 0; ch < C; ch++) {
            double *zc = z + ch * d;
            double *zpo = zp + (n * C + ch) * d, *xo = xf + (n * C + ch) * d;
            double s = 0.0;
            for (Py_ssize_t a = 0; a < K; a++) s += zc[2 * a + 1];
            const double en = (miss && miss[n * C + ch]) ? 0.0        /* none: missing */
                                                         : y[n * C + ch] - s;   /* innovation */
            e[n * C + ch] = en;
            for (Py_ssize_t i = 0; i < d; i++) {
                zpo[i] = zc[i];
                xo[i] = zc[i] + kn[i] * en;                          /* X̂(n|n) */
            }
            for (Py_ssize_t a = 0; a < K; a++) {                     /* X̂(n+1|n) = F X̂(n|n) */
                zc[2 * a] = xo[2 * a + 1];
                zc[2 * a + 1] = -xo[2 * a] + cn[a] * xo[2 * a + 1];
            }
        }
    }
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&by); PyBuffer_Release(&bc); PyBuffer_Release(&bk); PyBuffer_Release(&bz);
    PyBuffer_Release(&bzp); PyBuffer_Release(&be); PyBuffer_Release(&bxf);
    if (bm.buf != NULL) PyBuffer_Release(&bm);
    return ret;
}

/* Modified Bryson-Frazier smoothing of one window of W samples (λ = 0 after it):
 *   λ(n) = hᵀ e(n)/S(n) + A(n)ᵀ λ(n+1),  A = F (I - k h),  X̂s(n) = X̂(n) + P(n) λ(n);
 * at a missing sample (miss[n, ch]) k = 0 and there is no innovation: λ(n) = F(n)ᵀ λ(n+1).
 * xs receives the first nout samples (its size sets nout). */
PyObject *backward(PyObject *self, PyObject *args) {
    Py_buffer bc, bk, bS, bP, bzp, be, bxs, bm = {0};
    Py_ssize_t K;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*w*n|y*", &bc, &bk, &bS, &bP, &bzp, &be, &bxs, &K, &bm))
        return NULL;
    PyObject *ret = NULL;
    double *lam = NULL, *mu = NULL;
    const Py_ssize_t W = bS.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t d = 2 * K;
    if (W <= 0 || K <= 0 || !need(&bc, W * K, "c")) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "backward: empty window");
        goto done;
    }
    const Py_ssize_t C = (be.len / (Py_ssize_t)sizeof(double)) / W;
    const Py_ssize_t nout = C ? (bxs.len / (Py_ssize_t)sizeof(double)) / (C * d) : 0;
    if (C <= 0 || nout > W || !need(&bk, W * d, "k") || !need(&bP, W * d * d, "P") ||
        !need(&bzp, W * C * d, "zp") || !need(&be, W * C, "e") ||
        (bm.buf != NULL && bm.len != 0 && bm.len < W * C)) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "backward: inconsistent sizes");
        goto done;
    }
    const unsigned char *miss = (bm.buf != NULL && bm.len != 0) ? bm.buf : NULL;
    lam = calloc((size_t)(C * d), sizeof(double));
    mu = malloc(sizeof(double) * d);
    if (!lam || !mu) { PyErr_NoMemory(); goto done; }
    const double *c = bc.buf, *k = bk.buf, *S = bS.buf, *P = bP.buf, *zp = bzp.buf, *e = be.buf;
    double *xs = bxs.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t n = W - 1; n >= 0; n--) {
        const double *cn = c + n * K, *kn = k + n * d, *Pn = P + n * d * d;
        for (Py_ssize_t ch = 0; ch < C; ch++) {
            double *l = lam + ch * d;
            const int gone = miss && miss[n * C + ch];
            if (n < W - 1) {                      /* λ <- A(n)ᵀ λ = (I - hᵀkᵀ) Fᵀ λ */
                for (Py_ssize_t a = 0; a < K; a++) {
                    mu[2 * a] = -l[2 * a + 1];
                    mu[2 * a + 1] = l[2 * a] + cn[a] * l[2 * a + 1];
                }
                double kmu = 0.0;                 /* missing: k = 0, λ <- Fᵀ λ */
                if (!gone)
                    for (Py_ssize_t i = 0; i < d; i++) kmu += kn[i] * mu[i];
                for (Py_ssize_t a = 0; a < K; a++) {
                    l[2 * a] = mu[2 * a];
                    l[2 * a + 1] = mu[2 * a + 1] - kmu;
                }
            }
            if (!gone) {                          /* + hᵀ e(n)/S(n); none when missing */
                const double g = e[n * C + ch] / S[n];
                for (Py_ssize_t a = 0; a < K; a++) l[2 * a + 1] += g;
            }
            if (n < nout) {
                const double *zc = zp + (n * C + ch) * d;
                double *xo = xs + (n * C + ch) * d;
                for (Py_ssize_t i = 0; i < d; i++) {
                    double s = 0.0;
                    for (Py_ssize_t j = 0; j < d; j++) s += Pn[i * d + j] * l[j];
                    xo[i] = zc[i] + s;
                }
            }
        }
    }
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    free(lam); free(mu);
    PyBuffer_Release(&bc); PyBuffer_Release(&bk); PyBuffer_Release(&bS); PyBuffer_Release(&bP);
    PyBuffer_Release(&bzp); PyBuffer_Release(&be); PyBuffer_Release(&bxs);
    if (bm.buf != NULL) PyBuffer_Release(&bm);
    return ret;
}


/* Peak amplitude from the state pairs (recursions.py's envelope, the same operations in its
 * order): xs (N x C x 2K), c (N x K) -> env (N x C x K),
 *   env = sqrt(max((x1 x1 - (c x1) x2 + x2 x2) / max(1 - (0.25 c) c, 1e-300), 0))
 * with x1, x2 the pair's entries; NaN passes through as np.maximum passes it. */
PyObject *envelope(PyObject *self, PyObject *args) {
    Py_buffer bx, bc, be;
    Py_ssize_t K;
    if (!PyArg_ParseTuple(args, "y*y*w*n", &bx, &bc, &be, &K))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t N = K > 0 ? bc.len / (Py_ssize_t)sizeof(double) / K : 0;
    const Py_ssize_t C = N > 0 ? bx.len / (Py_ssize_t)sizeof(double) / (N * 2 * K) : 0;
    if (K <= 0 || bc.len != N * K * (Py_ssize_t)sizeof(double) ||
        bx.len != N * C * 2 * K * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "envelope: expected xs (N x C x 2K) and c (N x K)");
        goto done;
    }
    if (!need(&be, N * C * K, "env"))
        goto done;
    const double *xs = bx.buf, *c = bc.buf;
    double *env = be.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t n = 0; n < N; n++) {
        for (Py_ssize_t a = 0; a < K; a++) {
            const double cc = c[n * K + a];
            double s2 = 1.0 - 0.25 * cc * cc;
            if (!(s2 >= 1e-300)) s2 = (s2 != s2) ? s2 : 1e-300;     /* np.maximum(., 1e-300) */
            for (Py_ssize_t ch = 0; ch < C; ch++) {
                const double *p = xs + ((n * C + ch) * K + a) * 2;
                const double x1 = p[0], x2 = p[1];
                double a2 = (x1 * x1 - cc * x1 * x2 + x2 * x2) / s2;
                if (a2 < 0.0) a2 = 0.0;                                 /* np.maximum(., 0); NaN stays */
                env[(n * C + ch) * K + a] = sqrt(a2);
            }
        }
    }
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&bx); PyBuffer_Release(&bc); PyBuffer_Release(&be);
    return ret;
}
