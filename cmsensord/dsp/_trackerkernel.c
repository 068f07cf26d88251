/*
 * The per-sample loops of the AV2KF order tracker (Yeh, Pan & Le, eqs. 10-25) in C.
 *
 * order_tracker.py documents the equations and checks dtypes and shapes; this
 * file checks buffer sizes so that a mistake cannot write out of bounds.  Same
 * semantics as the numpy paths (tested against the plain reference to 1e-9).
 * All arrays are C-contiguous float64.  d = 2K is the state size; the state of
 * component a is (x_a(n-1), x_a(n)) at positions (2a, 2a+1); F(n) is
 * blockdiag([[0, 1], [-1, c_a(n)]]) and the data row h has ones at odd positions.
 *
 *   sosfilt(sos, x, zi, out, skip, D)              anti-alias SOS cascade + decimation
 *   riccati(c, qd, q2, P, k, S, Pout, want_p[, miss])
 *                                                  exact gains, P carried (d x d)
 *   forward(y, c, k, z, zp, e, xf, K[, miss])      the filter for C channels
 *   model_omega(rpm, min_rpm, orders, fixed, by_order, two_pi, fs, speed, w)
 *                                                  components.py: model speed and omega / fs
 *   forward_blocks(y, c, k, z, rpm, K, B, p, cw, ce, min_rpm, top, half_fs, rms, amp, rmean, valid, tw, te)
 *                                                  forward + envelope + block_stats, a partial block carried
 *   live_in(sos, y, zi, skip, D, last_miss, pos0, W, line, vals, p0, min_rpm, orders, fixed, by_order,
 *           two_pi, fs, lo, yd, rd, speed, u, w)  sosfilt + the delayed speed + model_omega of a live call
 *   live_out(logu, lq, tab, dtab, have, seg, w, yd, cosw, z, prpm, rd, K, B, cw, ce, min_rpm, top, half_fs,
 *            n0, D, delay_in, rms, amp, rmean, valid, tw, te, rtail, starts, t_in)
 *                                                  the table's gains + forward_blocks of a live call
 *   backward(c, k, S, P, zp, e, xs, K[, miss])     MBF smoother over one window
 *
 * miss (optional; uint8, 1 = missing, empty = none missing) marks samples without a
 * measurement: riccati takes it per sample (T), forward/backward per sample and
 * channel (T x C, W x C).  A missing sample gets the time update only (gain 0):
 * riccati: k = 0, P(n|n) = P(n|n-1); forward: e = 0, X̂(n|n) = X̂(n|n-1); backward:
 * λ(n) = F(n)ᵀ λ(n+1) (the MBF recursion with k = 0 and no innovation term).
 *   tacho_eval(s, kT, kth, kw, kr, speed, turns, j, code)
 *                                                  tacho.py: speed and angle between knots
 *   lerp_rows(tab, dtab, i, f, a, b, w, m)         gain_table.py: the table's rows interpolated
 *   lerp_at(tab, dtab, x, have, seg, a, b, w, m)   gain_table.py: the same at grid coordinates
 *   block_stats(wave, env, rpm, K, min_rpm, top, half_fs, rms, amp, rmean, valid)
 *                                                  tracker.py: per-block statistics
 *   envelope(xs, c, env, K)                        recursions.py: peak amplitudes of the state pairs
 *   causal_fit(Tc, nc, todo, ck, c0, ppr, sbuf, col) tacho causal.py: the segments of new edges
 *   knot_fit(Tc, nc, c0, first, K, wk, base, ppr, out) tacho smoothing.py: the knots of the smoothed speed
 *   causal_rpm(sbuf, lo, hi, base, pos, fs, slack, rpm)
 *                                                  orders.py: the causal speed [rpm] at samples
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdlib.h>

static int need(Py_buffer *b, Py_ssize_t n_doubles, const char *name) {
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
static double pairwise_sum(const double *a, Py_ssize_t n, Py_ssize_t stride) {
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

/* One edge's column of the weighted quadratic fit's moment terms (w, wx, wx^2, wx^3, wx^4,
   wy, wxy, wx^2 y), stride m: what smoothing.py's weighted sums add. */
static void fit_terms(double *t, Py_ssize_t m, double w, double x, double y) {
    const double x2 = x * x, wx = w * x, wx2 = w * x2;
    t[0] = w; t[m] = wx; t[2 * m] = wx2; t[3 * m] = wx2 * x; t[4 * m] = wx2 * x2;
    t[5 * m] = w * y; t[6 * m] = wx * y; t[7 * m] = wx2 * y;
}

/* The fit's coefficients c[0..2] from its m columns of terms (pairwise sums, as numpy's),
   solved as smoothing.py's _solve_normal and _eliminate do: a line with 2 points, 0 below. */
static void solve_fit(const double *terms, Py_ssize_t m, Py_ssize_t npts, double c[3]) {
    double mom[8];
    for (int q = 0; q < 8; q++) mom[q] = pairwise_sum(terms + q * m, m, 1);
    c[0] = c[1] = c[2] = 0.0;
    if (npts < 2)
        return;
    const double s0 = mom[0], s1 = mom[1], s2 = mom[2], b0 = mom[5], b1 = mom[6];
    const double a02 = npts >= 3 ? mom[2] : 0.0, a12 = npts >= 3 ? mom[3] : 0.0;
    const double a22 = npts >= 3 ? mom[4] : 1.0, b2 = npts >= 3 ? mom[7] : 0.0;
    const double m1 = s1 / s0;
    const double d11 = s2 - m1 * s1;
    const double d12 = a12 - m1 * a02;
    const double e1 = b1 - m1 * b0;
    const double m2 = a02 / s0;
    const double d22 = a22 - m2 * a02;
    const double e2 = b2 - m2 * b0;
    const double m3 = d12 / d11;
    c[2] = (e2 - m3 * e1) / (d22 - m3 * d12);
    c[1] = (e1 - d12 * c[2]) / d11;
    c[0] = (b0 - s1 * c[1] - a02 * c[2]) / s0;
}

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
static void sos_all(const double *sos, Py_ssize_t S, const double *x, Py_ssize_t T, Py_ssize_t C,
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
static PyObject *sosfilt(PyObject *self, PyObject *args) {
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
static PyObject *riccati(PyObject *self, PyObject *args) {
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
static PyObject *forward(PyObject *self, PyObject *args) {
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
static PyObject *backward(PyObject *self, PyObject *args) {
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

/* TachoTracker.evaluate between knots (tacho.py documents it; same arithmetic, in
 * the same order, as its numpy expressions).  For each sample s[i]: j[i] = the
 * last knot with kT <= s[i] (numpy.searchsorted(kT, s, "right") - 1, clipped to
 * 0 .. n-1; NaN sorts after everything); code[i] = 0 before the first knot, 1
 * between knots j and j+1 of one run (kr equal): then speed[i] (linear) and
 * turns[i] (cubic Hermite) are written; 2 otherwise (after a run's last knot:
 * left to the caller, as are the samples before; speed and turns are 0 there). */
static PyObject *tacho_eval(PyObject *self, PyObject *args) {
    Py_buffer bs, bT, bth, bw, br, bsp, btu, bj, bcode;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*w*w*w*w*", &bs, &bT, &bth, &bw, &br, &bsp, &btu, &bj,
                          &bcode))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t N = bs.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t n = bT.len / (Py_ssize_t)sizeof(double);
    if (n <= 0) {
        PyErr_SetString(PyExc_ValueError, "tacho_eval: no knots");
        goto done;
    }
    if (!need(&bth, n, "kth") || !need(&bw, n, "kw") || !need(&bsp, N, "speed") ||
        !need(&btu, N, "turns"))
        goto done;
    if (br.len < n * (Py_ssize_t)sizeof(long long) || bj.len < N * (Py_ssize_t)sizeof(long long) ||
        bcode.len < N) {
        PyErr_SetString(PyExc_ValueError, "tacho_eval: kr, j or code too small");
        goto done;
    }
    const double *s = bs.buf, *kT = bT.buf, *kth = bth.buf, *kw = bw.buf;
    const long long *kr = br.buf;
    double *speed = bsp.buf, *turns = btu.buf;
    long long *jo = bj.buf;
    unsigned char *code = bcode.buf;
    Py_BEGIN_ALLOW_THREADS
    Py_ssize_t j = -1;                 /* last knot <= x; a hint carried from the previous sample */
    for (Py_ssize_t i = 0; i < N; i++) {
        const double x = s[i];
        if (x != x) {
            j = n - 1;
        } else if (!((j < 0 ? 1 : kT[j] <= x) && (j + 1 >= n || !(kT[j + 1] <= x)))) {
            Py_ssize_t lo = 0, hi = n;   /* count of knots <= x */
            while (lo < hi) {
                const Py_ssize_t mid = lo + (hi - lo) / 2;
                if (kT[mid] <= x) lo = mid + 1; else hi = mid;
            }
            j = lo - 1;
        }
        if (j < 0) {
            jo[i] = 0;
            code[i] = 0;
            speed[i] = 0.0;
            turns[i] = 0.0;
            continue;
        }
        jo[i] = j;
        if (j + 1 < n && kr[j + 1] == kr[j]) {
            const Py_ssize_t a = j, b = j + 1;
            const double h = kT[b] - kT[a];
            const double u = (x - kT[a]) / h;
            const double u2 = u * u, u3 = u * u * u;
            turns[i] = ((2 * u3 - 3 * u2 + 1) * kth[a] + (u3 - 2 * u2 + u) * h * kw[a]
                        + (-2 * u3 + 3 * u2) * kth[b] + (u3 - u2) * h * kw[b]);
            speed[i] = (1.0 - u) * kw[a] + u * kw[b];
            code[i] = 1;
        } else {
            code[i] = 2;
            speed[i] = 0.0;
            turns[i] = 0.0;
        }
    }
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&bs); PyBuffer_Release(&bT); PyBuffer_Release(&bth); PyBuffer_Release(&bw);
    PyBuffer_Release(&br); PyBuffer_Release(&bsp); PyBuffer_Release(&btu); PyBuffer_Release(&bj);
    PyBuffer_Release(&bcode);
    return ret;
}

/* Whether tab holds rows >= 2 rows of w doubles (their number to *rows), dtab rows - 1, and
 * 0 <= m <= w. */
static int table_shape(const Py_buffer *tab, const Py_buffer *dtab, Py_ssize_t w, Py_ssize_t m,
                       Py_ssize_t *rows) {
    *rows = w > 0 ? tab->len / (Py_ssize_t)sizeof(double) / w : 0;
    return w > 0 && m >= 0 && m <= w && *rows >= 2
        && dtab->len >= (*rows - 1) * w * (Py_ssize_t)sizeof(double);
}

/* Row i of the table interpolated at fraction fn, tab[i] + fn dtab[i]: its first m entries
 * to an, the other w - m to bn. */
static inline void lerp_row(const double *tab, const double *dtab, long long i, double fn,
                            double *an, double *bn, Py_ssize_t w, Py_ssize_t m) {
    const double *t = tab + i * w, *dt = dtab + i * w;
    for (Py_ssize_t j = 0; j < m; j++) an[j] = dt[j] * fn + t[j];
    for (Py_ssize_t j = m; j < w; j++) bn[j - m] = dt[j] * fn + t[j];
}

/* Rows of a table interpolated: row n is dtab[i[n]] * f[n] + tab[i[n]] (tab n_rows x w, dtab
 * (n_rows - 1) x w, 0 <= i[n] < n_rows - 1), the arithmetic of gain_table.py's numpy lookup;
 * its first m columns go to a (N x m), the rest to b (N x (w - m)), both contiguous. */
static PyObject *lerp_rows(PyObject *self, PyObject *args) {
    Py_buffer btab, bdtab, bi, bf, ba, bb;
    Py_ssize_t w, m;
    if (!PyArg_ParseTuple(args, "y*y*y*y*w*w*nn", &btab, &bdtab, &bi, &bf, &ba, &bb, &w, &m))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t N = bf.len / (Py_ssize_t)sizeof(double);
    Py_ssize_t rows;
    if (!table_shape(&btab, &bdtab, w, m, &rows) || bi.len != N * (Py_ssize_t)sizeof(long long)) {
        PyErr_SetString(PyExc_ValueError, "lerp_rows: expected tab (rows >= 2, w), dtab (rows - 1, w), "
                        "i and f of N entries, 0 <= m <= w");
        goto done;
    }
    if (!need(&ba, N * m, "a") || !need(&bb, N * (w - m), "b"))
        goto done;
    const double *tab = btab.buf, *dtab = bdtab.buf, *f = bf.buf;
    const long long *idx = bi.buf;
    double *a = ba.buf, *b = bb.buf;
    for (Py_ssize_t n = 0; n < N; n++) {
        if (idx[n] < 0 || idx[n] >= rows - 1) {
            PyErr_Format(PyExc_ValueError, "lerp_rows: row %lld outside 0..%zd", idx[n], rows - 2);
            goto done;
        }
    }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t n = 0; n < N; n++)
        lerp_row(tab, dtab, idx[n], f[n], a + n * m, b + n * (w - m), w, m);
    Py_END_ALLOW_THREADS
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&btab); PyBuffer_Release(&bdtab); PyBuffer_Release(&bi); PyBuffer_Release(&bf);
    PyBuffer_Release(&ba); PyBuffer_Release(&bb);
    return ret;
}

