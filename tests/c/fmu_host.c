/* A minimal FMI 2.0 co-simulation host in C, as a simulation tool loads an FMU.
 *
 *   fmu_host BINARY.so RESOURCE_URI GUID VR_U VR_Y FS N_STEPS [OUT.txt]
 *
 * dlopen()s the FMU binary, instantiates it, steps it N_STEPS times with communication step 1/FS and a
 * sine input, writes the outputs (one per line, %.17g) to OUT.txt if given, terminates, frees, dlcloses and
 * returns 0. Any failed call returns its own non-zero status. No FMI headers needed: the types are the
 * FMI 2.0 standard's (fmi2TypesPlatform.h / fmi2FunctionTypes.h). */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef int fmi2Status; /* fmi2OK = 0 */
typedef int fmi2Type;   /* fmi2CoSimulation = 1 */

typedef struct {
    void (*logger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef fmi2Component (*Instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions *,
                                     fmi2Boolean, fmi2Boolean);
typedef fmi2Status (*SetupExperiment)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
typedef fmi2Status (*Mode)(fmi2Component);
typedef fmi2Status (*SetReal)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2Real *);
typedef fmi2Status (*GetReal)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
typedef fmi2Status (*DoStep)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
typedef void (*FreeInstance)(fmi2Component);

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env;
    if (status != 0) fprintf(stderr, "[%s %d %s] %s\n", name, status, category, message);
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "missing symbol %s\n", name);
        exit(3);
    }
    return f;
}

int main(int argc, char **argv) {
    if (argc < 8) {
        fprintf(stderr, "usage: %s BINARY RESOURCE_URI GUID VR_U VR_Y FS N [OUT]\n", argv[0]);
        return 2;
    }
    fmi2ValueReference vr_u = (fmi2ValueReference)atoi(argv[4]), vr_y = (fmi2ValueReference)atoi(argv[5]);
    double fs = atof(argv[6]), h = 1.0 / fs;
    long n = atol(argv[7]);
    FILE *out = argc > 8 ? fopen(argv[8], "w") : NULL;
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "dlopen: %s\n", dlerror());
        return 4;
    }
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = ((Instantiate)sym(lib, "fmi2Instantiate"))("host", 1, argv[3], argv[2], &cb, 0, 0);
    if (!c) return 5;
    if (((SetupExperiment)sym(lib, "fmi2SetupExperiment"))(c, 0, 0.0, 0.0, 0, 0.0)) return 6;
    if (((Mode)sym(lib, "fmi2EnterInitializationMode"))(c)) return 7;
    if (((Mode)sym(lib, "fmi2ExitInitializationMode"))(c)) return 8;
    SetReal set_real = (SetReal)sym(lib, "fmi2SetReal");
    GetReal get_real = (GetReal)sym(lib, "fmi2GetReal");
    DoStep do_step = (DoStep)sym(lib, "fmi2DoStep");
    for (long k = 0; k < n; k++) {
        fmi2Real u = sin(2.0 * M_PI * 0.01 * (double)k), y = 0.0;
        if (set_real(c, &vr_u, 1, &u)) return 9;
        if (do_step(c, k * h, h, 1)) return 10;
        if (get_real(c, &vr_y, 1, &y)) return 11;
        if (out) fprintf(out, "%.17g\n", y);
    }
    if (out) fclose(out);
    if (((Mode)sym(lib, "fmi2Terminate"))(c)) return 12;
    ((FreeInstance)sym(lib, "fmi2FreeInstance"))(c);
    if (dlclose(lib)) return 13;
    return 0;
}
