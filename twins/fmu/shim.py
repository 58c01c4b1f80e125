"""A loader binary for the FMU, so that a host that is not a Python program can run it.

pythonfmu's wrapper binary (``binaries/linux64/<model>.so``) expects the Python C API to be in the process
already: a C host that is not linked with libpython cannot even load it (``undefined symbol:
_Py_NoneStruct``). On Linux x86-64, when ``gcc`` is available at export time, the export therefore ships a
small loader in its place and the wrapper beside it as ``<model>.pythonfmu.so``. On the first FMI call the
loader

1. loads libpython with ``RTLD_GLOBAL`` unless the process already has the Python C API (a Python host, or
   a C host linked with libpython): the path is ``$PIEZOTWIN_LIBPYTHON`` if set, else the exporting
   interpreter's shared library (``sysconfig``), else its soname through the ordinary library search;
2. loads the wrapper from its own folder, which then starts the interpreter as in any C host;
3. forwards every ``fmi2*`` function to the wrapper (one indirect call each).

**The per-sample calls in C.** Each instance the loader hands out is a block of its own (``Inst``) in front of
the wrapper's. A slave of this project attaches to it at instantiation (:mod:`twins.fmu.native`) and then keeps
its input ``u`` (value reference 0) and output ``y`` (1) there, so ``fmi2SetReal(u)`` and ``fmi2GetReal(y)`` are
answered in C. A slave whose core has a native step (a C function ``y = f(ctx, u)``, the cantilever's kernel
without measurement noise) arms it, and ``fmi2DoStep`` of that communication step with a finite ``u`` runs it
without entering Python. Every other call goes to the wrapper and disarms the native step first (a parameter
change, a reset, another step size: the slave's Python step handles it and arms again). A slave that does not
attach (an older copy of the project in the process) gets every call, as before. Besides the FMI functions the
loader exports ``piezotwin_instance`` (the block whose call is being forwarded).

Without ``gcc``, a shared libpython or on another platform the wrapper is shipped as before and a warning says
that a C host must then preload libpython.
"""

from __future__ import annotations

import logging
import platform
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from pathlib import Path

__all__ = ["SHIM_SOURCE", "WRAPPED_SUFFIX", "build_shim", "libpython", "with_loader"]

_LOG = logging.getLogger(__name__)

#: file name suffix of pythonfmu's wrapper when the loader takes its place
WRAPPED_SUFFIX = ".pythonfmu.so"