/* The grid row and fraction of coordinate x (gain_table.py's lookup: i = min(int(x), rows - 2), f = clip(x - i, 0, 1)). */
static inline long long grid_row(double x, Py_ssize_t rows, double *fn) {
    long long i = (long long)x;
    if (i > rows - 2) i = rows - 2;
    double f = x - (double)i;
    if (f < 0.0) f = 0.0;
    if (f > 1.0) f = 1.0;
    *fn = f;
    return i;
}

/* lerp_rows at grid coordinates x (N): i = min(int(x), rows - 2), f = clip(x - i, 0, 1), as
 * gain_table.py's lookup computes them, when the table has the rows i and i + 1 of every x
 * (have: one byte per segment of seg rows).  Returns True when done; False, writing nothing,
 * when a row is not there yet or an x is not a coordinate >= 0 (the caller's numpy path). */
static PyObject *lerp_at(PyObject *self, PyObject *args) {
    Py_buffer btab, bdtab, bx, bhave, ba, bb;
    Py_ssize_t seg, w, m;
    if (!PyArg_ParseTuple(args, "y*y*y*y*nw*w*nn", &btab, &bdtab, &bx, &bhave, &seg, &ba, &bb, &w, &m))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t N = bx.len / (Py_ssize_t)sizeof(double);
    Py_ssize_t rows;
    if (!table_shape(&btab, &bdtab, w, m, &rows) || seg < 1 || bhave.len < (rows + seg - 1) / seg) {
        PyErr_SetString(PyExc_ValueError, "lerp_at: expected tab (rows >= 2, w), dtab (rows - 1, w), "
                        "have of a byte per segment, 0 <= m <= w");
        goto done;
    }
    if (!need(&ba, N * m, "a") || !need(&bb, N * (w - m), "b"))
        goto done;
    const double *tab = btab.buf, *dtab = bdtab.buf, *x = bx.buf;
    const unsigned char *have = bhave.buf;
    double *a = ba.buf, *b = bb.buf;
    double fn;
    for (Py_ssize_t n = 0; n < N; n++) {
        if (!(x[n] >= 0.0 && x[n] < 9.0e15)) {
            ret = Py_False;
            goto found;
        }
        const long long i = grid_row(x[n], rows, &fn);
        if (!have[i / seg] || !have[(i + 1) / seg]) {
            ret = Py_False;
            goto found;
        }
    }
    for (Py_ssize_t n = 0; n < N; n++) {
        const long long i = grid_row(x[n], rows, &fn);
        lerp_row(tab, dtab, i, fn, a + n * m, b + n * (w - m), w, m);
    }
    ret = Py_True;
found:
    Py_INCREF(ret);
done:
    PyBuffer_Release(&btab); PyBuffer_Release(&bdtab); PyBuffer_Release(&bx); PyBuffer_Release(&bhave);
    PyBuffer_Release(&ba); PyBuffer_Release(&bb);
    return ret;
}

/* The order tracker's per-block statistics (tracker.py's _block_stats, the same operations in
 * numpy's order) of contiguous wave, env (E x B x C x K) and rpm (E x B): rms = sqrt(sum(wave^2)
 * / B) and amp = sum(env) / B over each block's samples (numpy sums a block's column one sample
 * after the other when C K > 1, pairwise when it is 1: the column is then contiguous), rmean =
 * sum(rpm) / B (pairwise), valid = every |rpm| >= min_rpm and max |rpm| / 60 top < half_fs;
 * rms and amp NaN where not valid. */
/* The statistics of one block (B samples): wave, env (B x CK), rpm (B), sq scratch (B x CK);
 * rms and amp (CK), rmean and valid (one each). */
static void stats_of_block(const double *we, const double *ee, const double *re, Py_ssize_t B,
                           Py_ssize_t CK, double min_rpm, double top, double half_fs, double *sq,
                           double *rs, double *am, double *rmean, unsigned char *valid) {
    const double n = (double)B;
    for (Py_ssize_t i = 0; i < B * CK; i++) sq[i] = we[i] * we[i];
    if (CK == 1) {
        rs[0] = pairwise_sum(sq, B, 1);
        am[0] = pairwise_sum(ee, B, 1);
    } else {
        for (Py_ssize_t j = 0; j < CK; j++) { rs[j] = sq[j]; am[j] = ee[j]; }
        for (Py_ssize_t b = 1; b < B; b++)
            for (Py_ssize_t j = 0; j < CK; j++) { rs[j] += sq[b * CK + j]; am[j] += ee[b * CK + j]; }
    }
    for (Py_ssize_t j = 0; j < CK; j++) { rs[j] = sqrt(rs[j] / n); am[j] = am[j] / n; }
    *rmean = pairwise_sum(re, B, 1) / n;
    int ok = 1;
    double hi = 0.0;
    for (Py_ssize_t b = 0; b < B; b++) {
        const double a = fabs(re[b]);
        ok &= a >= min_rpm;                             /* NaN: not valid */
        if (b == 0 || (hi == hi && (a > hi || a != a))) hi = a;
    }
    *valid = ok && hi / 60.0 * top < half_fs;
    if (!*valid)
        for (Py_ssize_t j = 0; j < CK; j++) { rs[j] = NAN; am[j] = NAN; }
}

