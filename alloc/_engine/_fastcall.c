/* alloc._engine._fastcall: the allocator's call path in C.
 *
 * ``FastCall`` is the base type of ``alloc.Allocator``.  Its ``tp_call`` does, without a
 * Python frame, what ``Allocator._call_py`` does on its fast paths: check the demand (and
 * ``u_prev``, ``dt``) by type, shape, dtype and layout; call the method's one compiled kernel
 * (numba's entry for exactly those argument types, alloc.api._entry_point: the same compiled
 * code with the same arguments, so the same bits); mark its packed output
 * read-only and return the ``Result`` tuple of views into it.  Every other case -- another
 * argument form, an input the kernel does not vouch for (status code 2), no compiled kernel --
 * goes to ``self._call_py(*args, **kwargs)``, the Python implementation, which re-checks
 * and answers (or raises the named error).  Measured in benchmarks/bench_alloc.py.
 *
 * Packed output of a kernel (alloc._engine._kernels.packed_out): u (m), B u (k), v (k), v - B u (k).
 * The kernel returns (out, code, iterations); code 0 = exact, 1 = unattainable.
 *
 * Thread safety: each FastCall owns one re-entrant lock.  The C path holds it around a
 * kernel call whose path was set up as stateful (``lock_plain``/``lock_rate``: the kernel
 * mutates a cache or warm start); ``_acquire()``/``_release()`` give the Python path the same
 * lock, so the C and Python paths of one allocator exclude each other.
 *
 * The lock's state (owner, depth, waiters) is read and written only with the GIL held, so
 * the uncontended take and drop are a few plain loads and stores (a PyThread lock's
 * sem_trywait/sem_post pair measured 123 ns, a pthread mutex 33 ns; benchmarks/bench_lock.py).
 * A thread that finds the lock held by another waits on a condition variable with the GIL
 * released; the owner's drop bumps a generation count under the mutex and wakes the waiters,
 * which re-check with the GIL (no wake-up is lost: a waiter reads the generation with the
 * GIL before it releases it, and only a GIL holder can bump it).  No thread ever waits for
 * the GIL while holding the mutex.  The design needs the GIL: a free-threaded build (and
 * Windows, without pthreads) does not build this extension, and alloc then runs the Python
 * path with a threading.RLock.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <time.h>
#include <pthread.h>
#include <pythread.h>

#if defined(Py_GIL_DISABLED) || defined(_WIN32)
#error "alloc._engine._fastcall's lock relies on the GIL and pthreads; alloc runs its Python call path instead"
#endif

#define MAXARGS 40

typedef struct {
    PyObject_HEAD
    PyObject *kernel;  /* plain path: kernel(*pre, v, *post); NULL = none */
    PyObject *pre;
    PyObject *post;
    PyObject *rkernel; /* rate path: rkernel(*rpre, v, u_prev, dt); NULL = none */
    PyObject *rpre;
    PyObject *method;  /* Result.method */
    PyObject *status;  /* (Status.EXACT, Status.UNATTAINABLE) */
    PyObject *rtype;   /* the Result type (a tuple subclass) */
    Py_ssize_t k, m;
    double maxmag;
    int lock_plain, lock_rate; /* hold the lock around the plain / rate kernel */
    /* the lock (see the top of this file): owner, depth, waiters with the GIL held */
    unsigned long owner; /* thread holding the lock (valid while depth > 0) */
    long depth;          /* re-entry count of the owner; 0 = free */
    long waiters;        /* threads waiting for it */
    unsigned long gen;   /* bumped by each drop that finds waiters (under mutex, with the GIL) */
    int sync_ready;      /* mutex and cond initialised */
    pthread_mutex_t mutex;
    pthread_cond_t cond;
} FastCall;

/* Take the allocator's lock (re-entrant).  Called with the GIL held. */
static void lock_take(FastCall *self) {
    unsigned long me = PyThread_get_thread_ident();
    if (self->depth == 0) {
        self->owner = me;
        self->depth = 1;
        return;
    }
    if (self->owner == me) {
        self->depth++;
        return;
    }
    self->waiters++;
    while (self->depth != 0) {
        unsigned long seen = self->gen;
        Py_BEGIN_ALLOW_THREADS
        pthread_mutex_lock(&self->mutex);
        while (self->gen == seen)
            pthread_cond_wait(&self->cond, &self->mutex);
        pthread_mutex_unlock(&self->mutex);
        Py_END_ALLOW_THREADS
    }
    self->waiters--;
    self->owner = me;
    self->depth = 1;
}

/* Drop one level of the lock (the caller holds it).  Called with the GIL held. */
static void lock_drop(FastCall *self) {
    if (--self->depth == 0) {
        self->owner = 0;
        if (self->waiters > 0) {
            pthread_mutex_lock(&self->mutex);
            self->gen++;
            pthread_cond_broadcast(&self->cond);
            pthread_mutex_unlock(&self->mutex);
        }
    }
}

