/*
 * A live call's tacho edges (edges.py, tracker.py, monitor/shaft.py): the functions below,
 * added to the _trackerkernel module by add_tacho_edge_functions at its creation.
 */
#include "_trackerkernel.h"

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

int add_tacho_edge_functions(PyObject *m) {
    tacho_s_append = PyUnicode_InternFromString("append");
    tacho_s_maxlen = PyUnicode_InternFromString("maxlen");
    if (tacho_s_append == NULL || tacho_s_maxlen == NULL)
        return -1;
    return PyModule_AddFunctions(m, tacho_edge_methods);
}
