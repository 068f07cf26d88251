/*
 * The tacho's compiled loops (docs/tacho.md): the speed and angle between knots (tacho_eval),
 * the causal segments of new edges (causal_fit), the knots of the smoothed speed (knot_fit)
 * and the causal speed at samples (causal_rpm).  _trackerkernel.c lists the functions.
 */
#include "_trackerkernel.h"

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

/* TachoTracker.evaluate between knots (tacho.py documents it; same arithmetic, in
 * the same order, as its numpy expressions).  For each sample s[i]: j[i] = the
 * last knot with kT <= s[i] (numpy.searchsorted(kT, s, "right") - 1, clipped to
 * 0 .. n-1; NaN sorts after everything); code[i] = 0 before the first knot, 1
 * between knots j and j+1 of one run (kr equal): then speed[i] (linear) and
 * turns[i] (cubic Hermite) are written; 2 otherwise (after a run's last knot:
 * left to the caller, as are the samples before; speed and turns are 0 there). */
PyObject *tacho_eval(PyObject *self, PyObject *args) {
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

/* The causal segment of each new committed edge (tacho causal.py's _flush_segments and
 * smoothing.py's weighted_quadratic, the same operations in their order): edge k (committed
 * index; Tc, nc: the run's committed edge times and pulse counts from index c0 on, Python
 * lists of numbers) of each (k, known) in todo is fitted with the weighted quadratic over the
 * edges k, k - 1, ... back to m = len(ck) of them (weights ck, those before c0 left out), x
 * scaled by the largest |dx|.  Its segment goes to column col + r of sbuf (5 x cap): key =
 * max(known, T), T, speed, acceleration, valid (1.0: two points or more). */
PyObject *causal_fit(PyObject *self, PyObject *args) {
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
PyObject *knot_fit(PyObject *self, PyObject *args) {
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
PyObject *causal_rpm(PyObject *self, PyObject *args) {
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
