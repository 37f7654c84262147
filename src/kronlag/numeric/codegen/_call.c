/* kronlag.numeric.codegen._call: the fixed call layer between Python and the generated C kernels.
 *
 * Built once when kronlag is installed (setup.py, an optional extension); kronlag falls back to
 * ctypes when it is missing.  The generated libraries are loaded with ctypes; this module calls
 * their functions through their addresses, reading NumPy float64 vectors in place (any other
 * sequence is converted; a wrong shape is an InputError) and returning new arrays.  Every call uses
 * its own buffers, so calls from several threads are safe.
 *
 *   evaluate(spec, t, q, qd, p) -> array
 *       spec = (address, m, n_parameters, rows, cols): the kernel
 *       void f(double t, const double *q, const double *qd, const double *p, double *out)
 *       writing rows * cols doubles; the result has shape (rows, cols), or (rows,) when cols < 0.
 *       qd may be None (zeros).
 *   ForwardDynamics(address, m, r, s, n_parameters, result_type)(t, q, qd, p, alpha, beta)
 *       -> result_type(qdd, lam, mu, unique_multipliers, rank), or the rank alone when it is < 0
 *       (-1 singular, -2 the joints' friction did not converge).  address:
 *       int f(const double *in, double *out) with in = [t, alpha, beta, q, qd, p],
 *       out = [qdd, lam, mu], returning the rank of [Phi_q; A] or a failure (< 0).  One object per
 *       library, called with the vectorcall protocol: no argument tuple, no per-call set-up.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <structmember.h>
#include <string.h>

typedef void (*kronlag_kernel)(double t, const double *q, const double *qd, const double *p, double *out);
typedef int (*kronlag_packed)(const double *in, double *out);

/* kronlag.core.errors.InputError (a ValueError), raised on input of the wrong shape. */
static PyObject *input_error;

/* Inputs up to this many doubles live on the stack. */
#define STACK_DOUBLES 512

/* A float64 vector of length n: the data of `object` when it already is one (`*owner` NULL),
 * else of a converted copy owned through `*owner`.  NULL with an exception on error. */
static const double *read_vector(PyObject *object, Py_ssize_t n, const char *name, PyObject **owner)
{
    *owner = NULL;
    if (PyArray_CheckExact(object)) {
        PyArrayObject *array = (PyArrayObject *)object;
        if (PyArray_TYPE(array) == NPY_DOUBLE && PyArray_NDIM(array) == 1 && PyArray_DIM(array, 0) == n
            && PyArray_IS_C_CONTIGUOUS(array) && PyArray_ISALIGNED(array))
            return (const double *)PyArray_DATA(array);
    }
    PyArrayObject *array = (PyArrayObject *)PyArray_FROMANY(object, NPY_DOUBLE, 0, 0, NPY_ARRAY_IN_ARRAY);
    if (!array) return NULL;
    if (PyArray_NDIM(array) != 1 || PyArray_DIM(array, 0) != n) {
        PyObject *shape = PyObject_GetAttrString((PyObject *)array, "shape");
        PyErr_Format(input_error, "%s must have shape (%zd,), got %R", name, n, shape);
        Py_XDECREF(shape);
        Py_DECREF(array);
        return NULL;
    }
    *owner = (PyObject *)array;
    return (const double *)PyArray_DATA(array);
}

static int read_spec(PyObject *spec, Py_ssize_t size, Py_ssize_t *values, void **address)
{
    if (!PyTuple_Check(spec) || PyTuple_GET_SIZE(spec) != size) {
        PyErr_SetString(PyExc_TypeError, "spec must be the tuple made by kronlag.codegen");
        return -1;
    }
    *address = PyLong_AsVoidPtr(PyTuple_GET_ITEM(spec, 0));
    for (Py_ssize_t i = 1; i < size; ++i) values[i] = PyLong_AsSsize_t(PyTuple_GET_ITEM(spec, i));
    return PyErr_Occurred() ? -1 : 0;
}

