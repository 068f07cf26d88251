/*
 * The wire decoder's scan of a receive buffer, in C (docs/PROTOCOL.md receiver rules 1-3,
 * rule 4's t0 unwrapping and rule 5's counters).
 *
 * scan() is the frame-by-frame loop of Decoder._scan in cmsensord/protocol.py (the plain
 * reference, Decoder(runs=False)) step for step: hunt for A5 5A, reject a header with a
 * version other than `version`, a type outside 1..max_type or len > max_payload by dropping
 * the first sync byte, wait for (or, with `final`, drop the first sync byte of) an
 * incomplete candidate, check each frame's CRC-32 on its own bytes 2 .. 14+len-1 and on a
 * mismatch drop only the first sync byte (rule 2), count seq gaps mod 65536 (rule 3) and
 * unwrap t0 across 2^32 (rule 4).  Instead of a frame object per good frame it writes the
 * frame's fields into ten int64 rows of `out` (the order of cmsensord.frame_batch.Columns:
 * type code, seq, t0, chan, flags, payload start, payload end, unwrapped t0, stream offset,
 * seq gap), one column per frame; or, given the Frame class, it makes the Frame tuples itself
 * (a live read of a few frames, where building them from columns would cost more than the scan).
 *
 * The CRC is zlib's (IEEE 802.3, reflected, polynomial 0xEDB88320, initial and final
 * value 0xFFFFFFFF), computed slice-by-8 from tables made at import, so the module needs
 * nothing but the C library.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

#define HEADER_LEN 14
#define CRC_LEN 4
#define N_ROWS 10
/* below this many bytes the scan keeps the GIL (a live read of a few frames: dropping and
   taking the GIL back would cost more than the scan) */
#define RELEASE_GIL_BYTES 16384

static uint32_t crc_table[8][256];

static void make_tables(void) {
    for (uint32_t i = 0; i < 256; i++) {
        uint32_t c = i;
        for (int k = 0; k < 8; k++)
            c = (c & 1) ? (c >> 1) ^ 0xEDB88320u : c >> 1;
        crc_table[0][i] = c;
    }
    for (uint32_t i = 0; i < 256; i++)
        for (int t = 1; t < 8; t++)
            crc_table[t][i] = (crc_table[t - 1][i] >> 8) ^ crc_table[0][crc_table[t - 1][i] & 0xFF];
}

static inline uint32_t le32(const uint8_t *p) {
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

static inline uint32_t le16(const uint8_t *p) {
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8);
}

/* zlib.crc32(p[0:n]) */
static uint32_t crc32_ieee(const uint8_t *p, Py_ssize_t n) {
    uint32_t c = 0xFFFFFFFFu;
    while (n >= 8) {
        uint32_t a = le32(p) ^ c, b = le32(p + 4);
        c = crc_table[7][a & 0xFF] ^ crc_table[6][(a >> 8) & 0xFF] ^ crc_table[5][(a >> 16) & 0xFF] ^
            crc_table[4][a >> 24] ^ crc_table[3][b & 0xFF] ^ crc_table[2][(b >> 8) & 0xFF] ^
            crc_table[1][(b >> 16) & 0xFF] ^ crc_table[0][b >> 24];
        p += 8;
        n -= 8;
    }
    while (n-- > 0)
        c = (c >> 8) ^ crc_table[0][(c ^ *p++) & 0xFF];
    return c ^ 0xFFFFFFFFu;
}

/* the offset of the first A5 5A at or after `pos`, or -1 */
static Py_ssize_t find_sync(const uint8_t *buf, Py_ssize_t n, Py_ssize_t pos) {
    while (pos + 1 < n) {
        const uint8_t *hit = memchr(buf + pos, 0xA5, (size_t)(n - 1 - pos));
        if (hit == NULL)
            return -1;
        pos = hit - buf;
        if (buf[pos + 1] == 0x5A)
            return pos;
        pos++;
    }
    return -1;
}

typedef struct {
    /* parameters */
    const uint8_t *buf;
    Py_ssize_t n;
    int final;
    long version, max_type, max_payload;
    long long base;
    /* receiver state (rules 3 and 4); has_seq 0: no frame yet */
    int has_seq;
    long long last_seq, last_t0, last_unw;
    /* results: columns in out, or (frame_cls not NULL) Frame tuples appended to list */
    PyTypeObject *frame_cls;
    PyObject *types, *list;
    int failed;
    int64_t *out;
    Py_ssize_t cap, k, pos;
    long long discarded, rejects, crc_fail, lost, overruns;
    long long by_type[256];
} Scan;

