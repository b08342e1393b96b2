/* The compiled twin of biped_sim/recording/frames.py's PyFrameBuffer: the recording process's frames for
 * its bag writer process, appended in one C call a message or a period under the interpreter lock.
 *
 * Why C: the node records about 45000 periods a wall second in fast mode. Queuing Python tuples for a
 * sender thread to marshal kept ~5 container objects a period alive for 0.1 s, which set off the cyclic
 * collector in the simulating thread, and the marshal, the deallocation and the page faults of that
 * garbage took the interpreter lock from it (docs/performance.md, "Recording"). Here a period is copied
 * into one growable buffer that is reused from one hand-over to the next, and no object survives the call.
 *
 * The bytes are frames.py's, bit for bit (test/unit/test_frames.py): FRAME = "<cI" (kind, payload length),
 * and inside an "M" frame, RECORD = "<QHI" (t_ns, channel id, CDR length) then the CDR. Every value is
 * written little-endian byte by byte, so the output does not depend on the host. A call checks all it is
 * given before it writes anything: a refused call leaves the buffer as it was.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <errno.h>
#include <stdint.h>
#include <string.h>
#include <unistd.h>

#define FRAME_SIZE 5
#define RECORD_SIZE 14
#define MAX_PAYLOAD 0xFFFFFFFFu

typedef struct {
    PyObject_HEAD
    PyObject *channels;   /* dict: topic (str) -> channel id (int, 1..65535) */
    char *buf;
    Py_ssize_t len, cap;
    Py_ssize_t open;      /* offset of the open "M" frame's header, or -1 */
    char *spare;          /* the buffer write_to wrote last: the next one to fill */
    Py_ssize_t spare_cap;
    int writing;          /* write_to runs (without the interpreter lock) */
} FrameBuffer;

static void put_u16(char *p, uint16_t v) { p[0] = (char)v; p[1] = (char)(v >> 8); }
static void put_u32(char *p, uint32_t v) { for (int i = 0; i < 4; i++) p[i] = (char)(v >> (8 * i)); }
static void put_u64(char *p, uint64_t v) { for (int i = 0; i < 8; i++) p[i] = (char)(v >> (8 * i)); }