static PyObject *block_stats(PyObject *self, PyObject *args) {
    Py_buffer bw, be, br, brms, bamp, bmean, bvalid;
    Py_ssize_t K;
    double min_rpm, top, half_fs;
    if (!PyArg_ParseTuple(args, "y*y*y*ndddw*w*w*w*", &bw, &be, &br, &K, &min_rpm, &top, &half_fs,
                          &brms, &bamp, &bmean, &bvalid))
        return NULL;
    PyObject *ret = NULL;
    double *sq = NULL;
    const Py_ssize_t E = bmean.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t B = E > 0 ? br.len / (Py_ssize_t)sizeof(double) / E : 0;
    const Py_ssize_t CK = B > 0 ? bw.len / (Py_ssize_t)sizeof(double) / (E * B) : 0;
    if (E <= 0 || B <= 0 || K <= 0 || CK <= 0 || CK % K || br.len != E * B * (Py_ssize_t)sizeof(double)
        || bw.len != E * B * CK * (Py_ssize_t)sizeof(double) || be.len != bw.len || bvalid.len < E) {
        PyErr_SetString(PyExc_ValueError, "block_stats: expected wave and env (E x B x C x K), rpm "
                        "(E x B), rmean and valid of E entries");
        goto done;
    }
    if (!need(&brms, E * CK, "rms") || !need(&bamp, E * CK, "amp"))
        goto done;
    sq = malloc(sizeof(double) * (size_t)(B * CK));
    if (sq == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    const double *wave = bw.buf, *env = be.buf, *rpm = br.buf;
    double *rms = brms.buf, *amp = bamp.buf, *rmean = bmean.buf;
    unsigned char *valid = bvalid.buf;
    for (Py_ssize_t e = 0; e < E; e++)
        stats_of_block(wave + e * B * CK, env + e * B * CK, rpm + e * B, B, CK, min_rpm, top, half_fs,
                       sq, rms + e * CK, amp + e * CK, rmean + e, valid + e);
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    free(sq);
    PyBuffer_Release(&bw); PyBuffer_Release(&be); PyBuffer_Release(&br); PyBuffer_Release(&brms);
    PyBuffer_Release(&bamp); PyBuffer_Release(&bmean); PyBuffer_Release(&bvalid);
    return ret;
}

/* The model speed and omega / fs of one speed (components.py's model_speed and Omegas, then / fs). */
static inline void omega_row(double r, double min_rpm, const double *orders, const double *fixed,
                             const unsigned char *by_order, Py_ssize_t K, double two_pi, double fs,
                             double *speed, double *w) {
    double a = fabs(r);
    if (!isfinite(a)) a = 0.0;
    const double sp = a >= min_rpm ? a : min_rpm;
    *speed = sp;
    for (Py_ssize_t k = 0; k < K; k++)
        w[k] = by_order[k] ? orders[k] * sp / 60.0 * two_pi / fs : fixed[k] / fs;
}

/* The model speed and omega / fs of the components (components.py's model_speed and Omegas,
 * then / fs, the same operations): rpm (N) -> speed (N) = max(|rpm| or 0 where not finite,
 * min_rpm); w (N x K) = order x speed / 60 x two_pi / fs, or fixed / fs (fixed = 2 pi f of a
 * fixed-frequency component, by_order[k] = 0). */
static PyObject *model_omega(PyObject *self, PyObject *args) {
    Py_buffer br, bo, bf, bb, bs, bw;
    double min_rpm, two_pi, fs;
    if (!PyArg_ParseTuple(args, "y*dy*y*y*ddw*w*", &br, &min_rpm, &bo, &bf, &bb, &two_pi, &fs, &bs, &bw))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t N = br.len / (Py_ssize_t)sizeof(double), K = bo.len / (Py_ssize_t)sizeof(double);
    if (K <= 0 || bf.len != K * (Py_ssize_t)sizeof(double) || bb.len != K) {
        PyErr_SetString(PyExc_ValueError, "model_omega: expected orders and fixed of K doubles, by_order of K bytes");
        goto done;
    }
    if (!need(&bs, N, "speed") || !need(&bw, N * K, "w"))
        goto done;
    const double *rpm = br.buf, *orders = bo.buf, *fixed = bf.buf;
    const unsigned char *by_order = bb.buf;
    double *speed = bs.buf, *w = bw.buf;
    for (Py_ssize_t n = 0; n < N; n++)
        omega_row(rpm[n], min_rpm, orders, fixed, by_order, K, two_pi, fs, speed + n, w + n * K);
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&br); PyBuffer_Release(&bo); PyBuffer_Release(&bf); PyBuffer_Release(&bb);
    PyBuffer_Release(&bs); PyBuffer_Release(&bw);
    return ret;
}

/* forward, envelope and block_stats in one pass (tracker.py's causal path of a call without a
 * missing sample, without the smoother): the T new samples y (T x C), c (T x K), k (T x 2K) from
 * the state z (C x 2K, updated) follow the p samples carried from the last call (their wave and
 * env cw, ce: p x C x K); rpm (p + T) is the speed of them all.  The E = (p + T) / B whole blocks
 * give rms, amp (E x C x K), rmean and valid (E); the samples after them go to tw, te
 * ((p + T - E B) x C x K), to be carried.  The same operations as forward, envelope and
 * block_stats in their order (a block's waveform and envelope are kept only while its
 * statistics are made). */
/* Where a sample's c (K) and k (2K) come from: rows of the arrays c and k (forward_blocks), or
 * made (live_out): c = 2 cosw, k the gain table's row (tab, dtab: rows x w, [k | S]) interpolated
 * at the grid coordinate x = logu / lq, as lerp_at does it. */
typedef struct {
    const double *c, *k;
    const double *cosw, *logu, *tab, *dtab;
    double lq;
    Py_ssize_t rows, w;
} gains_src;

/* forward, envelope and block_stats over the p carried and T new samples (see forward_blocks);
 * rpm (p + T) contiguous; scratch of 3 B C K + 3 d + K + 1 doubles. */
static void blocks_pass(const double *y, const gains_src *g, double *z, const double *rpm, Py_ssize_t C,
                        Py_ssize_t K, Py_ssize_t B, Py_ssize_t p, Py_ssize_t T, const double *cw,
                        const double *ce, double min_rpm, double top, double half_fs, double *rms,
                        double *amp, double *rmean, unsigned char *valid, double *tw, double *te,
                        double *scratch) {
    const Py_ssize_t d = 2 * K, CK = C * K, E = (p + T) / B;
    double *wave = scratch, *env = scratch + B * CK, *sq = scratch + 2 * B * CK, *xo = scratch + 3 * B * CK;
    double *kb = xo + d, *cb = kb + 2 * d;          /* made rows: k | S (d + 1), c (K) */
    for (Py_ssize_t i = 0; i < p + T; i++) {
        const Py_ssize_t e = i / B, b = i % B;
        double *wo = e < E ? wave + b * CK : tw + (i - E * B) * CK;   /* this sample's place */
        double *eo = e < E ? env + b * CK : te + (i - E * B) * CK;
        if (i < p) {                                                 /* carried */
            for (Py_ssize_t j = 0; j < CK; j++) { wo[j] = cw[i * CK + j]; eo[j] = ce[i * CK + j]; }
        } else {
            const Py_ssize_t n = i - p;
            const double *cn, *kn;
            if (g->c != NULL) {
                cn = g->c + n * K;
                kn = g->k + n * d;
            } else {
                double fn;
                const long long r = grid_row(g->logu[n] / g->lq, g->rows, &fn);
                lerp_row(g->tab, g->dtab, r, fn, kb, kb + d, g->w, g->w - 1);
                for (Py_ssize_t a = 0; a < K; a++) cb[a] = 2.0 * g->cosw[n * K + a];
                cn = cb;
                kn = kb;
            }
            for (Py_ssize_t ch = 0; ch < C; ch++) {
                double *zc = z + ch * d;
                double s = 0.0;                                      /* forward */
                for (Py_ssize_t a = 0; a < K; a++) s += zc[2 * a + 1];
                const double en = y[n * C + ch] - s;
                for (Py_ssize_t j = 0; j < d; j++) xo[j] = zc[j] + kn[j] * en;
                for (Py_ssize_t a = 0; a < K; a++) {
                    zc[2 * a] = xo[2 * a + 1];
                    zc[2 * a + 1] = -xo[2 * a] + cn[a] * xo[2 * a + 1];
                }
                for (Py_ssize_t a = 0; a < K; a++) {                 /* envelope */
                    const double cc = cn[a];
                    double s2 = 1.0 - 0.25 * cc * cc;
                    if (!(s2 >= 1e-300)) s2 = (s2 != s2) ? s2 : 1e-300;
                    const double x1 = xo[2 * a], x2 = xo[2 * a + 1];
                    double a2 = (x1 * x1 - cc * x1 * x2 + x2 * x2) / s2;
                    if (a2 < 0.0) a2 = 0.0;
                    wo[ch * K + a] = x2;
                    eo[ch * K + a] = sqrt(a2);
                }
            }
        }
        if (e < E && b == B - 1)
            stats_of_block(wave, env, rpm + e * B, B, CK, min_rpm, top, half_fs, sq, rms + e * CK,
                           amp + e * CK, rmean + e, valid + e);
    }
}