/* a frame_cls tuple of the 9 Frame fields (NULL and an exception when out of memory) */
static PyObject *make_frame(Scan *s, uint32_t code, uint32_t seq, uint32_t t0, uint32_t chan, uint32_t flags,
                            Py_ssize_t end_payload, long long unw, long long lost) {
    PyObject *f = s->frame_cls->tp_alloc(s->frame_cls, 9);
    if (f == NULL)
        return NULL;
    PyObject *type = PyTuple_GET_ITEM(s->types, code);
    Py_INCREF(type);
    PyTuple_SET_ITEM(f, 0, type);
    PyObject *v[8] = {
        PyLong_FromUnsignedLong(seq), PyLong_FromUnsignedLong(t0), PyLong_FromUnsignedLong(chan),
        PyLong_FromUnsignedLong(flags),
        PyBytes_FromStringAndSize((const char *)s->buf + s->pos + HEADER_LEN, end_payload - s->pos - HEADER_LEN),
        PyLong_FromLongLong(unw), PyLong_FromLongLong(s->base + s->pos), PyLong_FromLongLong(lost)};
    int ok = 1;
    for (int i = 0; i < 8; i++) {
        PyTuple_SET_ITEM(f, i + 1, v[i]);
        ok = ok && v[i] != NULL;
    }
    if (!ok) {
        Py_DECREF(f);
        return NULL;
    }
    return f;
}

/* one good frame at s->pos with these header fields: its column (or Frame), the counters, the state */
static void take_frame(Scan *s, uint32_t code, uint32_t seq, uint32_t t0, uint32_t chan, uint32_t flags,
                       Py_ssize_t end_payload) {
    long long lost, unw;
    if (!s->has_seq) {
        lost = 0;
        unw = t0;
    } else {
        lost = ((long long)seq - s->last_seq - 1) & 0xFFFF;
        unw = s->last_unw + ((((long long)t0 - s->last_t0 + 0x80000000LL) & 0xFFFFFFFFLL) - 0x80000000LL);
    }
    s->has_seq = 1;
    s->last_seq = seq;
    s->last_t0 = t0;
    s->last_unw = unw;
    s->lost += lost;
    if (flags & 1)                      /* FLAG_OVERRUN */
        s->overruns++;
    s->by_type[code]++;
    if (s->frame_cls != NULL) {
        PyObject *f = make_frame(s, code, seq, t0, chan, flags, end_payload, unw, lost);
        if (f == NULL || PyList_Append(s->list, f) < 0)
            s->failed = 1;
        Py_XDECREF(f);
        s->k++;
        return;
    }
    int64_t *col = s->out + s->k;
    const Py_ssize_t cap = s->cap;
    col[0] = code;
    col[cap] = seq;
    col[2 * cap] = t0;
    col[3 * cap] = chan;
    col[4 * cap] = flags;
    col[5 * cap] = s->pos + HEADER_LEN;
    col[6 * cap] = end_payload;
    col[7 * cap] = unw;
    col[8 * cap] = s->base + s->pos;
    col[9 * cap] = lost;
    s->k++;
}

/* the loop of Decoder._scan (see the file's comment) */
static void run_scan(Scan *s) {
    const uint8_t *buf = s->buf;
    const Py_ssize_t n = s->n;
    Py_ssize_t pos = 0;
    for (;;) {
        Py_ssize_t i = find_sync(buf, n, pos);
        if (i < 0) {                    /* no sync: keep only a trailing 0xA5 (half a sync) */
            Py_ssize_t keep = (!s->final && n > pos && buf[n - 1] == 0xA5) ? 1 : 0;
            s->discarded += n - keep - pos;
            pos = n - keep;
            break;
        }
        s->discarded += i - pos;
        pos = i;
        if (n - pos < HEADER_LEN) {
            if (s->final) {             /* truncated header at end of stream: not a frame */
                s->discarded++;
                pos++;
                continue;
            }
            break;
        }
        const uint8_t *h = buf + pos + 2;
        const uint32_t ver = h[0], code = h[1], ln = le16(h + 10);
        if (ver != (uint32_t)s->version || code < 1 || code > (uint32_t)s->max_type ||
            ln > (uint32_t)s->max_payload) {            /* rule 1 */
            s->rejects++;
            s->discarded++;
            pos++;
            continue;
        }
        const Py_ssize_t end_payload = pos + HEADER_LEN + (Py_ssize_t)ln;
        const Py_ssize_t end = end_payload + CRC_LEN;
        if (end > n) {
            if (s->final) {             /* truncated frame at end of stream: not a frame */
                s->discarded++;
                pos++;
                continue;
            }
            break;                      /* rule 2: wait for the whole frame */
        }
        if (crc32_ieee(h, end_payload - pos - 2) != le32(buf + end_payload)) {
            s->crc_fail++;              /* rule 2: drop only the first sync byte */
            s->discarded++;
            pos++;
            continue;
        }
        s->pos = pos;
        take_frame(s, code, le16(h + 2), le32(h + 4), h[8], h[9], end_payload);
        pos = end;
        if (s->failed)
            return;
    }
    s->pos = pos;
}