static int reserve(FrameBuffer *self, Py_ssize_t extra) {
    if (extra > PY_SSIZE_T_MAX - self->len) {
        PyErr_NoMemory();
        return -1;
    }
    if (self->len + extra <= self->cap) return 0;
    Py_ssize_t cap = self->cap ? self->cap : 65536;
    while (cap < self->len + extra) cap = cap > PY_SSIZE_T_MAX / 2 ? self->len + extra : cap * 2;
    char *b = PyMem_RawRealloc(self->buf, (size_t)cap);
    if (b == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    self->buf = b;
    self->cap = cap;
    return 0;
}

static void close_frame(FrameBuffer *self) {
    if (self->open >= 0) {
        put_u32(self->buf + self->open + 1, (uint32_t)(self->len - self->open - FRAME_SIZE));
        self->open = -1;
    }
}

/* The channel id of ``topic`` and the size of ``data``, checked (-1 and an exception if refused). */
static int check_message(FrameBuffer *self, PyObject *topic, PyObject *data, uint16_t *cid, Py_ssize_t *size) {
    PyObject *id = PyDict_GetItemWithError(self->channels, topic);   /* borrowed */
    if (id == NULL) {
        if (!PyErr_Occurred())
            PyErr_Format(PyExc_ValueError, "unknown topic %R: call add_topic first", topic);
        return -1;
    }
    long v = PyLong_AsLong(id);
    if (v == -1 && PyErr_Occurred()) return -1;
    if (v < 1 || v > 65535) {
        PyErr_Format(PyExc_ValueError, "the channel id of %R must be 1..65535, got %ld", topic, v);
        return -1;
    }
    if (!PyBytes_Check(data)) {
        PyErr_Format(PyExc_TypeError, "the CDR of a message on %R must be bytes, not %.100s", topic,
                     Py_TYPE(data)->tp_name);
        return -1;
    }
    *size = PyBytes_GET_SIZE(data);
    if ((uint64_t)*size > MAX_PAYLOAD - RECORD_SIZE) {
        PyErr_Format(PyExc_ValueError, "a message on %R is larger than a frame can hold", topic);
        return -1;
    }
    *cid = (uint16_t)v;
    return 0;
}

static int check_time(PyObject *t_ns, uint64_t *out) {
    if (!PyLong_Check(t_ns)) {
        PyErr_Format(PyExc_TypeError, "t_ns must be an int (nanoseconds), not %.100s", Py_TYPE(t_ns)->tp_name);
        return -1;
    }
    int overflow;
    long long v = PyLong_AsLongLongAndOverflow(t_ns, &overflow);
    if (v == -1 && PyErr_Occurred()) return -1;
    if (overflow < 0 || (overflow == 0 && v < 0)) {
        PyErr_SetString(PyExc_ValueError, "t_ns must be >= 0");
        return -1;
    }
    if (overflow == 0) {
        *out = (uint64_t)v;
        return 0;
    }
    *out = PyLong_AsUnsignedLongLong(t_ns);     /* OverflowError beyond 64 bits */
    return (*out == (uint64_t)-1 && PyErr_Occurred()) ? -1 : 0;
}

/* Room for a record of ``size`` bytes of CDR in the open "M" frame (opened here if none is). */
static int open_record(FrameBuffer *self, Py_ssize_t size) {
    Py_ssize_t need = RECORD_SIZE + size;
    if (self->open >= 0 && (uint64_t)(self->len - self->open - FRAME_SIZE) + (uint64_t)need > MAX_PAYLOAD)
        close_frame(self);
    if (reserve(self, need + (self->open < 0 ? FRAME_SIZE : 0)) < 0) return -1;
    if (self->open < 0) {
        self->open = self->len;
        self->buf[self->len] = 'M';
        put_u32(self->buf + self->len + 1, 0);
        self->len += FRAME_SIZE;
    }
    return 0;
}

static void put_record(FrameBuffer *self, uint64_t t, uint16_t cid, PyObject *data, Py_ssize_t size) {
    char *p = self->buf + self->len;
    put_u64(p, t);
    put_u16(p + 8, cid);
    put_u32(p + 10, (uint32_t)size);
    memcpy(p + RECORD_SIZE, PyBytes_AS_STRING(data), (size_t)size);
    self->len += RECORD_SIZE + size;
}

static PyObject *FrameBuffer_message(FrameBuffer *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "message(t_ns, topic, data) takes 3 arguments");
        return NULL;
    }
    uint64_t t;
    uint16_t cid;
    Py_ssize_t size;
    if (check_time(args[0], &t) < 0 || check_message(self, args[1], args[2], &cid, &size) < 0) return NULL;
    if (open_record(self, size) < 0) return NULL;
    put_record(self, t, cid, args[2], size);
    Py_RETURN_NONE;
}

static PyObject *FrameBuffer_messages(FrameBuffer *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2) {
        PyErr_SetString(PyExc_TypeError, "messages(t_ns, messages) takes 2 arguments");
        return NULL;
    }
    uint64_t t;
    if (check_time(args[0], &t) < 0) return NULL;
    if (!PyList_Check(args[1]) && !PyTuple_Check(args[1])) {
        PyErr_SetString(PyExc_TypeError, "messages must be a list of (topic, CDR bytes)");
        return NULL;
    }
    PyObject *seq = PySequence_Fast(args[1], "messages must be a list of (topic, CDR bytes)");
    if (seq == NULL) return NULL;
    Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    PyObject **items = PySequence_Fast_ITEMS(seq);
    uint16_t cid;
    Py_ssize_t size;
    for (Py_ssize_t i = 0; i < n; i++) {      /* all checked before anything is written: the shapes, */
        if (!PyTuple_CheckExact(items[i]) || PyTuple_GET_SIZE(items[i]) != 2) {
            PyErr_SetString(PyExc_TypeError, "messages must be a list of (topic, CDR bytes)");
            goto fail;
        }
    }
    for (Py_ssize_t i = 0; i < n; i++) {      /* then the topics and the CDR */
        if (check_message(self, PyTuple_GET_ITEM(items[i], 0), PyTuple_GET_ITEM(items[i], 1), &cid, &size) < 0)
            goto fail;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *data = PyTuple_GET_ITEM(items[i], 1);
        check_message(self, PyTuple_GET_ITEM(items[i], 0), data, &cid, &size);   /* checked above */
        if (open_record(self, size) < 0) goto fail;      /* only out of memory: what was written stays whole */
        put_record(self, t, cid, data, size);
    }
    Py_DECREF(seq);
    Py_RETURN_NONE;
fail:
    Py_DECREF(seq);
    return NULL;
}

