/*
 * No-Python lower bound for the benchmarks (scripts/_bound.py builds and runs it).
 *
 * Integrates one FMI 3 model-exchange FMU with the same CVODE library, method and
 * settings that fmpy's CVodeSolver (and so trackingbox's ModelExchangeStepper) uses:
 * BDF, dense direct linear solver with a difference-quotient Jacobian, relative
 * tolerance rtol, absolute tolerance rtol * nominal per state, the same largest
 * step, inputs interpolated linearly from a table at every right-hand-side call,
 * and CV_NORMAL returns on the output grid where the outputs are read. The only
 * difference from the Python run is that the right-hand side and the loop are C.
 * Event-free FMUs only (the embedded compile path makes them); an FMU with event
 * indicators or a time event is refused (exit 3).
 *
 * usage: bound_driver JOB OUT
 *   JOB (text): binary path / instantiation token / resource URI ("-": none) /
 *               "t0 t1 rtol maxstep" / np then np lines "vr value" /
 *               nin then nin vrs / nt then nt lines "t u1 .. unin" /
 *               ngrid then ngrid times / nout then nout vrs
 *   OUT: the outputs at the grid times, ngrid*nout doubles (row-major)
 * stdout: "cpu S wall S rhs N steps N" (the integration loop only)
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef void *N_Vector;
typedef void *SUNMatrix;
typedef void *SUNLinearSolver;
typedef void *SUNContext;
typedef int (*CVRhsFn)(double t, N_Vector y, N_Vector ydot, void *user);

static int (*p_SUNContext_Create)(int, SUNContext *);
static N_Vector (*p_N_VNew_Serial)(int64_t, SUNContext);
static double *(*p_N_VGetArrayPointer)(N_Vector);
static SUNMatrix (*p_SUNDenseMatrix)(int64_t, int64_t, SUNContext);
static SUNLinearSolver (*p_SUNLinSol_Dense)(N_Vector, SUNMatrix, SUNContext);
static void *(*p_CVodeCreate)(int, SUNContext);
static int (*p_CVodeInit)(void *, CVRhsFn, double, N_Vector);
static int (*p_CVodeSVtolerances)(void *, double, N_Vector);
static int (*p_CVodeSetLinearSolver)(void *, SUNLinearSolver, SUNMatrix);
static int (*p_CVodeSetMaxStep)(void *, double);
static int (*p_CVodeSetMaxNumSteps)(void *, long);
static int (*p_CVodeSetUserData)(void *, void *);
static int (*p_CVode)(void *, double, N_Vector, double *, int);
static int (*p_CVodeGetNumRhsEvals)(void *, long *);
static int (*p_CVodeGetNumSteps)(void *, long *);

typedef void *fmi3Instance;
static fmi3Instance (*f_Instantiate)(const char *, const char *, const char *, bool, bool, void *, void *);
static int (*f_EnterInit)(fmi3Instance, bool, double, double, bool, double);
static int (*f_ExitInit)(fmi3Instance);
static int (*f_UpdateDiscrete)(fmi3Instance, bool *, bool *, bool *, bool *, bool *, double *);
static int (*f_EnterCT)(fmi3Instance);
static int (*f_SetTime)(fmi3Instance, double);
static int (*f_SetStates)(fmi3Instance, const double *, size_t);
static int (*f_GetStates)(fmi3Instance, double *, size_t);
static int (*f_GetDer)(fmi3Instance, double *, size_t);
static int (*f_GetNominals)(fmi3Instance, double *, size_t);
static int (*f_GetNx)(fmi3Instance, size_t *);
static int (*f_GetNz)(fmi3Instance, size_t *);
static int (*f_SetF64)(fmi3Instance, const uint32_t *, size_t, const double *, size_t);
static int (*f_GetF64)(fmi3Instance, const uint32_t *, size_t, double *, size_t);
static int (*f_Completed)(fmi3Instance, bool, bool *, bool *);
static void (*f_Free)(fmi3Instance);

static void *must(void *lib, const char *name) {
    void *p = dlsym(lib, name);
    if (!p) { fprintf(stderr, "bound_driver: symbol %s not found\n", name); exit(3); }
    return p;
}

static void *open_lib(const char *dir, const char *name) {
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    void *h = dlopen(path, RTLD_NOW | RTLD_GLOBAL);
    if (!h) { fprintf(stderr, "bound_driver: %s\n", dlerror()); exit(3); }
    return h;
}

struct run {
    fmi3Instance fmu;
    size_t nx, nin, nt, cursor;
    uint32_t *in_vr;
    double *in_t, *in_u, *u;
};

static void set_inputs(struct run *r, double t) {
    if (r->nin == 0) return;
    const double *row;
    if (t <= r->in_t[0]) row = r->in_u;
    else if (t >= r->in_t[r->nt - 1]) row = r->in_u + (r->nt - 1) * r->nin;
    else {
        size_t i = r->cursor;
        while (i > 0 && r->in_t[i] > t) i--;
        while (i + 1 < r->nt && r->in_t[i + 1] <= t) i++;
        r->cursor = i;
        double w = (t - r->in_t[i]) / (r->in_t[i + 1] - r->in_t[i]);
        const double *a = r->in_u + i * r->nin, *b = a + r->nin;
        for (size_t j = 0; j < r->nin; j++) r->u[j] = a[j] + w * (b[j] - a[j]);
        row = r->u;
    }
    f_SetF64(r->fmu, r->in_vr, r->nin, row, r->nin);
}

static int rhs(double t, N_Vector y, N_Vector ydot, void *user) {
    struct run *r = user;
    if (f_SetTime(r->fmu, t) > 1) return -1;
    set_inputs(r, t);
    if (f_SetStates(r->fmu, p_N_VGetArrayPointer(y), r->nx) > 1) return -1;
    return f_GetDer(r->fmu, p_N_VGetArrayPointer(ydot), r->nx) > 1 ? -1 : 0;
}

static double now(clockid_t c) {
    struct timespec ts;
    clock_gettime(c, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

#define READ(fmt, ...) do { if (fscanf(job, fmt, __VA_ARGS__) < 1) { \
    fprintf(stderr, "bound_driver: malformed job file near '%s'\n", #__VA_ARGS__); exit(3); } } while (0)

int main(int argc, char **argv) {
    if (argc != 3) { fprintf(stderr, "usage: bound_driver JOB OUT\n"); return 3; }
    FILE *job = fopen(argv[1], "r");
    if (!job) { perror(argv[1]); return 3; }
    char bin[4096], token[512], res[4096], sundials[4096];
    READ("%4095s", sundials);
    READ("%4095s", bin);
    READ("%511s", token);
    READ("%4095s", res);
    double t0, t1, rtol, maxstep;
    READ("%lf %lf %lf %lf", &t0, &t1, &rtol, &maxstep);

    void *core = open_lib(sundials, "sundials_core.so");
    open_lib(sundials, "sundials_nvecserial.so");
    open_lib(sundials, "sundials_sunmatrixdense.so");
    open_lib(sundials, "sundials_sunlinsoldense.so");
    void *cv = open_lib(sundials, "sundials_cvode.so");
    (void)core;
    *(void **)&p_SUNContext_Create = must(RTLD_DEFAULT, "SUNContext_Create");
    *(void **)&p_N_VNew_Serial = must(RTLD_DEFAULT, "N_VNew_Serial");
    *(void **)&p_N_VGetArrayPointer = must(RTLD_DEFAULT, "N_VGetArrayPointer");
    *(void **)&p_SUNDenseMatrix = must(RTLD_DEFAULT, "SUNDenseMatrix");
    *(void **)&p_SUNLinSol_Dense = must(RTLD_DEFAULT, "SUNLinSol_Dense");
    *(void **)&p_CVodeCreate = must(cv, "CVodeCreate");
    *(void **)&p_CVodeInit = must(cv, "CVodeInit");
    *(void **)&p_CVodeSVtolerances = must(cv, "CVodeSVtolerances");
    *(void **)&p_CVodeSetLinearSolver = must(cv, "CVodeSetLinearSolver");
    *(void **)&p_CVodeSetMaxStep = must(cv, "CVodeSetMaxStep");
    *(void **)&p_CVodeSetMaxNumSteps = must(cv, "CVodeSetMaxNumSteps");
    *(void **)&p_CVodeSetUserData = must(cv, "CVodeSetUserData");
    *(void **)&p_CVode = must(cv, "CVode");
    *(void **)&p_CVodeGetNumRhsEvals = must(cv, "CVodeGetNumRhsEvals");
    *(void **)&p_CVodeGetNumSteps = must(cv, "CVodeGetNumSteps");

    void *lib = dlopen(bin, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "bound_driver: %s\n", dlerror()); return 3; }
    *(void **)&f_Instantiate = must(lib, "fmi3InstantiateModelExchange");
    *(void **)&f_EnterInit = must(lib, "fmi3EnterInitializationMode");
    *(void **)&f_ExitInit = must(lib, "fmi3ExitInitializationMode");
    *(void **)&f_UpdateDiscrete = must(lib, "fmi3UpdateDiscreteStates");
    *(void **)&f_EnterCT = must(lib, "fmi3EnterContinuousTimeMode");
    *(void **)&f_SetTime = must(lib, "fmi3SetTime");
    *(void **)&f_SetStates = must(lib, "fmi3SetContinuousStates");
    *(void **)&f_GetStates = must(lib, "fmi3GetContinuousStates");
    *(void **)&f_GetDer = must(lib, "fmi3GetContinuousStateDerivatives");
    *(void **)&f_GetNominals = must(lib, "fmi3GetNominalsOfContinuousStates");
    *(void **)&f_GetNx = must(lib, "fmi3GetNumberOfContinuousStates");
    *(void **)&f_GetNz = must(lib, "fmi3GetNumberOfEventIndicators");
    *(void **)&f_SetF64 = must(lib, "fmi3SetFloat64");
    *(void **)&f_GetF64 = must(lib, "fmi3GetFloat64");
    *(void **)&f_Completed = must(lib, "fmi3CompletedIntegratorStep");
    *(void **)&f_Free = must(lib, "fmi3FreeInstance");

    struct run r = {0};
    r.fmu = f_Instantiate("bound", token, strcmp(res, "-") ? res : NULL, false, false, NULL, NULL);
    if (!r.fmu) { fprintf(stderr, "bound_driver: fmi3InstantiateModelExchange failed\n"); return 3; }
    size_t np;
    READ("%zu", &np);
    for (size_t i = 0; i < np; i++) {
        uint32_t vr; double v;
        READ("%u %lf", &vr, &v);
        if (f_SetF64(r.fmu, &vr, 1, &v, 1) > 1) { fprintf(stderr, "bound_driver: cannot set vr %u\n", vr); return 3; }
    }
    READ("%zu", &r.nin);
    r.in_vr = calloc(r.nin + 1, sizeof *r.in_vr);
    for (size_t j = 0; j < r.nin; j++) READ("%u", &r.in_vr[j]);
    READ("%zu", &r.nt);
    r.in_t = calloc(r.nt + 1, sizeof(double));
    r.in_u = calloc(r.nt * r.nin + 1, sizeof(double));
    r.u = calloc(r.nin + 1, sizeof(double));
    for (size_t i = 0; i < r.nt; i++) {
        READ("%lf", &r.in_t[i]);
        for (size_t j = 0; j < r.nin; j++) READ("%lf", &r.in_u[i * r.nin + j]);
    }
    size_t ngrid, nout;
    READ("%zu", &ngrid);
    double *grid = calloc(ngrid + 1, sizeof(double));
    for (size_t i = 0; i < ngrid; i++) READ("%lf", &grid[i]);
    READ("%zu", &nout);
    uint32_t *out_vr = calloc(nout + 1, sizeof *out_vr);
    for (size_t j = 0; j < nout; j++) READ("%u", &out_vr[j]);
    fclose(job);
    double *out = calloc(ngrid * nout + 1, sizeof(double));

    set_inputs(&r, t0);
    if (f_EnterInit(r.fmu, true, rtol, t0, false, t1) > 1 || f_ExitInit(r.fmu) > 1) {
        fprintf(stderr, "bound_driver: initialisation failed\n"); return 3;
    }
    bool need = true, term = false, nom, val, next_defined = false; double next_t = 0;
    while (need && !term) f_UpdateDiscrete(r.fmu, &need, &term, &nom, &val, &next_defined, &next_t);
    f_EnterCT(r.fmu);
    size_t nz = 0;
    f_GetNx(r.fmu, &r.nx);
    f_GetNz(r.fmu, &nz);
    if (nz > 0 || next_defined || r.nx == 0) {
        fprintf(stderr, "bound_driver: only event-free FMUs with states (nz=%zu, time event %d, nx=%zu)\n",
                nz, (int)next_defined, r.nx);
        return 3;
    }

    SUNContext ctx;
    p_SUNContext_Create(0, &ctx);
    N_Vector y = p_N_VNew_Serial((int64_t)r.nx, ctx), atol = p_N_VNew_Serial((int64_t)r.nx, ctx);
    double *py = p_N_VGetArrayPointer(y), *pa = p_N_VGetArrayPointer(atol);
    f_GetStates(r.fmu, py, r.nx);
    f_GetNominals(r.fmu, pa, r.nx);
    for (size_t i = 0; i < r.nx; i++) pa[i] *= rtol;
    void *mem = p_CVodeCreate(2 /* CV_BDF */, ctx);
    SUNMatrix A = p_SUNDenseMatrix((int64_t)r.nx, (int64_t)r.nx, ctx);
    SUNLinearSolver LS = p_SUNLinSol_Dense(y, A, ctx);
    if (p_CVodeInit(mem, rhs, t0, y) || p_CVodeSVtolerances(mem, rtol, atol) ||
        p_CVodeSetLinearSolver(mem, LS, A) || p_CVodeSetMaxStep(mem, maxstep) ||
        p_CVodeSetMaxNumSteps(mem, 100000) || p_CVodeSetUserData(mem, &r)) {
        fprintf(stderr, "bound_driver: CVODE set-up failed\n"); return 3;
    }

    double c0 = now(CLOCK_PROCESS_CPUTIME_ID), w0 = now(CLOCK_MONOTONIC);
    for (size_t k = 0; k < ngrid; k++) {
        double tret = grid[k];
        if (grid[k] > t0) {
            int flag = p_CVode(mem, grid[k], y, &tret, 1 /* CV_NORMAL */);
            if (flag < 0) { fprintf(stderr, "bound_driver: CVode failed (%d) before t = %g\n", flag, grid[k]); return 4; }
            f_SetTime(r.fmu, tret);
            set_inputs(&r, tret);
            f_SetStates(r.fmu, py, r.nx);
            bool ev = false, tm = false;
            f_Completed(r.fmu, true, &ev, &tm);
            if (ev || tm) { fprintf(stderr, "bound_driver: the FMU asked for an event at t = %g\n", tret); return 3; }
        }
        f_GetF64(r.fmu, out_vr, nout, out + k * nout, nout);
    }
    double cpu = now(CLOCK_PROCESS_CPUTIME_ID) - c0, wall = now(CLOCK_MONOTONIC) - w0;
    long nrhs = 0, nsteps = 0;
    p_CVodeGetNumRhsEvals(mem, &nrhs);
    p_CVodeGetNumSteps(mem, &nsteps);
    FILE *fo = fopen(argv[2], "wb");
    if (!fo || fwrite(out, sizeof(double), ngrid * nout, fo) != ngrid * nout) { perror(argv[2]); return 3; }
    fclose(fo);
    printf("cpu %.6f wall %.6f rhs %ld steps %ld\n", cpu, wall, nrhs, nsteps);
    f_Free(r.fmu);
    return 0;
}