PyDoc_STRVAR(scan_doc,
"scan(buf, final, version, max_type, max_payload, base, last_seq, last_t0, last_unw, out, frame_cls, types)\n"
"\n"
"Frame every complete candidate of ``buf`` as Decoder._scan does (receiver rules 1-4).\n"
"``last_seq`` -1: no frame yet.  ``frame_cls`` None: the frames go into ``out`` (int64, 10 rows\n"
"of ``cap`` columns, C order, cap >= len(buf) // 18); else they are made as ``frame_cls`` tuples\n"
"(``types[code]`` their type, ``out`` unused).  Returns (frames: their number or their list,\n"
"bytes consumed, discarded, header rejects, CRC failures, frames lost, overruns,\n"
"(frames of type 0 .. max_type), last_seq or None, last_t0, last_unw).");

static PyObject *scan(PyObject *self, PyObject *args) {
    Py_buffer bbuf, bout = {0};
    int final;
    long version, max_type, max_payload;
    long long base, last_seq, last_t0, last_unw;
    PyObject *out, *frame_cls, *types;
    if (!PyArg_ParseTuple(args, "y*plllLLLLOOO", &bbuf, &final, &version, &max_type, &max_payload, &base,
                          &last_seq, &last_t0, &last_unw, &out, &frame_cls, &types))
        return NULL;
    PyObject *ret = NULL, *found = NULL;
    Scan *s = PyMem_Calloc(1, sizeof(Scan));
    if (s == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    if (max_type < 1 || max_type > 255 || max_payload < 0) {
        PyErr_SetString(PyExc_ValueError, "max_type must be 1..255 and max_payload >= 0");
        goto done;
    }
    if (frame_cls != Py_None) {
        if (!PyType_Check(frame_cls) || !PyType_IsSubtype((PyTypeObject *)frame_cls, &PyTuple_Type) ||
            !PyTuple_Check(types) || PyTuple_GET_SIZE(types) <= max_type) {
            PyErr_SetString(PyExc_TypeError, "frame_cls must be a tuple subclass and types a tuple of max_type + 1");
            goto done;
        }
        s->frame_cls = (PyTypeObject *)frame_cls;
        s->types = types;
        found = s->list = PyList_New(0);
        if (found == NULL)
            goto done;
    } else {
        if (PyObject_GetBuffer(out, &bout, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS) < 0)
            goto done;
        s->out = bout.buf;
        s->cap = bout.len / (Py_ssize_t)(N_ROWS * sizeof(int64_t));
        if (s->cap < bbuf.len / (HEADER_LEN + CRC_LEN)) {
            PyErr_Format(PyExc_ValueError, "out holds %zd frames, a buffer of %zd bytes may hold %zd",
                         s->cap, bbuf.len, bbuf.len / (HEADER_LEN + CRC_LEN));
            goto done;
        }
    }
    s->buf = bbuf.buf;
    s->n = bbuf.len;
    s->final = final;
    s->version = version;
    s->max_type = max_type;
    s->max_payload = max_payload;
    s->base = base;
    s->has_seq = last_seq >= 0;
    s->last_seq = last_seq;
    s->last_t0 = last_t0;
    s->last_unw = last_unw;
    if (s->frame_cls == NULL && s->n >= RELEASE_GIL_BYTES) {   /* columns only: no object made */
        Py_BEGIN_ALLOW_THREADS
        run_scan(s);
        Py_END_ALLOW_THREADS
    } else {
        run_scan(s);
    }
    if (s->failed)
        goto done;
    if (found == NULL && (found = PyLong_FromSsize_t(s->k)) == NULL)
        goto done;
    PyObject *counts = PyTuple_New(max_type + 1);
    if (counts == NULL)
        goto done;
    for (long t = 0; t <= max_type; t++) {
        PyObject *v = PyLong_FromLongLong(s->by_type[t]);
        if (v == NULL) {
            Py_DECREF(counts);
            goto done;
        }
        PyTuple_SET_ITEM(counts, t, v);
    }
    ret = Py_BuildValue("OnLLLLLNNLL", found, s->pos, s->discarded, s->rejects, s->crc_fail, s->lost,
                        s->overruns, counts, s->has_seq ? PyLong_FromLongLong(s->last_seq) : Py_NewRef(Py_None),
                        s->last_t0, s->last_unw);
done:
    Py_XDECREF(found);
    PyMem_Free(s);
    PyBuffer_Release(&bbuf);
    if (bout.obj != NULL)
        PyBuffer_Release(&bout);
    return ret;
}

PyDoc_STRVAR(crc32_doc, "crc32(data) -> int: zlib.crc32(data), this module's own table-driven CRC-32.");

static PyObject *crc32_py(PyObject *self, PyObject *args) {
    Py_buffer b;
    if (!PyArg_ParseTuple(args, "y*", &b))
        return NULL;
    uint32_t c = crc32_ieee(b.buf, b.len);
    PyBuffer_Release(&b);
    return PyLong_FromUnsignedLong(c);
}

static PyMethodDef methods[] = {
    {"scan", scan, METH_VARARGS, scan_doc},
    {"crc32", crc32_py, METH_VARARGS, crc32_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_wirekernel",
    "The wire decoder's scan of a receive buffer (cmsensord/protocol.py's Decoder), in C.", -1, methods,
};

PyMODINIT_FUNC PyInit__wirekernel(void) {
    make_tables();
    return PyModule_Create(&module);
}