static PyObject *FrameBuffer_frame(FrameBuffer *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 2 || !PyBytes_Check(args[0]) || PyBytes_GET_SIZE(args[0]) != 1 || !PyBytes_Check(args[1])) {
        PyErr_SetString(PyExc_TypeError, "frame(kind, payload): kind one byte, payload bytes");
        return NULL;
    }
    Py_ssize_t n = PyBytes_GET_SIZE(args[1]);
    if ((uint64_t)n > MAX_PAYLOAD) {
        PyErr_SetString(PyExc_ValueError, "a frame's payload must be shorter than 4 GiB");
        return NULL;
    }
    close_frame(self);
    if (reserve(self, FRAME_SIZE + n) < 0) return NULL;
    char *p = self->buf + self->len;
    p[0] = PyBytes_AS_STRING(args[0])[0];
    put_u32(p + 1, (uint32_t)n);
    memcpy(p + FRAME_SIZE, PyBytes_AS_STRING(args[1]), (size_t)n);
    self->len += FRAME_SIZE + n;
    Py_RETURN_NONE;
}

static PyObject *FrameBuffer_take(FrameBuffer *self, PyObject *Py_UNUSED(ignored)) {
    close_frame(self);
    PyObject *out = PyBytes_FromStringAndSize(self->buf ? self->buf : "", self->len);
    if (out != NULL) self->len = 0;       /* the memory stays for the next hand-over */
    return out;
}

/* Why: the sender thread used to copy 0.1 s of frames (about 2 MB in a fast run) into a new bytes
 * object under the interpreter lock, page faults included, about 1 ms a hand-over taken from the
 * simulating thread. Here the filled buffer is swapped for the spare one under the lock, written
 * without it, and kept as the next spare. */
static PyObject *FrameBuffer_write_to(FrameBuffer *self, PyObject *arg) {
    int fd = PyObject_AsFileDescriptor(arg);
    if (fd < 0) return NULL;
    if (self->writing) {
        PyErr_SetString(PyExc_RuntimeError, "write_to is already running in another thread");
        return NULL;
    }
    close_frame(self);
    char *out = self->buf;
    Py_ssize_t n = self->len, out_cap = self->cap, done = 0;
    self->buf = self->spare;
    self->cap = self->spare_cap;
    self->len = 0;
    self->spare = NULL;
    self->spare_cap = 0;
    self->writing = 1;
    int err = 0;
    Py_BEGIN_ALLOW_THREADS
    while (done < n) {
        ssize_t w = write(fd, out + done, (size_t)(n - done));
        if (w < 0) {
            if (errno == EINTR) continue;
            err = errno;
            break;
        }
        done += w;
    }
    Py_END_ALLOW_THREADS
    self->writing = 0;
    if (self->spare == NULL) {
        self->spare = out;
        self->spare_cap = out_cap;
    } else {
        PyMem_RawFree(out);
    }
    if (err) {
        errno = err;
        return PyErr_SetFromErrno(PyExc_OSError);
    }
    return PyLong_FromSsize_t(n);
}

static Py_ssize_t FrameBuffer_len(FrameBuffer *self) { return self->len; }

/* Why touch the memory here: the first fill of the two buffers (a few MB in a fast run) otherwise page
 * faults in the simulating thread during the run's first hand-overs, as a real-time loop must not. */
static char *touched(Py_ssize_t capacity) {
    char *b = PyMem_RawMalloc((size_t)capacity);
    if (b != NULL) memset(b, 0, (size_t)capacity);
    return b;
}