static PyObject *str_u_prev, *str_dt, *str_call_py, *str_empty;

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts); /* time.perf_counter's clock on Linux */
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int is_vector(PyObject *a, Py_ssize_t n) {
    if (!PyArray_CheckExact(a))
        return 0;
    PyArrayObject *x = (PyArrayObject *)a;
    /* the kernels are called through their entry for C-contiguous, aligned float64 vectors */
    return PyArray_NDIM(x) == 1 && PyArray_DIM(x, 0) == n && PyArray_TYPE(x) == NPY_DOUBLE &&
           PyArray_ISNOTSWAPPED(x) && PyArray_IS_C_CONTIGUOUS(x) && PyArray_ISALIGNED(x);
}

static PyObject *view(PyArrayObject *out, Py_ssize_t offset, Py_ssize_t len) {
    npy_intp dims[1] = {len};
    PyArray_Descr *d = PyArray_DESCR(out);
    Py_INCREF(d);
    /* flags 0 with given data: a read-only view, as out[a:b] of a read-only out */
    PyObject *a = PyArray_NewFromDescr(&PyArray_Type, d, 1, dims, NULL,
                                       (char *)PyArray_DATA(out) + offset * (Py_ssize_t)sizeof(double), 0, NULL);
    if (a == NULL)
        return NULL;
    Py_INCREF(out);
    if (PyArray_SetBaseObject((PyArrayObject *)a, (PyObject *)out) < 0) {
        Py_DECREF(a);
        return NULL;
    }
    return a;
}

static PyObject *slow(PyObject *self, PyObject *args, PyObject *kw) {
    PyObject *f = PyObject_GetAttr(self, str_call_py);
    if (f == NULL)
        return NULL;
    PyObject *r = PyObject_Call(f, args, kw);
    Py_DECREF(f);
    return r;
}

/* The Result of a kernel's answer, or NULL with no error set when the answer is not a fast one. */
static PyObject *finish(FastCall *self, PyObject *res, double t0) {
    double t = now() - t0;
    if (!PyTuple_CheckExact(res) || PyTuple_GET_SIZE(res) != 3)
        return NULL;
    PyObject *o = PyTuple_GET_ITEM(res, 0), *c = PyTuple_GET_ITEM(res, 1), *it = PyTuple_GET_ITEM(res, 2);
    if (!PyLong_CheckExact(c))
        return NULL;
    long code = PyLong_AsLong(c);
    if (code == -1 && PyErr_Occurred()) {
        PyErr_Clear();
        return NULL;
    }
    Py_ssize_t m = self->m, k = self->k;
    if (code < 0 || code > 1 || !is_vector(o, m + 3 * k) || !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)o))
        return NULL;
    PyArrayObject *out = (PyArrayObject *)o;
    PyArray_CLEARFLAGS(out, NPY_ARRAY_WRITEABLE);
    PyObject *items[9] = {NULL};
    items[0] = view(out, 0, m);         /* u */
    items[1] = view(out, m + k, k);     /* v */
    items[2] = view(out, m, k);         /* B u */
    items[3] = PyTuple_GET_ITEM(self->status, code);
    Py_INCREF(items[3]);
    items[4] = self->method;
    Py_INCREF(items[4]);
    items[5] = it;
    Py_INCREF(it);
    items[6] = PyFloat_FromDouble(t);
    items[7] = str_empty;
    Py_INCREF(str_empty);
    items[8] = view(out, m + 2 * k, k); /* v - B u */
    PyTypeObject *rt = (PyTypeObject *)self->rtype;
    PyObject *r = NULL;
    if (items[0] && items[1] && items[2] && items[6] && items[8])
        r = rt->tp_alloc(rt, 9);
    if (r == NULL) {
        for (int i = 0; i < 9; i++)
            Py_XDECREF(items[i]);
        if (!PyErr_Occurred())
            PyErr_NoMemory();
        return NULL;
    }
    for (int i = 0; i < 9; i++)
        PyTuple_SET_ITEM(r, i, items[i]);
    return r;
}