static PyObject *evaluate(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_ssize_t spec[5];
    void *address;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "evaluate(spec, t, q, qd, p)");
        return NULL;
    }
    if (read_spec(args[0], 5, spec, &address)) return NULL;
    Py_ssize_t m = spec[1], n_parameters = spec[2], rows = spec[3], cols = spec[4];
    double t = PyFloat_AsDouble(args[1]);
    if (t == -1.0 && PyErr_Occurred()) return NULL;
    PyObject *owners[3] = {NULL, NULL, NULL};
    PyObject *result = NULL;
    double zeros[STACK_DOUBLES];
    double *allocated = NULL;
    const double *q = read_vector(args[2], m, "q", &owners[0]);
    if (!q) goto done;
    const double *qd;
    if (args[3] == Py_None) {
        qd = zeros;
        if (m > STACK_DOUBLES) {
            qd = allocated = PyMem_Calloc(m, sizeof(double));
            if (!allocated) { PyErr_NoMemory(); goto done; }
        } else {
            memset(zeros, 0, m * sizeof(double));
        }
    } else if (!(qd = read_vector(args[3], m, "qd", &owners[1]))) {
        goto done;
    }
    const double *p = read_vector(args[4], n_parameters, "p", &owners[2]);
    if (!p) goto done;
    npy_intp shape[2] = {rows, cols};
    result = PyArray_SimpleNew(cols < 0 ? 1 : 2, shape, NPY_DOUBLE);
    if (result) ((kronlag_kernel)address)(t, q, qd, p, (double *)PyArray_DATA((PyArrayObject *)result));
done:
    PyMem_Free(allocated);
    for (int i = 0; i < 3; ++i) Py_XDECREF(owners[i]);
    return result;
}

/* The forward dynamics of one library, called with the vectorcall protocol: the library's entry, its
 * dimensions and the result type (a class with __slots__ qdd, lam, mu, unique_multipliers, rank, whose
 * __init__ only stores them: its instances are filled here, in place). */
typedef struct {
    PyObject_HEAD
    vectorcallfunc vectorcall;
    kronlag_packed function;
    Py_ssize_t m, r, s, n_parameters;
    PyTypeObject *result_type;
    Py_ssize_t offsets[5]; /* of the result's slots, in the order of RESULT_FIELDS */
} ForwardDynamics;

static const char *RESULT_FIELDS[5] = {"qdd", "lam", "mu", "unique_multipliers", "rank"};

static PyObject *forward_dynamics_call(PyObject *callable, PyObject *const *args, size_t nargsf, PyObject *kwnames)
{
    ForwardDynamics *self = (ForwardDynamics *)callable;
    if (PyVectorcall_NARGS(nargsf) != 6 || (kwnames && PyTuple_GET_SIZE(kwnames))) {
        PyErr_SetString(PyExc_TypeError, "forward_dynamics(t, q, qd, p, alpha, beta)");
        return NULL;
    }
    Py_ssize_t m = self->m, r = self->r, s = self->s, n_parameters = self->n_parameters;
    double t = PyFloat_AsDouble(args[0]), alpha = PyFloat_AsDouble(args[4]), beta = PyFloat_AsDouble(args[5]);
    if (PyErr_Occurred()) return NULL;
    Py_ssize_t n_in = 3 + 2 * m + n_parameters, n_out = m + r + s + 1;
    double stack[STACK_DOUBLES];
    double *buffer = n_in + n_out <= STACK_DOUBLES ? stack : PyMem_Malloc((n_in + n_out) * sizeof(double));
    if (!buffer) return PyErr_NoMemory();
    double *in = buffer, *out = buffer + n_in;
    PyObject *result = NULL, *owner = NULL;
    const char *names[3] = {"q", "qd", "p"};
    Py_ssize_t offsets[3] = {3, 3 + m, 3 + 2 * m}, lengths[3] = {m, m, n_parameters};
    for (int i = 0; i < 3; ++i) {
        const double *data = read_vector(args[1 + i], lengths[i], names[i], &owner);
        if (!data) goto done;
        memcpy(in + offsets[i], data, lengths[i] * sizeof(double));
        Py_CLEAR(owner);
    }
    in[0] = t;
    in[1] = alpha;
    in[2] = beta;
    int rank = self->function(in, out);
    if (rank < 0) {
        result = PyLong_FromLong(rank);
        goto done;
    }
    PyObject *items[5] = {NULL, NULL, NULL, PyBool_FromLong(rank == r + s), PyLong_FromLong(rank)};
    npy_intp sizes[3] = {m, r, s};
    double *starts[3] = {out, out + m, out + m + r};
    for (int i = 0; i < 3; ++i) {
        items[i] = PyArray_SimpleNew(1, &sizes[i], NPY_DOUBLE);
        if (items[i]) memcpy(PyArray_DATA((PyArrayObject *)items[i]), starts[i], sizes[i] * sizeof(double));
    }
    if (items[0] && items[1] && items[2] && items[4])
        result = self->result_type->tp_alloc(self->result_type, 0);
    for (int i = 0; i < 5; ++i) {
        if (result) *(PyObject **)((char *)result + self->offsets[i]) = items[i]; /* the reference moves */
        else Py_XDECREF(items[i]);
    }
done:
    if (buffer != stack) PyMem_Free(buffer);
    return result;
}