static int FrameBuffer_init(FrameBuffer *self, PyObject *args, PyObject *kwds) {
    static char *kwlist[] = {"channels", "capacity", NULL};
    PyObject *channels;
    Py_ssize_t capacity = 0;
    if (!PyArg_ParseTupleAndKeywords(args, kwds, "O!|n:FrameBuffer", kwlist, &PyDict_Type, &channels, &capacity))
        return -1;
    if (capacity < 0) {
        PyErr_SetString(PyExc_ValueError, "capacity must be >= 0");
        return -1;
    }
    Py_INCREF(channels);
    Py_XSETREF(self->channels, channels);
    self->len = 0;
    self->open = -1;
    if (capacity > 0 && self->buf == NULL && self->spare == NULL) {
        self->buf = touched(capacity);
        self->spare = touched(capacity);
        if (self->buf == NULL || self->spare == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        self->cap = self->spare_cap = capacity;
    }
    return 0;
}

static void FrameBuffer_dealloc(FrameBuffer *self) {
    Py_XDECREF(self->channels);
    PyMem_RawFree(self->buf);
    PyMem_RawFree(self->spare);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyObject *FrameBuffer_new(PyTypeObject *type, PyObject *args, PyObject *kwds) {
    FrameBuffer *self = (FrameBuffer *)type->tp_alloc(type, 0);
    if (self != NULL) self->open = -1;
    return (PyObject *)self;
}

static PyObject *FrameBuffer_get_channels(FrameBuffer *self, void *closure) {
    Py_INCREF(self->channels);
    return self->channels;
}

static PyMethodDef FrameBuffer_methods[] = {
    {"message", (PyCFunction)(void (*)(void))FrameBuffer_message, METH_FASTCALL,
     "message(t_ns, topic, data): one message record (in the open M frame)."},
    {"messages", (PyCFunction)(void (*)(void))FrameBuffer_messages, METH_FASTCALL,
     "messages(t_ns, [(topic, data), ...]): the records of one time, all or none."},
    {"frame", (PyCFunction)(void (*)(void))FrameBuffer_frame, METH_FASTCALL,
     "frame(kind, payload): a frame of its own (it ends the open M frame)."},
    {"take", (PyCFunction)FrameBuffer_take, METH_NOARGS, "take() -> bytes: everything so far; the buffer empties."},
    {"write_to", (PyCFunction)FrameBuffer_write_to, METH_O,
     "write_to(fd) -> int: everything so far written to fd (without the interpreter lock); the buffer empties."},
    {NULL, NULL, 0, NULL},
};

static PyGetSetDef FrameBuffer_getset[] = {
    {"channels", (getter)FrameBuffer_get_channels, NULL, "topic -> channel id (the dict it was given)", NULL},
    {NULL, NULL, NULL, NULL, NULL},
};

static PySequenceMethods FrameBuffer_as_sequence = {.sq_length = (lenfunc)FrameBuffer_len};

static PyTypeObject FrameBufferType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "biped_sim.recording._frames.FrameBuffer",
    .tp_doc = "The frames for the bag writer process (the compiled twin of frames.PyFrameBuffer).",
    .tp_basicsize = sizeof(FrameBuffer),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = FrameBuffer_new,
    .tp_init = (initproc)FrameBuffer_init,
    .tp_dealloc = (destructor)FrameBuffer_dealloc,
    .tp_methods = FrameBuffer_methods,
    .tp_getset = FrameBuffer_getset,
    .tp_as_sequence = &FrameBuffer_as_sequence,
};

/* ---- the writer process's side: M frames -> MCAP Message records -------------------------------------
 * The compiled twin of McapFileWriter.add_records' Python loop (frames.records, then add_message for
 * each): the same Message records in the chunk, the same (log time, offset) pairs in the message index,
 * the same sequence numbers. Why: that loop was about 1 us of the writer process's CPU a message, and the
 * writer working on the other vCPU is what slows a fast node run (docs/performance.md, "Recording"). */

static uint64_t get_u64(const unsigned char *p) {
    uint64_t v = 0;
    for (int i = 7; i >= 0; i--) v = (v << 8) | p[i];
    return v;
}

/* append_messages(payload, offset, chunk, chunk_size, message_index, channels, sequences) -> offset
 * Appends the records of the M frame ``payload`` from ``offset`` to the bytearray ``chunk`` as Message
 * records until the chunk holds more than ``chunk_size`` bytes or the payload ends; returns the offset
 * reached. ``channels``: {topic id: channel id}; ``sequences``: {topic id: last sequence number},
 * updated; ``message_index``: {channel id: bytearray of (log time, offset in the chunk) as <QQ pairs},
 * appended to (packed here, as the MessageIndex record holds them: no object a message). */
static PyObject *append_messages(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 7 || !PyBytes_Check(args[0]) || !PyByteArray_Check(args[2]) || !PyDict_Check(args[4])
        || !PyDict_Check(args[5]) || !PyDict_Check(args[6])) {
        PyErr_SetString(PyExc_TypeError, "append_messages(payload: bytes, offset, chunk: bytearray, chunk_size, "
                                         "message_index: dict, channels: dict, sequences: dict)");
        return NULL;
    }
    const unsigned char *p = (const unsigned char *)PyBytes_AS_STRING(args[0]);
    Py_ssize_t end = PyBytes_GET_SIZE(args[0]);
    Py_ssize_t off = PyLong_AsSsize_t(args[1]);
    if (off == -1 && PyErr_Occurred()) return NULL;
    Py_ssize_t chunk_size = PyLong_AsSsize_t(args[3]);
    if (chunk_size == -1 && PyErr_Occurred()) return NULL;
    PyObject *chunk = args[2], *index = args[4], *channels = args[5], *sequences = args[6];
    while (off < end) {
        if (end - off < RECORD_SIZE) goto cut_short;
        uint64_t t = get_u64(p + off);
        long topic = (long)p[off + 8] | ((long)p[off + 9] << 8);
        Py_ssize_t size = (Py_ssize_t)((uint32_t)p[off + 10] | ((uint32_t)p[off + 11] << 8)
                                       | ((uint32_t)p[off + 12] << 16) | ((uint32_t)p[off + 13] << 24));
        if (end - off - RECORD_SIZE < size) goto cut_short;
        PyObject *topic_id = PyLong_FromLong(topic);
        if (topic_id == NULL) return NULL;
        PyObject *cid_obj = PyDict_GetItemWithError(channels, topic_id);      /* borrowed */
        PyObject *last = cid_obj ? PyDict_GetItemWithError(sequences, topic_id) : NULL;
        if (last == NULL) {
            if (!PyErr_Occurred()) PyErr_SetObject(PyExc_KeyError, topic_id);
            Py_DECREF(topic_id);
            return NULL;
        }
        long cid = PyLong_AsLong(cid_obj);
        unsigned long long prev = PyLong_AsUnsignedLongLong(last);
        if ((cid == -1 || prev == (unsigned long long)-1) && PyErr_Occurred()) {
            Py_DECREF(topic_id);
            return NULL;
        }
        uint32_t seq = (uint32_t)(prev + 1);
        PyObject *seq_obj = PyLong_FromUnsignedLong(seq);
        int bad = seq_obj == NULL || PyDict_SetItem(sequences, topic_id, seq_obj) < 0;
        Py_XDECREF(seq_obj);
        Py_DECREF(topic_id);
        if (bad) return NULL;
        Py_ssize_t at = PyByteArray_GET_SIZE(chunk);
        PyObject *pairs = PyDict_GetItemWithError(index, cid_obj);       /* borrowed */
        if (pairs == NULL) {
            if (PyErr_Occurred()) return NULL;
            pairs = PyByteArray_FromStringAndSize(NULL, 0);
            if (pairs == NULL) return NULL;
            bad = PyDict_SetItem(index, cid_obj, pairs) < 0;
            Py_DECREF(pairs);                   /* the dict holds it */
            if (bad) return NULL;
        } else if (!PyByteArray_Check(pairs)) {
            PyErr_SetString(PyExc_TypeError, "message_index values must be bytearrays of (log time, offset) pairs");
            return NULL;
        }
        Py_ssize_t n_pairs = PyByteArray_GET_SIZE(pairs);
        if (PyByteArray_Resize(pairs, n_pairs + 16) < 0) return NULL;
        put_u64(PyByteArray_AS_STRING(pairs) + n_pairs, t);
        put_u64(PyByteArray_AS_STRING(pairs) + n_pairs + 8, (uint64_t)at);
        /* the Message record: opcode 0x05, record length, channel id, sequence, log time, publish time, data */
        if (PyByteArray_Resize(chunk, at + 9 + 22 + size) < 0) return NULL;
        char *q = PyByteArray_AS_STRING(chunk) + at;
        q[0] = 0x05;
        put_u64(q + 1, (uint64_t)(22 + size));
        put_u16(q + 9, (uint16_t)cid);
        put_u32(q + 11, seq);
        put_u64(q + 15, t);
        put_u64(q + 23, t);
        memcpy(q + 31, p + off + RECORD_SIZE, (size_t)size);
        off += RECORD_SIZE + size;
        if (PyByteArray_GET_SIZE(chunk) > chunk_size) break;
    }
    return PyLong_FromSsize_t(off);
cut_short:
    PyErr_SetString(PyExc_ValueError, "a message record cut short in an M frame");
    return NULL;
}

static PyMethodDef module_methods[] = {
    {"append_messages", (PyCFunction)(void (*)(void))append_messages, METH_FASTCALL,
     "append_messages(payload, offset, chunk, chunk_size, message_index, channels, sequences) -> offset"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef frames_module = {
    PyModuleDef_HEAD_INIT, "_frames", "The compiled twins of biped_sim.recording.frames.PyFrameBuffer and of "
    "McapFileWriter.add_records' loop.", -1, module_methods,
};

PyMODINIT_FUNC PyInit__frames(void) {
    if (PyType_Ready(&FrameBufferType) < 0) return NULL;
    PyObject *m = PyModule_Create(&frames_module);
    if (m == NULL) return NULL;
    Py_INCREF(&FrameBufferType);
    if (PyModule_AddObject(m, "FrameBuffer", (PyObject *)&FrameBufferType) < 0) {
        Py_DECREF(&FrameBufferType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