#: C source of the loader; the export prepends the three ``#define``s (libpython path, soname, wrapper file)
SHIM_SOURCE = r"""
#define _GNU_SOURCE /* dladdr */
#include <dlfcn.h>
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define API __attribute__((visibility("default")))

typedef void *C;
typedef unsigned int VR;
typedef int S; /* fmi2Status: fmi2OK 0, fmi2Error 3 */
typedef void (*Logger)(void *, const char *, int, const char *, const char *, ...);
typedef struct { Logger logger; void *alloc, *free, *step_finished, *env; } Callbacks;

#define SPECIAL_FUNCTIONS(X) \
  X(const char *, fmi2GetTypesPlatform, (void), ()) \
  X(const char *, fmi2GetVersion, (void), ()) \
  X(C, fmi2Instantiate, (const char *name, int type, const char *guid, const char *res, const Callbacks *cb, \
                         int visible, int logging), (name, type, guid, res, cb, visible, logging)) \
  X(void, fmi2FreeInstance, (C c), (c))

/* every other FMI 2.0 function returns an fmi2Status: forwarded, or fmi2Error (3) if the wrapper is not loaded;
   these as they are, OWN_FUNCTIONS through a definition of their own below (u, y and the native step) */
#define PLAIN_FUNCTIONS(X) \
  X(S, fmi2SetDebugLogging, (C c, int on, size_t n, const char *const cat[]), (c, on, n, cat)) \
  X(S, fmi2SetupExperiment, (C c, int tol_on, double tol, double t0, int stop_on, double t1), \
    (c, tol_on, tol, t0, stop_on, t1)) \
  X(S, fmi2EnterInitializationMode, (C c), (c)) \
  X(S, fmi2ExitInitializationMode, (C c), (c)) \
  X(S, fmi2Terminate, (C c), (c)) \
  X(S, fmi2GetInteger, (C c, const VR vr[], size_t n, int v[]), (c, vr, n, v)) \
  X(S, fmi2GetBoolean, (C c, const VR vr[], size_t n, int v[]), (c, vr, n, v)) \
  X(S, fmi2GetString, (C c, const VR vr[], size_t n, const char *v[]), (c, vr, n, v)) \
  X(S, fmi2SetInteger, (C c, const VR vr[], size_t n, const int v[]), (c, vr, n, v)) \
  X(S, fmi2SetBoolean, (C c, const VR vr[], size_t n, const int v[]), (c, vr, n, v)) \
  X(S, fmi2SetString, (C c, const VR vr[], size_t n, const char *const v[]), (c, vr, n, v)) \
  X(S, fmi2GetFMUstate, (C c, void **st), (c, st)) \
  X(S, fmi2SetFMUstate, (C c, void *st), (c, st)) \
  X(S, fmi2FreeFMUstate, (C c, void **st), (c, st)) \
  X(S, fmi2SerializedFMUstateSize, (C c, void *st, size_t *n), (c, st, n)) \
  X(S, fmi2SerializeFMUstate, (C c, void *st, char b[], size_t n), (c, st, b, n)) \
  X(S, fmi2DeSerializeFMUstate, (C c, const char b[], size_t n, void **st), (c, b, n, st)) \
  X(S, fmi2GetDirectionalDerivative, (C c, const VR u[], size_t nu, const VR z[], size_t nz, const double dv[], \
                                      double dz[]), (c, u, nu, z, nz, dv, dz)) \
  X(S, fmi2SetRealInputDerivatives, (C c, const VR vr[], size_t n, const int o[], const double v[]), \
    (c, vr, n, o, v)) \
  X(S, fmi2GetRealOutputDerivatives, (C c, const VR vr[], size_t n, const int o[], double v[]), (c, vr, n, o, v)) \
  X(S, fmi2CancelStep, (C c), (c)) \
  X(S, fmi2GetStatus, (C c, int kind, int *v), (c, kind, v)) \
  X(S, fmi2GetIntegerStatus, (C c, int kind, int *v), (c, kind, v)) \
  X(S, fmi2GetBooleanStatus, (C c, int kind, int *v), (c, kind, v)) \
  X(S, fmi2GetStringStatus, (C c, int kind, const char **v), (c, kind, v))
#define OWN_FUNCTIONS(X) \
  X(S, fmi2Reset, (C c), (c)) \
  X(S, fmi2GetReal, (C c, const VR vr[], size_t n, double v[]), (c, vr, n, v)) \
  X(S, fmi2SetReal, (C c, const VR vr[], size_t n, const double v[]), (c, vr, n, v)) \
  X(S, fmi2DoStep, (C c, double t, double h, int no_prior), (c, t, h, no_prior)) \
  X(S, fmi2GetRealStatus, (C c, int kind, double *v), (c, kind, v))
#define STATUS_FUNCTIONS(X) PLAIN_FUNCTIONS(X) OWN_FUNCTIONS(X)

/* The instance handed to the host: u and y kept here once the slave attaches (twins.fmu.native._Block has the
   same layout), and an armed native step that does one sample of the communication step h without Python. */
typedef double (*NativeStep)(void *ctx, double u);
typedef struct {
    unsigned magic; /* INST_MAGIC */
    int attached;   /* the slave keeps u and y here */
    double u, y;    /* input (value reference 0) and output (1) */
    double h;       /* the communication step the native step stands for */
    NativeStep step; /* NULL: not armed */
    void *ctx;
    double last_time; /* end of the last step done here (fmi2LastSuccessfulTime) */
    int stepped_here; /* the last step was done here */
    int pad;
    C inner; /* the wrapper's instance */
} Inst;
#define INST_MAGIC 0x50545731u
#define VR_U 0u
#define VR_Y 1u

/* the instance whose call is being forwarded: a slave created in that call attaches to it */
static __thread Inst *current;
API void *piezotwin_instance(void) { return current; }

#define POINTER(ret, name, params, args) static ret(*p_##name) params;
SPECIAL_FUNCTIONS(POINTER)
STATUS_FUNCTIONS(POINTER)

static pthread_once_t once = PTHREAD_ONCE_INIT;
static int ready;
static char problem[2048];

static int load_libpython(void) {
    if (dlsym(RTLD_DEFAULT, "Py_IsInitialized")) return 1; /* the process has the Python C API already */
    const char *env = getenv("PIEZOTWIN_LIBPYTHON");
    const char *paths[] = {env, LIBPYTHON, LIBPYTHON_SONAME};
    for (size_t i = 0; i < sizeof paths / sizeof *paths; i++) {
        if (paths[i] && *paths[i] && dlopen(paths[i], RTLD_NOW | RTLD_GLOBAL)) return 1;
    }
    snprintf(problem, sizeof problem, "cannot load libpython (%s, %s; set PIEZOTWIN_LIBPYTHON): %s",
             LIBPYTHON, LIBPYTHON_SONAME, dlerror());
    return 0;
}

static void load(void) {
    if (!load_libpython()) return;
    Dl_info self;
    if (!dladdr((void *)&load, &self) || !self.dli_fname) {
        snprintf(problem, sizeof problem, "cannot locate the FMU binary's folder");
        return;
    }
    char path[4096];
    const char *slash = strrchr(self.dli_fname, '/');
    int dir = slash ? (int)(slash - self.dli_fname + 1) : 0;
    snprintf(path, sizeof path, "%.*s%s", dir, self.dli_fname, WRAPPED);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        snprintf(problem, sizeof problem, "cannot load %s: %s", path, dlerror());
        return;
    }
#define RESOLVE(ret, name, params, args) \
    if (!(*(void **)&p_##name = dlsym(lib, #name))) { \
        snprintf(problem, sizeof problem, "%s has no %s", path, #name); \
        return; \
    }
    SPECIAL_FUNCTIONS(RESOLVE)
    STATUS_FUNCTIONS(RESOLVE)
    ready = 1;
}

static int loaded(void) {
    pthread_once(&once, load);
    return ready;
}

API const char *fmi2GetTypesPlatform(void) { return loaded() ? p_fmi2GetTypesPlatform() : "default"; }
API const char *fmi2GetVersion(void) { return loaded() ? p_fmi2GetVersion() : "2.0"; }

API C fmi2Instantiate(const char *name, int type, const char *guid, const char *res, const Callbacks *cb,
                      int visible, int logging) {
    if (!loaded()) {
        if (cb && cb->logger) cb->logger(cb->env, name, 3, "logStatusError", "%s", problem);
        else fprintf(stderr, "%s\n", problem);
        return NULL;
    }
    Inst *in = calloc(1, sizeof *in);
    if (!in) return NULL;
    in->magic = INST_MAGIC;
    current = in;
    in->inner = p_fmi2Instantiate(name, type, guid, res, cb, visible, logging);
    current = NULL;
    if (!in->inner) {
        free(in);
        return NULL;
    }
    return in;
}

API void fmi2FreeInstance(C c) {
    Inst *in = c;
    if (!in) return;
    in->step = NULL;
    current = in;
    if (loaded()) p_fmi2FreeInstance(in->inner);
    current = NULL;
    free(in);
}

/* a call for the wrapper: the native step disarmed (the slave arms it again), the instance current */
#define FORWARD(ret, name, params, args) \
    static S forward_##name params { \
        Inst *in = c; \
        if (!in || !loaded()) return 3; \
        in->step = NULL; \
        in->stepped_here = 0; \
        c = in->inner; \
        current = in; \
        S s = p_##name args; \
        current = NULL; \
        return s; \
    }
STATUS_FUNCTIONS(FORWARD)

#define PLAIN(ret, name, params, args) \
    API ret name params { return forward_##name args; }
PLAIN_FUNCTIONS(PLAIN)

API S fmi2Reset(C c) {
    Inst *in = c;
    if (in) in->attached = 0; /* the wrapper makes a new slave, which attaches again */
    return forward_fmi2Reset(c);
}

API S fmi2SetReal(C c, const VR vr[], size_t n, const double v[]) {
    Inst *in = c;
    if (!in || !in->attached) return forward_fmi2SetReal(c, vr, n, v);
    if (n == 1 && vr[0] == VR_U) {
        in->u = v[0];
        return 0;
    }
    S worst = 0;
    for (size_t i = 0; i < n; i++) {
        S s = 0;
        if (vr[i] == VR_U) in->u = v[i];
        else s = forward_fmi2SetReal(c, vr + i, 1, v + i);
        if (s > worst) worst = s;
    }
    return worst;
}

API S fmi2GetReal(C c, const VR vr[], size_t n, double v[]) {
    Inst *in = c;
    if (!in || !in->attached) return forward_fmi2GetReal(c, vr, n, v);
    S worst = 0;
    for (size_t i = 0; i < n; i++) {
        S s = 0;
        if (vr[i] == VR_Y) v[i] = in->y;
        else if (vr[i] == VR_U) v[i] = in->u;
        else {
            NativeStep armed = in->step; /* a read leaves the native step armed */
            s = forward_fmi2GetReal(c, vr + i, 1, v + i);
            in->step = armed;
        }
        if (s > worst) worst = s;
    }
    return worst;
}

API S fmi2DoStep(C c, double t, double h, int no_prior) {
    Inst *in = c;
    if (in && in->step && h == in->h && isfinite(in->u)) {
        in->y = in->step(in->ctx, in->u);
        in->last_time = t + h;
        in->stepped_here = 1;
        return 0;
    }
    return forward_fmi2DoStep(c, t, h, no_prior);
}

API S fmi2GetRealStatus(C c, int kind, double *v) {
    Inst *in = c;
    if (in && in->stepped_here && kind == 2 /* fmi2LastSuccessfulTime */) {
        *v = in->last_time;
        return 0;
    }
    return forward_fmi2GetRealStatus(c, kind, v);
}
"""