/* ForwardDynamics(address, m, r, s, n_parameters, result_type) */
static PyObject *forward_dynamics_new(PyTypeObject *type, PyObject *args, PyObject *kwargs)
{
    PyObject *address;
    Py_ssize_t m, r, s, n_parameters;
    PyTypeObject *result_type;
    if (kwargs && PyDict_GET_SIZE(kwargs)) {
        PyErr_SetString(PyExc_TypeError, "ForwardDynamics takes positional arguments only");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "OnnnnO!", &address, &m, &r, &s, &n_parameters, &PyType_Type, &result_type))
        return NULL;
    Py_ssize_t offsets[5];
    for (int i = 0; i < 5; ++i) {
        PyObject *descriptor = PyObject_GetAttrString((PyObject *)result_type, RESULT_FIELDS[i]);
        if (!descriptor) {
            if (!PyErr_ExceptionMatches(PyExc_AttributeError)) return NULL;
            PyErr_Clear();
            descriptor = Py_NewRef(Py_None);
        }
        int slot = Py_IS_TYPE(descriptor, &PyMemberDescr_Type)
                   && ((PyMemberDescrObject *)descriptor)->d_member->type == T_OBJECT_EX
                   && !(((PyMemberDescrObject *)descriptor)->d_member->flags & READONLY);
        if (slot) offsets[i] = ((PyMemberDescrObject *)descriptor)->d_member->offset;
        Py_DECREF(descriptor);
        if (!slot) {
            PyErr_Format(PyExc_TypeError, "%s.%s must be a slot", result_type->tp_name, RESULT_FIELDS[i]);
            return NULL;
        }
    }
    void *function = PyLong_AsVoidPtr(address);
    if (!function) {
        if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "the address of the forward dynamics is NULL");
        return NULL;
    }
    ForwardDynamics *self = (ForwardDynamics *)type->tp_alloc(type, 0);
    if (!self) return NULL;
    self->vectorcall = forward_dynamics_call;
    self->function = (kronlag_packed)function;
    self->m = m;
    self->r = r;
    self->s = s;
    self->n_parameters = n_parameters;
    self->result_type = (PyTypeObject *)Py_NewRef(result_type);
    memcpy(self->offsets, offsets, sizeof offsets);
    return (PyObject *)self;
}

static void forward_dynamics_dealloc(PyObject *object)
{
    Py_XDECREF(((ForwardDynamics *)object)->result_type);
    Py_TYPE(object)->tp_free(object);
}

static PyTypeObject ForwardDynamicsType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "kronlag.numeric.codegen._call.ForwardDynamics",
    .tp_doc = "ForwardDynamics(address, m, r, s, n_parameters, result_type)(t, q, qd, p, alpha, beta)\n"
              "-> result_type(qdd, lam, mu, unique_multipliers, rank), or the rank (< 0) on failure",
    .tp_basicsize = sizeof(ForwardDynamics),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_VECTORCALL,
    .tp_vectorcall_offset = offsetof(ForwardDynamics, vectorcall),
    .tp_call = PyVectorcall_Call,
    .tp_new = forward_dynamics_new,
    .tp_dealloc = forward_dynamics_dealloc,
};

static PyMethodDef methods[] = {
    {"evaluate", (PyCFunction)(void (*)(void))evaluate, METH_FASTCALL, "evaluate(spec, t, q, qd, p) -> array"},
    {NULL, NULL, 0, NULL}
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "kronlag.numeric.codegen._call",
                                    "The fixed call layer of kronlag's generated C kernels.", -1, methods};

PyMODINIT_FUNC PyInit__call(void)
{
    import_array();
    PyObject *errors = PyImport_ImportModule("kronlag.core.errors");
    if (!errors) return NULL;
    input_error = PyObject_GetAttrString(errors, "InputError");
    Py_DECREF(errors);
    if (!input_error) return NULL;
    if (PyType_Ready(&ForwardDynamicsType) < 0) return NULL;
    PyObject *created = PyModule_Create(&module);
    if (created && PyModule_AddObjectRef(created, "ForwardDynamics", (PyObject *)&ForwardDynamicsType) < 0)
        Py_CLEAR(created);
    return created;
}