static PyObject *forward_blocks(PyObject *self, PyObject *args) {
    Py_buffer by, bc, bk, bz, br, bcw, bce, brms, bamp, bmean, bvalid, btw, bte;
    Py_ssize_t K, B, p;
    double min_rpm, top, half_fs;
    if (!PyArg_ParseTuple(args, "y*y*y*w*y*nnny*y*dddw*w*w*w*w*w*", &by, &bc, &bk, &bz, &br, &K, &B, &p,
                          &bcw, &bce, &min_rpm, &top, &half_fs, &brms, &bamp, &bmean, &bvalid, &btw, &bte))
        return NULL;
    PyObject *ret = NULL;
    double *scratch = NULL;
    const Py_ssize_t d = 2 * K;
    const Py_ssize_t C = K > 0 ? bz.len / (Py_ssize_t)sizeof(double) / d : 0;
    const Py_ssize_t T = K > 0 ? bc.len / (Py_ssize_t)sizeof(double) / K : 0;
    const Py_ssize_t E = B > 0 && p >= 0 ? (p + T) / B : 0;
    const Py_ssize_t CK = C * K, tail = p + T - E * B;
    if (K <= 0 || C <= 0 || B <= 0 || p < 0 || bc.len != T * K * (Py_ssize_t)sizeof(double)
        || br.len != (p + T) * (Py_ssize_t)sizeof(double) || bmean.len != E * (Py_ssize_t)sizeof(double)
        || bvalid.len != E) {
        PyErr_SetString(PyExc_ValueError, "forward_blocks: expected c (T x K), rpm (p + T), rmean and "
                        "valid of (p + T) / B entries");
        goto done;
    }
    if (!need(&by, T * C, "y") || !need(&bk, T * d, "k") || !need(&bcw, p * CK, "cw") ||
        !need(&bce, p * CK, "ce") || !need(&brms, E * CK, "rms") || !need(&bamp, E * CK, "amp") ||
        !need(&btw, tail * CK, "tw") || !need(&bte, tail * CK, "te"))
        goto done;
    scratch = malloc(sizeof(double) * (size_t)(3 * B * CK + 3 * d + K + 1));
    if (scratch == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    const gains_src g = {.c = bc.buf, .k = bk.buf};
    blocks_pass(by.buf, &g, bz.buf, br.buf, C, K, B, p, T, bcw.buf, bce.buf, min_rpm, top, half_fs, brms.buf,
                bamp.buf, bmean.buf, bvalid.buf, btw.buf, bte.buf, scratch);
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    free(scratch);
    PyBuffer_Release(&by); PyBuffer_Release(&bc); PyBuffer_Release(&bk); PyBuffer_Release(&bz);
    PyBuffer_Release(&br); PyBuffer_Release(&bcw); PyBuffer_Release(&bce); PyBuffer_Release(&brms);
    PyBuffer_Release(&bamp); PyBuffer_Release(&bmean); PyBuffer_Release(&bvalid); PyBuffer_Release(&btw);
    PyBuffer_Release(&bte);
    return ret;
}

/* Python's a // b. */
static Py_ssize_t floordiv(Py_ssize_t a, Py_ssize_t b) {
    const Py_ssize_t q = a / b;
    return (a % b != 0 && ((a < 0) != (b < 0))) ? q - 1 : q;
}

/* The first steps of a live tracker call (tracker.py's _prepare, _decimate with speed_line.py's
 * _delayed_at_steady, and model_omega), when they take the common path: y (T x C) without a NaN,
 * no missing input within W of the first kept sample (pos0 = n_in + skip; last_miss, C int64:
 * each channel's last missing input), T >= n = len(line) (the delay line, read and replaced in
 * place).  Returns False, changing nothing, when a condition does not hold (the caller's general
 * path); else True: the kept samples skip, skip + D, ... filtered (zi carried) to yd (N x C), their
 * speeds rd (N: from the old line before sample n, else vals, the speeds asked at input samples
 * p0, p0 + D, ...), the new line (the speeds of the last n inputs asked, NaN elsewhere), the model
 * speed (N) at rd, u = speed / lo (N) and w = omega / fs (N x K). */
static PyObject *live_in(PyObject *self, PyObject *args) {
    Py_buffer bsos, by, bzi, bmiss, bline, bvals, bo, bf, bb, byd, brd, bsp, bu, bw;
    Py_ssize_t skip, D, W, p0;
    long long pos0;
    double min_rpm, two_pi, fs, lo;
    if (!PyArg_ParseTuple(args, "y*y*w*nny*Lnw*y*ndy*y*y*dddw*w*w*w*w*", &bsos, &by, &bzi, &skip, &D, &bmiss,
                          &pos0, &W, &bline, &bvals, &p0, &min_rpm, &bo, &bf, &bb, &two_pi, &fs, &lo, &byd, &brd,
                          &bsp, &bu, &bw))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t S = bsos.len / (Py_ssize_t)sizeof(double) / 6;
    const Py_ssize_t C = S > 0 ? bzi.len / (Py_ssize_t)sizeof(double) / (2 * S) : 0;
    const Py_ssize_t K = bo.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t n = bline.len / (Py_ssize_t)sizeof(double), nv = bvals.len / (Py_ssize_t)sizeof(double);
    if (C <= 0 || D <= 0 || skip < 0 || S <= 0 || K <= 0 || bsos.len != S * 6 * (Py_ssize_t)sizeof(double)
        || bmiss.len != C * (Py_ssize_t)sizeof(long long) || bf.len != K * (Py_ssize_t)sizeof(double)
        || bb.len != K || p0 < 0) {
        PyErr_SetString(PyExc_ValueError, "live_in: expected sos (S x 6), C > 0, D > 0, skip >= 0, "
                        "last_miss of C int64, orders and fixed of K doubles, by_order of K bytes");
        goto done;
    }
    const Py_ssize_t T = by.len / (Py_ssize_t)sizeof(double) / C;
    const Py_ssize_t N = skip < T ? (T - skip + D - 1) / D : 0;
    if (by.len != T * C * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "live_in: y is not T x C");
        goto done;
    }
    if (!need(&byd, N * C, "yd") || !need(&brd, N, "rd") || !need(&bsp, N, "speed") || !need(&bu, N, "u") ||
        !need(&bw, N * K, "w"))
        goto done;
    const double *sos = bsos.buf, *y = by.buf, *vals = bvals.buf;
    const long long *last = bmiss.buf;
    double *line = bline.buf;
    ret = Py_False;
    if (N == 0 || T < n)
        goto found;
    for (Py_ssize_t c = 0; c < C; c++)
        if (pos0 - last[c] < W) goto found;               /* a missing input near: the general path */
    for (Py_ssize_t i = 0; i < T * C; i++)
        if (y[i] != y[i]) goto found;                     /* NaN: a missing sample */
    Py_ssize_t k = skip < n ? (n - skip + D - 1) / D : 0; /* kept samples still in the old line */
    if (k > N) k = N;
    const Py_ssize_t j0 = k < N ? floordiv(skip + k * D - n - p0, D) : 0;
    if (k < N && (j0 < 0 || j0 + (N - k) > nv))
        goto found;
    const Py_ssize_t tail = T - n;
    const Py_ssize_t at = tail > p0 ? (tail - p0 + D - 1) / D : 0;   /* speeds asked before the line */
    const Py_ssize_t m0 = p0 + at * D - tail;
    const Py_ssize_t slots = m0 < n ? (n - m0 + D - 1) / D : 0;
    if (at > nv || nv - at != slots || m0 < 0)
        goto found;
    ret = Py_True;
    double *yd = byd.buf, *rd = brd.buf, *speed = bsp.buf, *u = bu.buf, *w = bw.buf;
    PyThreadState *save = T * C * S > (1 << 17) ? PyEval_SaveThread() : NULL;   /* as sosfilt */
    sos_all(sos, S, y, T, C, bzi.buf, yd, skip, D);
    if (save != NULL)
        PyEval_RestoreThread(save);
    for (Py_ssize_t i = 0; i < N; i++) {
        rd[i] = i < k ? line[skip + i * D] : vals[j0 + i - k];
        omega_row(rd[i], min_rpm, bo.buf, bf.buf, bb.buf, K, two_pi, fs, speed + i, w + i * K);
        u[i] = speed[i] / lo;
    }
    for (Py_ssize_t m = 0; m < n; m++) line[m] = NAN;
    for (Py_ssize_t j = 0; j < slots; j++) line[m0 + j * D] = vals[at + j];
found:
    Py_INCREF(ret);
done:
    PyBuffer_Release(&bsos); PyBuffer_Release(&by); PyBuffer_Release(&bzi); PyBuffer_Release(&bmiss);
    PyBuffer_Release(&bline); PyBuffer_Release(&bvals); PyBuffer_Release(&bo); PyBuffer_Release(&bf);
    PyBuffer_Release(&bb); PyBuffer_Release(&byd); PyBuffer_Release(&brd); PyBuffer_Release(&bsp);
    PyBuffer_Release(&bu); PyBuffer_Release(&bw);
    return ret;
}

/* The rest of a live tracker call (live.py): the gains and forward_blocks.  The T new samples
 * yd (T x C), their speeds rd (T) after the p carried (prpm, cw, ce: the state's partial block),
 * cosw (T x K) = cos(omega / fs), logu (T) = log(model speed / the grid's lowest speed); the gains
 * from the table (tab, dtab: rows x w = [k | S], have: a byte per segment of seg rows) at
 * x = logu / lq (lerp_at), c = 2 cosw; then forward_blocks from z (updated): rms, amp (E x C x K),
 * rmean, valid (E), the new partial block tw, te (tail x C x K) and its speeds rtail, and the
 * blocks' first tracker samples starts (E, int64: n0 - p + e B) and input samples t_in
 * ((start + B - 1) D - delay_in).  Returns False, changing nothing, when an x is not a coordinate
 * >= 0 or its rows are not in the table yet (the caller's lookup fills them). */