static PyObject *fc_call(PyObject *op, PyObject *args, PyObject *kw) {
    FastCall *self = (FastCall *)op;
    PyObject *up = NULL, *dt = NULL;
    if (PyTuple_GET_SIZE(args) != 1)
        return slow(op, args, kw);
    PyObject *v = PyTuple_GET_ITEM(args, 0);
    if (kw != NULL && PyDict_GET_SIZE(kw) > 0) {
        Py_ssize_t found = 0;
        up = PyDict_GetItemWithError(kw, str_u_prev);
        if (up != NULL)
            found++;
        else if (PyErr_Occurred())
            return NULL;
        dt = PyDict_GetItemWithError(kw, str_dt);
        if (dt != NULL)
            found++;
        else if (PyErr_Occurred())
            return NULL;
        if (found != PyDict_GET_SIZE(kw))
            return slow(op, args, kw);
        if (up == Py_None)
            up = NULL;
        if (dt == Py_None)
            dt = NULL;
    }
    if (!is_vector(v, self->k))
        return slow(op, args, kw);
    PyObject *argv[MAXARGS];
    Py_ssize_t n = 0;
    PyObject *kern;
    if (up == NULL && dt == NULL) {
        if (self->kernel == NULL)
            return slow(op, args, kw);
        kern = self->kernel;
        for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(self->pre); i++)
            argv[n++] = PyTuple_GET_ITEM(self->pre, i);
        argv[n++] = v;
        for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(self->post); i++)
            argv[n++] = PyTuple_GET_ITEM(self->post, i);
    } else {
        if (self->rkernel == NULL || up == NULL || dt == NULL || !PyFloat_CheckExact(dt) || !is_vector(up, self->m))
            return slow(op, args, kw);
        double d = PyFloat_AS_DOUBLE(dt);
        if (!(d > 0.0 && d <= self->maxmag))
            return slow(op, args, kw);
        kern = self->rkernel;
        for (Py_ssize_t i = 0; i < PyTuple_GET_SIZE(self->rpre); i++)
            argv[n++] = PyTuple_GET_ITEM(self->rpre, i);
        argv[n++] = v;
        argv[n++] = up;
        argv[n++] = dt;
    }
    int locked = (up == NULL) ? self->lock_plain : self->lock_rate;
    if (locked)
        lock_take(self);
    double t0 = now();
    PyObject *res = PyObject_Vectorcall(kern, argv, n, NULL);
    if (locked)
        lock_drop(self);
    if (res == NULL)
        return NULL; /* the kernel raised: as on the Python path */
    PyObject *r = finish(self, res, t0);
    Py_DECREF(res);
    if (r != NULL || PyErr_Occurred())
        return r;
    return slow(op, args, kw); /* not a fast answer: the Python path decides */
}

static int check_tuple(PyObject *t, const char *name) {
    if (!PyTuple_Check(t)) {
        PyErr_Format(PyExc_TypeError, "_fast_setup: %s must be a tuple", name);
        return -1;
    }
    return 0;
}

static PyObject *fc_setup(PyObject *op, PyObject *args) {
    FastCall *self = (FastCall *)op;
    PyObject *kernel, *pre, *post, *rkernel, *rpre, *method, *status, *rtype;
    Py_ssize_t k, m;
    double maxmag;
    int lock_plain = 1, lock_rate = 1;
    if (!PyArg_ParseTuple(args, "OOOOOOOOnnd|pp:_fast_setup", &kernel, &pre, &post, &rkernel, &rpre, &method,
                          &status, &rtype, &k, &m, &maxmag, &lock_plain, &lock_rate))
        return NULL;
    if (check_tuple(pre, "pre") || check_tuple(post, "post") || check_tuple(rpre, "rpre") ||
        check_tuple(status, "status"))
        return NULL;
    if (PyTuple_GET_SIZE(status) != 2 || !PyType_Check(rtype) ||
        !PyType_IsSubtype((PyTypeObject *)rtype, &PyTuple_Type) || k < 1 || m < 1) {
        PyErr_SetString(PyExc_ValueError, "_fast_setup: bad status, result type or sizes");
        return NULL;
    }
    if (PyTuple_GET_SIZE(pre) + 1 + PyTuple_GET_SIZE(post) > MAXARGS || PyTuple_GET_SIZE(rpre) + 3 > MAXARGS) {
        PyErr_SetString(PyExc_ValueError, "_fast_setup: too many kernel arguments");
        return NULL;
    }
#define SET(field, value)                      \
    do {                                       \
        PyObject *tmp_ = self->field;          \
        self->field = (value);                 \
        Py_XINCREF(self->field);               \
        Py_XDECREF(tmp_);                      \
    } while (0)
    SET(kernel, kernel == Py_None ? NULL : kernel);
    SET(pre, pre);
    SET(post, post);
    SET(rkernel, rkernel == Py_None ? NULL : rkernel);
    SET(rpre, rpre);
    SET(method, method);
    SET(status, status);
    SET(rtype, rtype);
#undef SET
    self->k = k;
    self->m = m;
    self->maxmag = maxmag;
    self->lock_plain = lock_plain;
    self->lock_rate = lock_rate;
    Py_RETURN_NONE;
}

static PyObject *fc_acquire(PyObject *op, PyObject *Py_UNUSED(ignored)) {
    lock_take((FastCall *)op);
    Py_RETURN_NONE;
}

