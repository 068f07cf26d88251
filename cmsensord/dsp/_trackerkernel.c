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
 *   edge_lists, tacho_payloads, regular_edges      a live call's tacho edges (_trackerkernel_edges.c)
 *
 * This file holds the module; the functions are in _trackerkernel_filter.c (sosfilt, riccati,
 * forward, backward, envelope), _trackerkernel_blocks.c (the gain table's rows, block_stats,
 * model_omega, forward_blocks, live_in, live_out), _trackerkernel_tacho.c (tacho_eval,
 * causal_fit, knot_fit, causal_rpm) and _trackerkernel_edges.c; _trackerkernel.h holds what
 * they share.
 */
#include "_trackerkernel.h"

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