static PyObject *live_out(PyObject *self, PyObject *args) {
    Py_buffer blu, btab, bdtab, bhave, by, bcos, bz, bpr, brd, bcw, bce, brms, bamp, bmean, bvalid, btw, bte,
        brt, bst, bti;
    Py_ssize_t seg, w, K, B, D, delay;
    long long n0;
    double lq, min_rpm, top, half_fs;
    if (!PyArg_ParseTuple(args, "y*dy*y*y*nny*y*w*y*y*nny*y*dddLnnw*w*w*w*w*w*w*w*w*", &blu, &lq, &btab, &bdtab,
                          &bhave, &seg, &w, &by, &bcos, &bz, &bpr, &brd, &K, &B, &bcw, &bce, &min_rpm, &top,
                          &half_fs, &n0, &D, &delay, &brms, &bamp, &bmean, &bvalid, &btw, &bte, &brt, &bst,
                          &bti))
        return NULL;
    PyObject *ret = NULL;
    double *scratch = NULL;
    const Py_ssize_t d = 2 * K;
    const Py_ssize_t C = K > 0 ? bz.len / (Py_ssize_t)sizeof(double) / d : 0;
    const Py_ssize_t T = brd.len / (Py_ssize_t)sizeof(double), p = bpr.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t E = B > 0 ? (p + T) / B : 0;
    const Py_ssize_t CK = C * K, tail = p + T - E * B;
    Py_ssize_t rows;
    if (K <= 0 || C <= 0 || B <= 0 || w != d + 1 || seg < 1 || !table_shape(&btab, &bdtab, w, w - 1, &rows)
        || bhave.len < (rows + seg - 1) / seg || bmean.len != E * (Py_ssize_t)sizeof(double)
        || bvalid.len != E) {
        PyErr_SetString(PyExc_ValueError, "live_out: expected K > 0, tab (rows >= 2, 2K + 1), dtab, have of a "
                        "byte per segment, rmean and valid of (p + T) / B entries");
        goto done;
    }
    if (!need(&blu, T, "logu") || !need(&by, T * C, "yd") || !need(&bcos, T * K, "cosw") ||
        !need(&bcw, p * CK, "cw") || !need(&bce, p * CK, "ce") || !need(&brms, E * CK, "rms") ||
        !need(&bamp, E * CK, "amp") || !need(&btw, tail * CK, "tw") || !need(&bte, tail * CK, "te") ||
        !need(&brt, tail, "rtail") || !need(&bst, E, "starts") || !need(&bti, E, "t_in"))
        goto done;
    const double *logu = blu.buf;
    const unsigned char *have = bhave.buf;
    ret = Py_False;
    for (Py_ssize_t n = 0; n < T; n++) {
        const double x = logu[n] / lq;
        if (!(x >= 0.0 && x < 9.0e15))
            goto found;
        double fn;
        const long long i = grid_row(x, rows, &fn);
        if (!have[i / seg] || !have[(i + 1) / seg])
            goto found;
    }
    scratch = malloc(sizeof(double) * (size_t)(3 * B * CK + 3 * d + K + 1 + p + T));
    if (scratch == NULL) {
        ret = NULL;
        PyErr_NoMemory();
        goto done;
    }
    ret = Py_True;
    double *rpm = scratch + 3 * B * CK + 3 * d + K + 1;         /* [prpm, rd] */
    const double *pr = bpr.buf, *rd = brd.buf;
    for (Py_ssize_t i = 0; i < p; i++) rpm[i] = pr[i];
    for (Py_ssize_t i = 0; i < T; i++) rpm[p + i] = rd[i];
    const gains_src g = {.cosw = bcos.buf, .logu = logu, .tab = btab.buf, .dtab = bdtab.buf, .lq = lq,
                         .rows = rows, .w = w};
    blocks_pass(by.buf, &g, bz.buf, rpm, C, K, B, p, T, bcw.buf, bce.buf, min_rpm, top, half_fs, brms.buf,
                bamp.buf, bmean.buf, bvalid.buf, btw.buf, bte.buf, scratch);
    double *rt = brt.buf;
    long long *st = bst.buf, *ti = bti.buf;
    for (Py_ssize_t i = 0; i < tail; i++) rt[i] = rpm[E * B + i];
    for (Py_ssize_t e = 0; e < E; e++) {
        st[e] = n0 - p + (long long)(B * e);
        ti[e] = (st[e] + B - 1) * D - delay;
    }
found:
    Py_INCREF(ret);
done:
    free(scratch);
    PyBuffer_Release(&blu); PyBuffer_Release(&btab); PyBuffer_Release(&bdtab); PyBuffer_Release(&bhave);
    PyBuffer_Release(&by); PyBuffer_Release(&bcos); PyBuffer_Release(&bz); PyBuffer_Release(&bpr);
    PyBuffer_Release(&brd); PyBuffer_Release(&bcw); PyBuffer_Release(&bce); PyBuffer_Release(&brms);
    PyBuffer_Release(&bamp); PyBuffer_Release(&bmean); PyBuffer_Release(&bvalid); PyBuffer_Release(&btw);
    PyBuffer_Release(&bte); PyBuffer_Release(&brt); PyBuffer_Release(&bst); PyBuffer_Release(&bti);
    return ret;
}

/* Peak amplitude from the state pairs (recursions.py's envelope, the same operations in its
 * order): xs (N x C x 2K), c (N x K) -> env (N x C x K),
 *   env = sqrt(max((x1 x1 - (c x1) x2 + x2 x2) / max(1 - (0.25 c) c, 1e-300), 0))
 * with x1, x2 the pair's entries; NaN passes through as np.maximum passes it. */