static PyObject *fc_release(PyObject *op, PyObject *Py_UNUSED(ignored)) {
    FastCall *self = (FastCall *)op;
    if (self->depth <= 0 || self->owner != PyThread_get_thread_ident()) {
        PyErr_SetString(PyExc_RuntimeError, "_release: the allocator's lock is not held by this thread");
        return NULL;
    }
    lock_drop(self);
    Py_RETURN_NONE;
}

static PyObject *fc_new(PyTypeObject *type, PyObject *args, PyObject *kw) {
    PyObject *op = PyType_GenericNew(type, args, kw);
    if (op == NULL)
        return NULL;
    FastCall *self = (FastCall *)op;
    self->lock_plain = self->lock_rate = 1;
    if (pthread_mutex_init(&self->mutex, NULL) != 0) {
        Py_DECREF(op);
        return PyErr_NoMemory();
    }
    if (pthread_cond_init(&self->cond, NULL) != 0) {
        pthread_mutex_destroy(&self->mutex);
        Py_DECREF(op);
        return PyErr_NoMemory();
    }
    self->sync_ready = 1;
    return op;
}

static int fc_traverse(PyObject *op, visitproc visit, void *arg) {
    FastCall *self = (FastCall *)op;
    Py_VISIT(self->kernel);
    Py_VISIT(self->pre);
    Py_VISIT(self->post);
    Py_VISIT(self->rkernel);
    Py_VISIT(self->rpre);
    Py_VISIT(self->method);
    Py_VISIT(self->status);
    Py_VISIT(self->rtype);
    return 0;
}

static int fc_clear(PyObject *op) {
    FastCall *self = (FastCall *)op;
    Py_CLEAR(self->kernel);
    Py_CLEAR(self->pre);
    Py_CLEAR(self->post);
    Py_CLEAR(self->rkernel);
    Py_CLEAR(self->rpre);
    Py_CLEAR(self->method);
    Py_CLEAR(self->status);
    Py_CLEAR(self->rtype);
    return 0;
}

static void fc_dealloc(PyObject *op) {
    PyObject_GC_UnTrack(op);
    fc_clear(op);
    FastCall *self = (FastCall *)op;
    if (self->sync_ready) {
        pthread_cond_destroy(&self->cond);
        pthread_mutex_destroy(&self->mutex);
        self->sync_ready = 0;
    }
    Py_TYPE(op)->tp_free(op);
}

static PyMethodDef fc_methods[] = {
    {"_fast_setup", fc_setup, METH_VARARGS,
     "_fast_setup(kernel, pre, post, rate_kernel, rate_pre, method, status, result_type, k, m, max_magnitude): "
     "the compiled kernels the C call path calls (None: that path goes to _call_py).  Optional "
     "lock_plain, lock_rate (default True): hold the allocator's lock around that kernel."},
    {"_acquire", fc_acquire, METH_NOARGS, "Take the allocator's lock (re-entrant; blocks without the GIL)."},
    {"_release", fc_release, METH_NOARGS, "Release the allocator's lock (RuntimeError if this thread does not hold it)."},
    {NULL, NULL, 0, NULL}};

static PyTypeObject FastCallType = {
    PyVarObject_HEAD_INIT(NULL, 0).tp_name = "alloc._engine._fastcall.FastCall",
    .tp_basicsize = sizeof(FastCall),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_BASETYPE | Py_TPFLAGS_HAVE_GC,
    .tp_doc = "Base of alloc.Allocator: its call path in C (see alloc/_engine/_fastcall.c).",
    .tp_call = fc_call,
    .tp_traverse = fc_traverse,
    .tp_clear = fc_clear,
    .tp_dealloc = fc_dealloc,
    .tp_methods = fc_methods,
    .tp_new = fc_new,
};

static struct PyModuleDef moduledef = {PyModuleDef_HEAD_INIT, "alloc._engine._fastcall",
                                       "The allocator's call path in C (see alloc/api.py).", -1, NULL};

PyMODINIT_FUNC PyInit__fastcall(void) {
    import_array();
    if (PyType_Ready(&FastCallType) < 0)
        return NULL;
    str_u_prev = PyUnicode_InternFromString("u_prev");
    str_dt = PyUnicode_InternFromString("dt");
    str_call_py = PyUnicode_InternFromString("_call_py");
    str_empty = PyUnicode_InternFromString("");
    if (!str_u_prev || !str_dt || !str_call_py || !str_empty)
        return NULL;
    PyObject *mod = PyModule_Create(&moduledef);
    if (mod == NULL)
        return NULL;
    Py_INCREF(&FastCallType);
    if (PyModule_AddObject(mod, "FastCall", (PyObject *)&FastCallType) < 0) {
        Py_DECREF(&FastCallType);
        Py_DECREF(mod);
        return NULL;
    }
    return mod;
}