def libpython() -> tuple[str, str] | None:
    """(path, soname) of this interpreter's shared libpython, or None for a statically linked Python."""
    libdir = sysconfig.get_config_var("LIBDIR") or ""
    name = sysconfig.get_config_var("LDLIBRARY") or ""
    soname = sysconfig.get_config_var("INSTSONAME") or name
    path = Path(libdir) / name
    if not name.endswith(".so") or not path.exists():
        return None
    return str(path), soname


def _c_string(text: str) -> str:
    """A C string literal of ``text`` (UTF-8; quotes, backslashes and non-printable bytes escaped)."""
    out = []
    for b in text.encode("utf-8"):
        ch = chr(b)
        out.append(f"\\{ch}" if ch in '"\\' else ch if 32 <= b < 127 else f"\\{b:03o}")
    return '"' + "".join(out) + '"'


def _why_not() -> str | None:
    """Why no loader can be built here (None: it can)."""
    if sys.platform != "linux" or platform.machine() not in ("x86_64", "AMD64"):
        return f"the loader is built for linux64 only (this is {sys.platform} {platform.machine()})"
    if shutil.which("gcc") is None:
        return "gcc is not installed"
    if libpython() is None:
        return "this Python has no shared libpython"
    return None


def build_shim(wrapped_name: str) -> bytes | None:
    """The loader binary (bytes of a shared library) that forwards to ``wrapped_name`` in its own folder,
    or None, with a logged warning, where it cannot be built (the FMU then needs a host with libpython)."""
    why = _why_not()
    found = libpython()
    if why is None and found is not None:
        path, soname = found
        head = (
            f"#define LIBPYTHON {_c_string(path)}\n#define LIBPYTHON_SONAME {_c_string(soname)}\n"
            f"#define WRAPPED {_c_string(wrapped_name)}\n"
        )
        with tempfile.TemporaryDirectory(prefix="piezotwin_shim_") as tmp:
            src, lib = Path(tmp) / "loader.c", Path(tmp) / "loader.so"
            src.write_text(head + SHIM_SOURCE)
            res = subprocess.run(
                ["gcc", "-shared", "-fPIC", "-O2", "-pthread", "-fvisibility=hidden", "-o", str(lib), str(src), "-ldl"],
                capture_output=True,
                text=True,
            )
            if res.returncode == 0:
                return lib.read_bytes()
            why = f"gcc failed: {res.stderr.strip()[-500:]}"
    _LOG.warning(
        "FMU without its libpython loader (%s): a C host must be linked with libpython or preload it "
        "(LD_PRELOAD); Python hosts are not affected",
        why,
    )
    return None


def with_loader(members: dict[str, bytes]) -> dict[str, bytes]:
    """The FMU's ``members`` (archive name -> bytes) with each linux64 wrapper replaced by the loader and kept
    beside it as ``<model>.pythonfmu.so``; unchanged where no loader can be built."""
    out = dict(members)
    for name in [
        n for n in members if n.startswith("binaries/linux64/") and n.endswith(".so") and not n.endswith(WRAPPED_SUFFIX)
    ]:
        wrapped = name[: -len(".so")] + WRAPPED_SUFFIX
        loader = build_shim(wrapped.rsplit("/", 1)[1])
        if loader is None:
            return members
        out[name], out[wrapped] = loader, members[name]
    return out
