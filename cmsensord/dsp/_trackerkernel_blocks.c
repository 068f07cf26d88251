/*
 * The order tracker's per-block work: the gain table's rows interpolated (gain_table.py), the
 * per-block statistics, the model speed and omega (components.py), the fused filter +
 * envelope + statistics pass, and a live call's two passes (live.py).  _trackerkernel.c lists
 * the functions.
 */
#include "_trackerkernel.h"

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
PyObject *lerp_rows(PyObject *self, PyObject *args) {
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
PyObject *lerp_at(PyObject *self, PyObject *args) {
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

PyObject *block_stats(PyObject *self, PyObject *args) {
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
PyObject *model_omega(PyObject *self, PyObject *args) {
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

PyObject *forward_blocks(PyObject *self, PyObject *args) {
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
PyObject *live_in(PyObject *self, PyObject *args) {
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
PyObject *live_out(PyObject *self, PyObject *args) {
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