static PyObject *envelope(PyObject *self, PyObject *args) {
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

/* The causal segment of each new committed edge (tacho causal.py's _flush_segments and
 * smoothing.py's weighted_quadratic, the same operations in their order): edge k (committed
 * index; Tc, nc: the run's committed edge times and pulse counts from index c0 on, Python
 * lists of numbers) of each (k, known) in todo is fitted with the weighted quadratic over the
 * edges k, k - 1, ... back to m = len(ck) of them (weights ck, those before c0 left out), x
 * scaled by the largest |dx|.  Its segment goes to column col + r of sbuf (5 x cap): key =
 * max(known, T), T, speed, acceleration, valid (1.0: two points or more). */
static PyObject *causal_fit(PyObject *self, PyObject *args) {
    PyObject *oT, *on, *otodo;
    Py_buffer bck, bbuf;
    long long c0;
    double ppr;
    Py_ssize_t col;
    if (!PyArg_ParseTuple(args, "OOOy*Ldw*n", &oT, &on, &otodo, &bck, &c0, &ppr, &bbuf, &col))
        return NULL;
    PyObject *ret = NULL, *fT = NULL, *fn = NULL, *ftodo = NULL;
    double *Tc = NULL, *terms = NULL;
    const Py_ssize_t m = bck.len / (Py_ssize_t)sizeof(double);
    const Py_ssize_t cap = bbuf.len / (Py_ssize_t)sizeof(double) / 5;
    fT = PySequence_Fast(oT, "causal_fit: Tc must be a sequence");
    fn = fT ? PySequence_Fast(on, "causal_fit: nc must be a sequence") : NULL;
    ftodo = fn ? PySequence_Fast(otodo, "causal_fit: todo must be a sequence") : NULL;
    if (ftodo == NULL)
        goto done;
    const Py_ssize_t nT = PySequence_Fast_GET_SIZE(fT);
    const Py_ssize_t R = PySequence_Fast_GET_SIZE(ftodo);
    if (PySequence_Fast_GET_SIZE(fn) != nT || m < 1 || bbuf.len != 5 * cap * (Py_ssize_t)sizeof(double)
        || col < 0 || col + R > cap) {
        PyErr_SetString(PyExc_ValueError, "causal_fit: expected Tc and nc of one length, ck of at "
                        "least one weight, sbuf (5 x cap) with room for todo at col");
        goto done;
    }
    Tc = malloc(sizeof(double) * (size_t)(2 * nT + 8 * m + 1));
    if (Tc == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    double *nc = Tc + nT;
    terms = nc + nT;
    for (Py_ssize_t i = 0; i < nT; i++) {                 /* np.asarray(..., float64) of the lists */
        Tc[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(fT, i));
        nc[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(fn, i));
    }
    if (PyErr_Occurred())
        goto done;
    const double *ck = bck.buf;
    double *seg = (double *)bbuf.buf + col;
    for (Py_ssize_t r = 0; r < R; r++) {
        PyObject *item = PySequence_Fast_GET_ITEM(ftodo, r);
        long long k;
        double kn;
        if (!PyArg_ParseTuple(item, "Ld", &k, &kn))
            goto done;
        if (k - c0 < 0 || k - c0 >= nT) {
            PyErr_Format(PyExc_ValueError, "causal_fit: edge %lld outside the committed %lld..%lld",
                         k, c0, c0 + (long long)nT - 1);
            goto done;
        }
        const Py_ssize_t kr = (Py_ssize_t)(k - c0);
        const double Tk = Tc[kr], nk = nc[kr];
        double S = 0.0;
        Py_ssize_t npts = 0;
        for (Py_ssize_t j = 0; j < m; j++) {       /* S: np.abs(dx).max(), NaN propagating */
            const double dx = kr - j >= 0 ? Tc[kr - j] - Tk : 0.0;
            const double a = fabs(dx);
            if (j == 0 || (S == S && (a > S || a != a))) S = a;
            npts += kr - j >= 0;
        }
        if (!(S > 0)) S = 1.0;
        for (Py_ssize_t j = 0; j < m; j++) {
            const int use = kr - j >= 0;
            const double w = use ? ck[j] : 0.0 * ck[j];
            const double x = (use ? Tc[kr - j] - Tk : 0.0) / S;
            const double y = use ? nc[kr - j] - nk : 0.0;
            fit_terms(terms + j, m, w, x, y);
        }
        double c[3];
        solve_fit(terms, m, npts, c);
        const double c1 = c[1], c2 = c[2];
        seg[r] = (kn >= Tk || kn != kn) ? kn : Tk;             /* np.maximum(known, Tk) */
        seg[cap + r] = Tk;
        seg[2 * cap + r] = c1 / (S * ppr);
        seg[3 * cap + r] = 2.0 * c2 / (S * S * ppr);
        seg[4 * cap + r] = npts >= 2 ? 1.0 : 0.0;
    }
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    free(Tc);
    Py_XDECREF(fT); Py_XDECREF(fn); Py_XDECREF(ftodo);
    PyBuffer_Release(&bck); PyBuffer_Release(&bbuf);
    return ret;
}

/* The knots of the smoothed speed (tacho smoothing.py's _fit and weighted_quadratic, the same
 * operations in their order): at each centre k = first .. first + R - 1 (committed indices; Tc,
 * nc: the run's committed edge times and pulse counts from index c0 on, Python lists of
 * numbers; K committed edges in all) the weighted quadratic of pulse count vs edge time over
 * the edges k - h .. k + h within 0 .. K - 1 (weights wk, 2h + 1 of them, the others left out),
 * x scaled by the largest |dx|; the knot goes to column r of out (3 x R): its time, angle base +
 * (n + c0) / ppr and speed c1 / (S ppr). */
static PyObject *knot_fit(PyObject *self, PyObject *args) {
    PyObject *oT, *on;
    Py_buffer bwk, bout;
    long long c0, first, K;
    double base, ppr;
    if (!PyArg_ParseTuple(args, "OOLLLy*ddw*", &oT, &on, &c0, &first, &K, &bwk, &base, &ppr, &bout))
        return NULL;
    PyObject *ret = NULL, *fT = NULL, *fn = NULL;
    double *Tc = NULL;
    const Py_ssize_t m = bwk.len / (Py_ssize_t)sizeof(double), h = (m - 1) / 2;
    const Py_ssize_t R = bout.len / (Py_ssize_t)sizeof(double) / 3;
    fT = PySequence_Fast(oT, "knot_fit: Tc must be a sequence");
    fn = fT ? PySequence_Fast(on, "knot_fit: nc must be a sequence") : NULL;
    if (fn == NULL)
        goto done;
    const Py_ssize_t nT = PySequence_Fast_GET_SIZE(fT);
    if (PySequence_Fast_GET_SIZE(fn) != nT || m < 3 || m % 2 == 0 || bout.len != 3 * R * (Py_ssize_t)sizeof(double)
        || K > c0 + nT || first < c0 || first + R > K) {
        PyErr_SetString(PyExc_ValueError, "knot_fit: expected Tc and nc of one length, 2h + 1 >= 3 weights, "
                        "out (3 x R) and centres among the committed edges");
        goto done;
    }
    for (Py_ssize_t r = 0; r < R; r++) {            /* every window's edges must be there */
        const long long lo = first + r - h > 0 ? first + r - h : 0;
        if (lo < c0) {
            PyErr_SetString(PyExc_ValueError, "knot_fit: a window reaches before the kept edges");
            goto done;
        }
    }
    Tc = malloc(sizeof(double) * (size_t)(2 * nT + 8 * m + 1));
    if (Tc == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    double *nc = Tc + nT, *terms = nc + nT;
    for (Py_ssize_t i = 0; i < nT; i++) {                 /* np.asarray(..., float64) of the lists */
        Tc[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(fT, i));
        nc[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(fn, i));
    }
    if (PyErr_Occurred())
        goto done;
    const double *wk = bwk.buf;
    double *out = bout.buf;
    for (Py_ssize_t r = 0; r < R; r++) {
        const long long k = first + r;
        const long long lo = k - h > 0 ? k - h : 0, hi = k + h < K - 1 ? k + h : K - 1;
        const Py_ssize_t kr = (Py_ssize_t)(k - c0);
        const double Tk = Tc[kr], nk = nc[kr];
        double S = 0.0;
        Py_ssize_t npts = 0;
        for (Py_ssize_t j = 0; j < m; j++) {       /* S: np.abs(dx).max(), NaN propagating */
            const long long i = k - h + j;
            const int use = i >= lo && i <= hi;
            const double a = fabs(use ? Tc[i - c0] - Tk : 0.0);
            if (j == 0 || (S == S && (a > S || a != a))) S = a;
            npts += use;
        }
        for (Py_ssize_t j = 0; j < m; j++) {
            const long long i = k - h + j;
            const int use = i >= lo && i <= hi;
            const double w = use ? wk[j] : 0.0 * wk[j];
            const double x = (use ? Tc[i - c0] - Tk : 0.0) / S;
            const double y = use ? nc[i - c0] - nk : 0.0;
            fit_terms(terms + j, m, w, x, y);
        }
        double c[3];
        solve_fit(terms, m, npts, c);
        const double c0f = c[0], c1 = c[1];
        out[r] = Tk;
        out[R + r] = base + (nk + c0f) / ppr;
        out[2 * R + r] = c1 / (S * ppr);
    }
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    free(Tc);
    Py_XDECREF(fT); Py_XDECREF(fn);
    PyBuffer_Release(&bwk); PyBuffer_Release(&bout);
    return ret;
}

/* The order tracker's speed [rpm] at board samples base + pos[i] (orders.py's _rpm of tacho
 * causal.py's evaluate_causal, the same operations in their order): the segment is the last
 * one whose key <= s among columns lo..hi-1 of sbuf (5 x cap: key, T, w, a, valid; numpy's
 * searchsorted, NaN sorting last), then sp = a tau + w with tau = s - T, capped at slack / tau
 * when tau w > slack, 0 unless valid > 0 and sp > 0 (and 0 before the first segment);
 * rpm = 60 (sp fs) where that is finite, else 0. */
static PyObject *causal_rpm(PyObject *self, PyObject *args) {
    Py_buffer bbuf, bpos, brpm;
    Py_ssize_t lo, hi;
    long long base;
    double fs, slack;
    if (!PyArg_ParseTuple(args, "y*nnLy*ddw*", &bbuf, &lo, &hi, &base, &bpos, &fs, &slack, &brpm))
        return NULL;
    PyObject *ret = NULL;
    const Py_ssize_t cap = bbuf.len / (Py_ssize_t)sizeof(double) / 5;
    const Py_ssize_t N = bpos.len / (Py_ssize_t)sizeof(long long);
    if (bbuf.len != 5 * cap * (Py_ssize_t)sizeof(double) || lo < 0 || hi < lo || hi > cap) {
        PyErr_SetString(PyExc_ValueError, "causal_rpm: expected sbuf (5 x cap), 0 <= lo <= hi <= cap");
        goto done;
    }
    if (!need(&brpm, N, "rpm"))
        goto done;
    const double *keys = (const double *)bbuf.buf + lo;
    const double *T = keys + cap, *w = keys + 2 * cap, *a = keys + 3 * cap, *v = keys + 4 * cap;
    const long long *pos = bpos.buf;
    double *rpm = brpm.buf;
    const Py_ssize_t n = hi - lo;
    Py_ssize_t j = -1;                  /* last key <= s; a hint carried from the previous sample */
    for (Py_ssize_t i = 0; i < N; i++) {
        const double s = (double)(base + pos[i]);
        /* numpy's s < key: true also when key is NaN (and s is not) */
#define KEY_AFTER(q) (s < keys[q] || (keys[q] != keys[q] && s == s))
        if (!((j < 0 || !KEY_AFTER(j)) && (j + 1 >= n || KEY_AFTER(j + 1)))) {
            Py_ssize_t l = 0, h = n;    /* count of keys not after s */
            while (l < h) {
                const Py_ssize_t mid = l + (h - l) / 2;
                if (KEY_AFTER(mid)) h = mid; else l = mid + 1;
            }
            j = l - 1;
        }
#undef KEY_AFTER
        if (j < 0) {                    /* before the first segment: not valid */
            rpm[i] = 0.0;
            continue;
        }
        const double tau = s - T[j];
        double sp = a[j] * tau;
        sp += w[j];
        if (tau * w[j] > slack) {       /* edges overdue: capped (np.minimum, NaN propagating) */
            const double c = slack / tau;
            if (!(sp <= c || sp != sp)) sp = c;
        }
        if (!(v[j] > 0 && sp > 0)) sp = 0.0;
        const double hz = sp * fs;
        rpm[i] = isfinite(hz) && sp != 0.0 ? 60.0 * hz : 0.0;
    }
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    PyBuffer_Release(&bbuf); PyBuffer_Release(&bpos); PyBuffer_Release(&brpm);
    return ret;
}

/* tacho edges.py: the functions at the end of this file, added at the module's creation */
static int add_tacho_edge_functions(PyObject *m);

static PyMethodDef methods[] = {
    {"envelope", envelope, METH_VARARGS, "Peak amplitudes of the tracker's state pairs (recursions.py)."},
    {"lerp_rows", lerp_rows, METH_VARARGS, "Table rows interpolated at fractional positions (gain table)."},
    {"lerp_at", lerp_at, METH_VARARGS, "Table rows interpolated at grid coordinates (gain table)."},
    {"block_stats", block_stats, METH_VARARGS, "The order tracker's per-block statistics (tracker.py)."},
    {"sosfilt", sosfilt, METH_VARARGS, "Anti-alias SOS cascade with carried state, decimating."},
    {"riccati", riccati, METH_VARARGS, "Exact Kalman gains per sample (Yeh, Pan & Le, eqs. 19-25)."},
    {"forward", forward, METH_VARARGS, "The tracker's filter recursion for C channels."},
    {"model_omega", model_omega, METH_VARARGS, "Model speed and omega / fs of the components (components.py)."},
    {"forward_blocks", forward_blocks, METH_VARARGS,
     "forward, envelope and block_stats in one pass, a partial block carried (tracker.py)."},
    {"live_in", live_in, METH_VARARGS,
     "A live call's decimation, delayed speed and model omega in one pass, or False (tracker.py)."},
    {"live_out", live_out, METH_VARARGS,
     "A live call's gains from the table and forward_blocks in one pass, or False (live.py)."},
    {"backward", backward, METH_VARARGS, "Modified Bryson-Frazier smoothing of one window."},
    {"tacho_eval", tacho_eval, METH_VARARGS, "Tacho speed and angle between knots (tacho.py)."},
    {"causal_fit", causal_fit, METH_VARARGS, "The tacho's causal segments of new edges (causal.py)."},
    {"knot_fit", knot_fit, METH_VARARGS, "The tacho's knots of the smoothed speed (smoothing.py)."},
    {"causal_rpm", causal_rpm, METH_VARARGS, "The causal speed [rpm] at samples (orders.py)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_trackerkernel",
                                     "Compiled order-tracker loops (see order_tracker.py).", -1, methods};

PyMODINIT_FUNC PyInit__trackerkernel(void) {
    PyObject *m = PyModule_Create(&module);
    if (m != NULL && add_tacho_edge_functions(m) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}

/* ---------------------------------------------------------------- tacho edges (edges.py)
 *
 *   edge_lists(t0, counts, offsets, L, last_t0, max_frames) -> (q, adv, end) or None
 *
 * tracker.py's _few_frames lists of a live call's TACHO frames (t0, counts: one per frame;
 * offsets: the frames' edge offsets, frame after frame; Python lists of ints): the edges
 * q = t0 * 256 + offset (1/256 sample) in time order within each frame, adv (at each frame's
 * first edge the coverage end of the frames before, t0 + L of the previous frame; -1 at the
 * first frame's and at every other edge) and end (the last frame's t0 + L).  None when the
 * frames need feed_few's checks in Python: none or more than max_frames of them, one
 * stepping back in time (from last_t0 on; None: none yet), a count below 0 or counts not
 * summing to len(offsets), an offset not u32, values near 2^53 (1/256 sample) or not ints.
 *
 *   tacho_payloads(payloads) -> (counts, offsets) or None
 *
 * monitor/shaft.py's decode_tacho_lists of TACHO payloads (docs/PROTOCOL.md: u16 N, then N
 * u32 edge offsets, little-endian; a list of bytes): the edge counts and all offsets, as
 * lists of ints; None when a payload is not bytes or not 2 + 4 N bytes long (Python then
 * gives each malformed one's message).
 *
 *   regular_edges(q, adv, j, hist, cT, cn, todo, pp, p, l, last_q, cq_last, now, n_last, i0,
 *                 tol, periods, lo, hi, margin) -> (k, now, pp, p, l)
 *
 * EdgeRuns._regular_edge of the edges q[j], q[j + 1], ... one after the other, as long as
 * each is regular: the same checks (the run's timeout before the edge, at the coverage end
 * adv[i] when >= 0 and at the edge; the edge after the last one received; its interval ratio
 * to EdgeRuns._predict's interval within 1 +- tol) and the same commitment (EdgeRuns._commit
 * of one pulse: (mid, rate) appended to hist, the deque of the predictor's last intervals,
 * the edge time and pulse count to cT and cn, (committed index, time) to todo, committed
 * indices from i0 on).  A ratio within margin of 1 +- tol stops it too: whatever an ulp
 * of difference in the prediction (Python's sum() of floats), the edge then goes through
 * the Python path, which decides.  q, adv: lists of ints (1/256 sample; samples, -1: no
 * advance); pp, p, l: the run's last three edges received; last_q: the last edge received;
 * cq_last: the last committed edge; now: the coverage end (samples).  Returns k, the edges
 * committed, and the state after them (coverage end, last three edges). */

#define TACHO_SUB 256
#define TACHO_MAX_HIST 64
#define TACHO_MAX_T ((1LL << 44) - 1)                 /* samples: 2^52 in 1/256 sample */

static PyObject *tacho_s_append, *tacho_s_maxlen;     /* interned method and attribute names */

/* o as an int in [lo, hi] into *v: 1, else 0 (no exception set: not an int, or outside). */
static int tacho_int(PyObject *o, long long lo, long long hi, long long *v) {
    if (!PyLong_Check(o)) return 0;
    int overflow;
    *v = PyLong_AsLongLongAndOverflow(o, &overflow);
    if (overflow || (*v == -1 && PyErr_Occurred())) {
        PyErr_Clear();
        return 0;
    }
    return lo <= *v && *v <= hi;
}

static PyObject *edge_lists(PyObject *self, PyObject *args) {
    PyObject *ot0, *ocounts, *ooff, *olast;
    long long L;
    Py_ssize_t max_frames;
    if (!PyArg_ParseTuple(args, "OOOLOn", &ot0, &ocounts, &ooff, &L, &olast, &max_frames))
        return NULL;
    if (!PyList_CheckExact(ot0) || !PyList_CheckExact(ocounts) || !PyList_CheckExact(ooff) || L < 0
        || L > TACHO_MAX_T)
        Py_RETURN_NONE;
    const Py_ssize_t F = PyList_GET_SIZE(ot0), E = PyList_GET_SIZE(ooff);
    long long prev = 0, t = 0, n = 0, total = 0, o;
    if (F < 1 || F > max_frames || PyList_GET_SIZE(ocounts) != F
        || (olast != Py_None && !tacho_int(olast, -TACHO_MAX_T, TACHO_MAX_T, &prev)))
        Py_RETURN_NONE;
    for (Py_ssize_t f = 0; f < F; f++) {              /* in time order, counts >= 0 adding up */
        if (!tacho_int(PyList_GET_ITEM(ot0, f), -TACHO_MAX_T, TACHO_MAX_T, &t)
            || !tacho_int(PyList_GET_ITEM(ocounts, f), 0, E, &n) || ((olast != Py_None || f > 0) && t < prev))
            Py_RETURN_NONE;
        prev = t;
        total += n;
    }
    if (total != E)
        Py_RETURN_NONE;
    long long *q = malloc(sizeof(long long) * (size_t)(E + 1));
    if (q == NULL)
        return PyErr_NoMemory();
    PyObject *lq = NULL, *ladv = NULL, *ret = NULL;
    Py_ssize_t pos = 0;
    for (Py_ssize_t f = 0; f < F; f++) {
        tacho_int(PyList_GET_ITEM(ot0, f), -TACHO_MAX_T, TACHO_MAX_T, &t);
        tacho_int(PyList_GET_ITEM(ocounts, f), 0, E, &n);
        for (Py_ssize_t e = pos; e < pos + n; e++) {
            if (!tacho_int(PyList_GET_ITEM(ooff, e), 0, 0xFFFFFFFFLL, &o)) {
                free(q);
                Py_RETURN_NONE;
            }
            const long long x = o + t * TACHO_SUB;
            Py_ssize_t i = e;
            for (; i > pos && q[i - 1] > x; i--) q[i] = q[i - 1];   /* sorted within the frame */
            q[i] = x;
        }
        pos += (Py_ssize_t)n;
    }
    lq = PyList_New(E);
    ladv = lq ? PyList_New(E) : NULL;
    if (ladv == NULL)
        goto done;
    pos = 0;
    long long end = -1;
    for (Py_ssize_t f = 0; f < F; f++) {
        tacho_int(PyList_GET_ITEM(ot0, f), -TACHO_MAX_T, TACHO_MAX_T, &t);
        tacho_int(PyList_GET_ITEM(ocounts, f), 0, E, &n);
        for (Py_ssize_t e = pos; e < pos + n; e++) {
            PyObject *a = PyLong_FromLongLong(q[e]), *b = PyLong_FromLongLong(e == pos ? end : -1);
            if (a == NULL || b == NULL) {
                Py_XDECREF(a); Py_XDECREF(b);
                goto done;
            }
            PyList_SET_ITEM(lq, e, a);
            PyList_SET_ITEM(ladv, e, b);
        }
        pos += (Py_ssize_t)n;
        end = t + L;
    }
    ret = Py_BuildValue("(OOL)", lq, ladv, end);
done:
    free(q);
    Py_XDECREF(lq); Py_XDECREF(ladv);
    return ret;
}

static PyObject *tacho_payloads(PyObject *self, PyObject *args) {
    PyObject *opay;
    if (!PyArg_ParseTuple(args, "O!", &PyList_Type, &opay))
        return NULL;
    const Py_ssize_t F = PyList_GET_SIZE(opay);
    Py_ssize_t E = 0;
    for (Py_ssize_t f = 0; f < F; f++) {               /* all well formed, or None */
        PyObject *p = PyList_GET_ITEM(opay, f);
        if (!PyBytes_CheckExact(p) || PyBytes_GET_SIZE(p) < 2)
            Py_RETURN_NONE;
        const unsigned char *b = (const unsigned char *)PyBytes_AS_STRING(p);
        const Py_ssize_t c = b[0] | (Py_ssize_t)b[1] << 8;
        if (PyBytes_GET_SIZE(p) != 2 + 4 * c)
            Py_RETURN_NONE;
        E += c;
    }
    PyObject *counts = PyList_New(F), *offsets = counts ? PyList_New(E) : NULL;
    if (offsets == NULL) {
        Py_XDECREF(counts);
        return NULL;
    }
    Py_ssize_t e = 0;
    for (Py_ssize_t f = 0; f < F; f++) {
        const unsigned char *b = (const unsigned char *)PyBytes_AS_STRING(PyList_GET_ITEM(opay, f));
        const Py_ssize_t c = b[0] | (Py_ssize_t)b[1] << 8;
        PyObject *oc = PyLong_FromSsize_t(c);
        if (oc == NULL) goto fail;
        PyList_SET_ITEM(counts, f, oc);
        for (Py_ssize_t i = 0; i < c; i++, e++) {
            const unsigned char *u = b + 2 + 4 * i;
            PyObject *oo = PyLong_FromUnsignedLong((unsigned long)u[0] | (unsigned long)u[1] << 8
                                                   | (unsigned long)u[2] << 16 | (unsigned long)u[3] << 24);
            if (oo == NULL) goto fail;
            PyList_SET_ITEM(offsets, e, oo);
        }
    }
    PyObject *ret = PyTuple_Pack(2, counts, offsets);
    Py_DECREF(counts); Py_DECREF(offsets);
    return ret;
fail:
    Py_DECREF(counts); Py_DECREF(offsets);
    return NULL;
}

/* EdgeRuns._predict over the n (mid, rate) entries, oldest first: Python's arithmetic, in
 * its order (sum() from 0.0 left to right, x ** 2 as pow(x, 2)). */
static double tacho_predict(const double *mid, const double *rate, int n, long long cq_last) {
    const double t_ref = mid[n - 1];
    double xs[TACHO_MAX_HIST];
    double sx = 0.0, sy = 0.0;
    for (int i = 0; i < n; i++) {
        xs[i] = mid[i] - t_ref;
        sx += xs[i];
        sy += rate[i];
    }
    const double xm = sx / (double)n, ym = sy / (double)n;
    double sxx = 0.0, sxy = 0.0;
    for (int i = 0; i < n; i++) sxx += pow(xs[i] - xm, 2.0);
    for (int i = 0; i < n; i++) sxy += (xs[i] - xm) * (rate[i] - ym);
    const double slope = sxx > 0 ? sxy / sxx : 0.0;
    const double r0 = ym + slope * (((double)cq_last - t_ref) - xm);
    const double d_last = 1.0 / rate[n - 1];
    const double disc = r0 * r0 + 2.0 * slope;
    if (r0 <= 0 || disc <= 0)
        return d_last;
    const double d = 2.0 / (r0 + sqrt(disc));
    const double lo = 0.5 * d_last, hi = 2.0 * d_last;
    const double m1 = lo > d ? lo : d;                    /* max(d, lo), min(m1, hi) as Python's */
    return hi < m1 ? hi : m1;
}

/* EdgeRuns._timeout_q of a run whose last three edges received are pp, p, l. */
static long long tacho_timeout_q(long long pp, long long p, long long l, double periods, long long lo,
                                 long long hi) {
    long long d = l - p;
    if (p - pp > d) d = p - pp;
    const long long t = (long long)ceil(periods * (double)d);
    const long long u = lo > t ? lo : t;
    return hi < u ? hi : u;
}

/* list.append(item), releasing item: -1 on an error (item NULL: its allocation failed). */
static int tacho_append(PyObject *list, PyObject *item) {
    if (item == NULL) return -1;
    const int rc = PyList_Append(list, item);
    Py_DECREF(item);
    return rc;
}

/* (a, b) of new references (released on a failure). */
static PyObject *tacho_pair(PyObject *a, PyObject *b) {
    PyObject *t = a && b ? PyTuple_New(2) : NULL;
    if (t == NULL) {
        Py_XDECREF(a); Py_XDECREF(b);
        return NULL;
    }
    PyTuple_SET_ITEM(t, 0, a);
    PyTuple_SET_ITEM(t, 1, b);
    return t;
}

/* hist.append(entry) (a deque), releasing entry: -1 on an error. */
static int tacho_hist_append(PyObject *hist, PyObject *entry) {
    if (entry == NULL) return -1;
    PyObject *res = PyObject_CallMethodObjArgs(hist, tacho_s_append, entry, NULL);
    Py_DECREF(entry);
    if (res == NULL) return -1;
    Py_DECREF(res);
    return 0;
}

static PyObject *regular_edges(PyObject *self, PyObject *args) {
    PyObject *oq, *oadv, *hist, *cT, *cn, *todo;
    Py_ssize_t j;
    long long pp, p, l, last_q, cq_last, now, n_last, i0, lo, hi;
    double tol, periods, margin;
    if (!PyArg_ParseTuple(args, "O!O!nOO!O!O!LLLLLLLLddLLd", &PyList_Type, &oq, &PyList_Type, &oadv, &j,
                          &hist, &PyList_Type, &cT, &PyList_Type, &cn, &PyList_Type, &todo, &pp, &p, &l,
                          &last_q, &cq_last, &now, &n_last, &i0, &tol, &periods, &lo, &hi, &margin))
        return NULL;
    const Py_ssize_t m = PyList_GET_SIZE(oq);
    if (PyList_GET_SIZE(oadv) != m || j < 0 || j > m) {
        PyErr_SetString(PyExc_ValueError, "regular_edges: expected q and adv of one length, 0 <= j <= len(q)");
        return NULL;
    }
    PyObject *maxlen = PyObject_GetAttr(hist, tacho_s_maxlen);
    if (maxlen == NULL) return NULL;
    const long w = maxlen == Py_None ? -1 : PyLong_AsLong(maxlen);
    Py_DECREF(maxlen);
    PyObject *fh = PySequence_Fast(hist, "regular_edges: hist must be a sequence");
    if (fh == NULL) return NULL;
    const Py_ssize_t nh = PySequence_Fast_GET_SIZE(fh);
    if (w < 2 || w > TACHO_MAX_HIST || nh < 2 || nh > w) {
        Py_DECREF(fh);
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "regular_edges: expected a deque of 2..maxlen (2..64) intervals");
        return NULL;
    }
    double mid[TACHO_MAX_HIST], rate[TACHO_MAX_HIST];
    int n = (int)nh;
    for (Py_ssize_t i = 0; i < nh; i++) {
        PyObject *e = PySequence_Fast_GET_ITEM(fh, i);
        if (!PyTuple_Check(e) || PyTuple_GET_SIZE(e) != 2) {
            PyErr_SetString(PyExc_ValueError, "regular_edges: hist entries must be (mid, rate) tuples");
            break;
        }
        mid[i] = PyFloat_AsDouble(PyTuple_GET_ITEM(e, 0));
        rate[i] = PyFloat_AsDouble(PyTuple_GET_ITEM(e, 1));
    }
    Py_DECREF(fh);
    if (PyErr_Occurred()) return NULL;
    for (Py_ssize_t i = j; i < m; i++) {            /* ints, or an error before any change */
        PyLong_AsLongLong(PyList_GET_ITEM(oq, i));
        PyLong_AsLongLong(PyList_GET_ITEM(oadv, i));
        if (PyErr_Occurred()) return NULL;
    }
    const double r_lo = 1.0 - tol + margin, r_hi = 1.0 + tol - margin;
    Py_ssize_t k = 0;
    for (Py_ssize_t i = j; i < m; i++) {
        const long long q = PyLong_AsLongLong(PyList_GET_ITEM(oq, i));
        const long long a = PyLong_AsLongLong(PyList_GET_ITEM(oadv, i));
        if (q <= last_q) break;
        const long long stop_q = l + tacho_timeout_q(pp, p, l, periods, lo, hi);
        const long long now_i = a >= 0 && a > now ? a : now;
        if (now_i * TACHO_SUB > stop_q || q > stop_q) break;
        const double P = tacho_predict(mid, rate, n, cq_last);
        if (!(P > 0)) break;
        const double r = (double)(q - cq_last) / P;
        if (!(r > r_lo && r < r_hi)) break;
        /* commit: EdgeRuns._commit(run, q, 1) after _regular_edge's updates */
        const long long d = q - cq_last;
        const double md = (double)cq_last + 0.5 * (double)d, rt = 1.0 / (double)d;
        const double T = (double)q / (double)TACHO_SUB;
        if (tacho_hist_append(hist, tacho_pair(PyFloat_FromDouble(md), PyFloat_FromDouble(rt))) < 0
            || tacho_append(cT, PyFloat_FromDouble(T)) < 0 || tacho_append(cn, PyLong_FromLongLong(n_last + 1)) < 0
            || tacho_append(todo, tacho_pair(PyLong_FromLongLong(i0 + k), PyFloat_FromDouble(T))) < 0)
            return NULL;
        if (n == w) {                                  /* the deque's oldest entry drops out */
            memmove(mid, mid + 1, sizeof(double) * (size_t)(n - 1));
            memmove(rate, rate + 1, sizeof(double) * (size_t)(n - 1));
            n--;
        }
        mid[n] = md;
        rate[n] = rt;
        n++;
        n_last++;
        cq_last = last_q = q;
        pp = p; p = l; l = q;
        now = now_i;
        k++;
    }
    return Py_BuildValue("(nLLLL)", k, now, pp, p, l);
}

/* The tacho edge functions, added to the module when it is created. */
static PyMethodDef tacho_edge_methods[] = {
    {"tacho_payloads", tacho_payloads, METH_VARARGS, "TACHO payloads as lists, or None (monitor/shaft.py)."},
    {"edge_lists", edge_lists, METH_VARARGS, "A live call's tacho edges as lists, or None (tacho tracker.py)."},
    {"regular_edges", regular_edges, METH_VARARGS,
     "A live call's regular tacho edges committed in one step (tacho edges.py)."},
    {NULL, NULL, 0, NULL},
};

static int add_tacho_edge_functions(PyObject *m) {
    tacho_s_append = PyUnicode_InternFromString("append");
    tacho_s_maxlen = PyUnicode_InternFromString("maxlen");
    if (tacho_s_append == NULL || tacho_s_maxlen == NULL)
        return -1;
    return PyModule_AddFunctions(m, tacho_edge_methods);
}
