/*
 * trackingbox native model-exchange stepper (see native/__init__.py).
 *
 * Owns one CVODE instance integrating one FMI 3 model-exchange FMU instance
 * that fmpy created and keeps driving between steps (parameters, event mode,
 * reads). The right-hand side calls the FMU's C functions directly and
 * interpolates the input table in C, so no Python runs inside a step.
 *
 * Settings are those of fmpy's CVodeSolver, which trackingbox's Python path
 * (fmu.ModelExchangeStepper) uses: BDF, dense direct linear solver with
 * CVODE's difference-quotient Jacobian, relative tolerance rtol, absolute
 * tolerance rtol * nominal per state, the given largest step and step count,
 * CV_NORMAL returns, and optionally CVodeSetStopTime at every target (the
 * "carry" mode). The right-hand side does what fmpy's does, in the same
 * order: set time, set inputs (linear interpolation, held beyond the ends),
 * set states, get derivatives.
 *
 * Every SUNDIALS and FMI function is looked up with dlsym on the library
 * handles the caller passes: the CVODE libraries fmpy loaded and the FMU
 * binary fmpy loaded, so there is one copy of each in the process.
 *
 * Return codes of tbn_step: TBN_OK, TBN_STEP_EVENT (the FMU asked for event
 * mode in fmi3CompletedIntegratorStep), TBN_TERMINATE, TBN_NONFINITE (a state
 * is NaN/inf after the step), TBN_FMU_FAILED (an FMU call returned more than
 * fmi3Warning: tbn_failed_call names it), TBN_CVODE_FAILED (tbn_error holds
 * CVODE's message; if the right-hand side failed, tbn_failed_call names the
 * FMU call; also when reading the states before CVODE or writing them after
 * it failed, as fmpy's solver step reports those).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define TBN_OK 0
#define TBN_STEP_EVENT 1
#define TBN_TERMINATE 2
#define TBN_NONFINITE 3
#define TBN_FMU_FAILED -1
#define TBN_CVODE_FAILED -2

typedef void *N_Vector;
typedef void *SUNMatrix;
typedef void *SUNLinearSolver;
typedef void *SUNContext;
typedef int (*CVRhsFn)(double t, N_Vector y, N_Vector ydot, void *user);
typedef void (*SUNErrHandlerFn)(int line, const char *func, const char *file, const char *msg, int code,
                                void *data, SUNContext ctx);
typedef void *fmi3Instance;
typedef int (*fmi_time_fn)(fmi3Instance, double);
typedef int (*fmi_vec_fn)(fmi3Instance, double *, size_t);
typedef int (*fmi_cvec_fn)(fmi3Instance, const double *, size_t);
typedef int (*fmi_setf64_fn)(fmi3Instance, const uint32_t *, size_t, const double *, size_t);
typedef int (*fmi_getf64_fn)(fmi3Instance, const uint32_t *, size_t, double *, size_t);
typedef int (*fmi_completed_fn)(fmi3Instance, bool, bool *, bool *);
typedef int (*fmi_mode_fn)(fmi3Instance);
typedef int (*fmi_update_fn)(fmi3Instance, bool *, bool *, bool *, bool *, bool *, double *);

struct sundials {
    int (*context_create)(int, SUNContext *);
    int (*context_free)(SUNContext *);
    int (*push_err_handler)(SUNContext, SUNErrHandlerFn, void *);
    N_Vector (*nv_new)(int64_t, SUNContext);
    void (*nv_destroy)(N_Vector);
    double *(*nv_data)(N_Vector);
    SUNMatrix (*dense_matrix)(int64_t, int64_t, SUNContext);
    void (*mat_destroy)(SUNMatrix);
    SUNLinearSolver (*linsol_dense)(N_Vector, SUNMatrix, SUNContext);
    int (*linsol_free)(SUNLinearSolver);
    void *(*create)(int, SUNContext);
    void (*free)(void **);
    int (*init)(void *, CVRhsFn, double, N_Vector);
    int (*reinit)(void *, double, N_Vector);
    int (*sv_tolerances)(void *, double, N_Vector);
    int (*set_linear_solver)(void *, SUNLinearSolver, SUNMatrix);
    int (*set_max_step)(void *, double);
    int (*set_max_num_steps)(void *, long);
    int (*set_user_data)(void *, void *);
    int (*set_stop_time)(void *, double);
    int (*get_current_time)(void *, double *);
    int (*get_num_steps)(void *, long *);
    int (*get_num_rhs_evals)(void *, long *);
    int (*cvode)(void *, double, N_Vector, double *, int);
};

typedef struct tbn {
    struct sundials s;
    /* FMU */
    fmi3Instance fmu;
    fmi_time_fn set_time;
    fmi_cvec_fn set_states;
    fmi_vec_fn get_states, get_derivatives, get_nominals;
    fmi_setf64_fn set_f64;
    fmi_getf64_fn get_f64;
    fmi_completed_fn completed;
    fmi_mode_fn enter_event_mode, enter_continuous_time_mode;
    fmi_update_fn update_discrete_states;
    bool needs_completed;
    double *x_before;
    size_t nx;
    /* inputs: nt rows of nin values, row-major */
    size_t nin, nt, cursor;
    uint32_t *in_vr;
    const double *in_t, *in_u;  /* the caller's (see tbn_set_inputs) */
    double *u;
    /* CVODE */
    SUNContext ctx;
    N_Vector y, abstol;
    SUNMatrix A;
    SUNLinearSolver LS;
    void *mem;
    double rtol;
    /* the first failure */
    const char *failed_call;
    int failed_status;
    char error[1024];
    /* tbn_advance's outputs (tbn_advance_reads) */
    struct advance_io {
        size_t nout;
        const uint32_t *out_vr;
        double *out, *x_out, *next_time, *reached;
        int *set_code, *next_defined;
    } adv;
} tbn;

/* CPU seconds spent inside tbn_step, tbn_set_parameters and the set and step of tbn_advance, all instances
 * of this process (tbn_cpu_seconds) */
static double cpu_total;

static double thread_cpu(void) {
    struct timespec ts;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

double tbn_cpu_seconds(void) { return cpu_total; }

static void *sym(void *handle, const char *name, char *err, size_t errlen, int *missing) {
    void *p = dlsym(handle, name);
    if (!p && !*missing) {
        snprintf(err, errlen, "symbol %s not found", name);
        *missing = 1;
    }
    return p;
}

#define SYM(field, handle, name) (*(void **)&(field) = sym((handle), (name), err, errlen, &missing))

static void on_error(int line, const char *func, const char *file, const char *msg, int code, void *data,
                     SUNContext ctx) {
    (void)line; (void)file; (void)code; (void)ctx;
    tbn *h = data;
    (void)func;
    snprintf(h->error, sizeof h->error, "%s", msg ? msg : "");
}

static int fail(tbn *h, const char *call, int status) {
    if (!h->failed_call) {
        h->failed_call = call;
        h->failed_status = status;
    }
    return -1;
}

static int set_inputs(tbn *h, double t) {
    if (h->nin == 0) return 0;
    const double *row;
    if (t <= h->in_t[0]) row = h->in_u;
    else if (t >= h->in_t[h->nt - 1]) row = h->in_u + (h->nt - 1) * h->nin;
    else {
        /* the interval with in_t[i] <= t < in_t[i + 1]; the solver asks for times near the last */
        size_t i = h->cursor;
        while (i > 0 && h->in_t[i] > t) i--;
        while (i + 1 < h->nt && h->in_t[i + 1] <= t) i++;
        h->cursor = i;
        double t0 = h->in_t[i], t1 = h->in_t[i + 1];
        double w = (t - t0) / (t1 - t0);
        const double *a = h->in_u + i * h->nin, *b = a + h->nin;
        for (size_t j = 0; j < h->nin; j++) h->u[j] = a[j] + w * (b[j] - a[j]);
        row = h->u;
    }
    int st = h->set_f64(h->fmu, h->in_vr, h->nin, row, h->nin);
    return st > 1 ? fail(h, "fmi3SetFloat64", st) : 0;
}

static int at_time(tbn *h, double t) {
    int st = h->set_time(h->fmu, t);
    if (st > 1) return fail(h, "fmi3SetTime", st);
    return set_inputs(h, t);
}

static int rhs(double t, N_Vector y, N_Vector ydot, void *user) {
    tbn *h = user;
    if (at_time(h, t)) return -1;
    int st = h->set_states(h->fmu, h->s.nv_data(y), h->nx);
    if (st > 1) return fail(h, "fmi3SetContinuousStates", st);
    st = h->get_derivatives(h->fmu, h->s.nv_data(ydot), h->nx);
    if (st > 1) return fail(h, "fmi3GetContinuousStateDerivatives", st);
    return 0;
}

void tbn_free(tbn *h) {
    if (!h) return;
    if (h->mem) h->s.free(&h->mem);
    if (h->LS) h->s.linsol_free(h->LS);
    if (h->A) h->s.mat_destroy(h->A);
    if (h->y) h->s.nv_destroy(h->y);
    if (h->abstol) h->s.nv_destroy(h->abstol);
    if (h->ctx) h->s.context_free(&h->ctx);
    free(h->in_vr); free(h->u);
    free(h->x_before);
    free(h);
}

/*
 * libs: the dlopen handles of sundials_core, _nvecserial, _sunmatrixdense, _sunlinsoldense, _cvode;
 * binary: the FMU binary's handle; instance: its fmi3Instance (in continuous-time mode, states set).
 */
tbn *tbn_new(void *const libs[5], void *binary, void *instance, size_t nx, double t0, double rtol,
             double max_step, long max_num_steps, int needs_completed, char *err, size_t errlen) {
    tbn *h = calloc(1, sizeof *h);
    if (!h) { snprintf(err, errlen, "out of memory"); return NULL; }
    int missing = 0;
    struct sundials *s = &h->s;
    SYM(s->context_create, libs[0], "SUNContext_Create");
    SYM(s->context_free, libs[0], "SUNContext_Free");
    SYM(s->push_err_handler, libs[0], "SUNContext_PushErrHandler");
    SYM(s->nv_new, libs[1], "N_VNew_Serial");
    SYM(s->nv_destroy, libs[1], "N_VDestroy_Serial");
    SYM(s->nv_data, libs[1], "N_VGetArrayPointer_Serial");
    SYM(s->dense_matrix, libs[2], "SUNDenseMatrix");
    SYM(s->mat_destroy, libs[2], "SUNMatDestroy_Dense");
    SYM(s->linsol_dense, libs[3], "SUNLinSol_Dense");
    SYM(s->linsol_free, libs[3], "SUNLinSolFree_Dense");
    SYM(s->create, libs[4], "CVodeCreate");
    SYM(s->free, libs[4], "CVodeFree");
    SYM(s->init, libs[4], "CVodeInit");
    SYM(s->reinit, libs[4], "CVodeReInit");
    SYM(s->sv_tolerances, libs[4], "CVodeSVtolerances");
    SYM(s->set_linear_solver, libs[4], "CVodeSetLinearSolver");
    SYM(s->set_max_step, libs[4], "CVodeSetMaxStep");
    SYM(s->set_max_num_steps, libs[4], "CVodeSetMaxNumSteps");
    SYM(s->set_user_data, libs[4], "CVodeSetUserData");
    SYM(s->set_stop_time, libs[4], "CVodeSetStopTime");
    SYM(s->get_current_time, libs[4], "CVodeGetCurrentTime");
    SYM(s->get_num_steps, libs[4], "CVodeGetNumSteps");
    SYM(s->get_num_rhs_evals, libs[4], "CVodeGetNumRhsEvals");
    SYM(s->cvode, libs[4], "CVode");
    SYM(h->set_time, binary, "fmi3SetTime");
    SYM(h->set_states, binary, "fmi3SetContinuousStates");
    SYM(h->get_states, binary, "fmi3GetContinuousStates");
    SYM(h->get_derivatives, binary, "fmi3GetContinuousStateDerivatives");
    SYM(h->get_nominals, binary, "fmi3GetNominalsOfContinuousStates");
    SYM(h->set_f64, binary, "fmi3SetFloat64");
    SYM(h->get_f64, binary, "fmi3GetFloat64");
    SYM(h->completed, binary, "fmi3CompletedIntegratorStep");
    SYM(h->enter_event_mode, binary, "fmi3EnterEventMode");
    SYM(h->enter_continuous_time_mode, binary, "fmi3EnterContinuousTimeMode");
    SYM(h->update_discrete_states, binary, "fmi3UpdateDiscreteStates");
    if (missing) { free(h); return NULL; }
    h->x_before = calloc(nx + 1, sizeof(double));
    if (!h->x_before) { snprintf(err, errlen, "out of memory"); free(h); return NULL; }
    h->fmu = instance;
    h->nx = nx;
    h->rtol = rtol;
    h->needs_completed = needs_completed != 0;

    const char *step = "SUNContext_Create";
    if (s->context_create(0 /* SUN_COMM_NULL */, &h->ctx)) goto failed;
    step = "N_VNew_Serial";
    h->y = s->nv_new((int64_t)nx, h->ctx);
    h->abstol = s->nv_new((int64_t)nx, h->ctx);
    if (!h->y || !h->abstol) goto failed;
    double *py = s->nv_data(h->y), *pa = s->nv_data(h->abstol);
    int st = h->get_states(h->fmu, py, nx);
    if (st > 1) { snprintf(err, errlen, "fmi3GetContinuousStates failed with status %d", st); tbn_free(h); return NULL; }
    st = h->get_nominals(h->fmu, pa, nx);
    if (st > 1) { snprintf(err, errlen, "fmi3GetNominalsOfContinuousStates failed with status %d", st); tbn_free(h); return NULL; }
    for (size_t i = 0; i < nx; i++) pa[i] *= rtol;
    step = "CVodeCreate";
    h->mem = s->create(2 /* CV_BDF */, h->ctx);
    if (!h->mem) goto failed;
    step = "CVodeInit";
    if (s->init(h->mem, rhs, t0, h->y)) goto failed;
    step = "CVodeSVtolerances";
    if (s->sv_tolerances(h->mem, rtol, h->abstol)) goto failed;
    step = "SUNDenseMatrix/SUNLinSol_Dense";
    h->A = s->dense_matrix((int64_t)nx, (int64_t)nx, h->ctx);
    h->LS = h->A ? s->linsol_dense(h->y, h->A, h->ctx) : NULL;
    if (!h->LS) goto failed;
    step = "CVodeSetLinearSolver";
    if (s->set_linear_solver(h->mem, h->LS, h->A)) goto failed;
    step = "CVodeSetMaxStep";
    if (s->set_max_step(h->mem, max_step)) goto failed;
    step = "CVodeSetMaxNumSteps";
    if (s->set_max_num_steps(h->mem, max_num_steps)) goto failed;
    step = "CVodeSetUserData";
    if (s->set_user_data(h->mem, h)) goto failed;
    step = "SUNContext_PushErrHandler";
    if (s->push_err_handler(h->ctx, on_error, h)) goto failed;
    return h;
failed:
    snprintf(err, errlen, "%s failed", step);
    tbn_free(h);
    return NULL;
}

/*
 * Use this input table from now on: nt times t and nt rows of nin values u (row-major). The value
 * references are copied; t and u are NOT: the caller keeps them alive and unchanged until the next
 * tbn_set_inputs or tbn_free (one copy of a long table in the process, not two).
 */
int tbn_set_inputs(tbn *h, size_t nin, const uint32_t *vr, size_t nt, const double *t, const double *u) {
    uint32_t *nvr = calloc(nin + 1, sizeof *nvr);
    double *row = calloc(nin + 1, sizeof *row);
    if (!nvr || !row) { free(nvr); free(row); return -1; }
    if (nin) memcpy(nvr, vr, nin * sizeof *nvr);
    free(h->in_vr); free(h->u);
    h->in_vr = nvr; h->u = row;
    h->in_t = t; h->in_u = u;
    h->nin = nt && t && u ? nin : 0;
    h->nt = nt;
    h->cursor = 0;
    return 0;
}

/* Re-initialise CVODE at t from the FMU's current states (fmpy's CVodeSolver.reset). */
int tbn_reset(tbn *h, double t) {
    h->failed_call = NULL;
    int st = h->get_states(h->fmu, h->s.nv_data(h->y), h->nx);
    if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_FMU_FAILED;
    return h->s.reinit(h->mem, t, h->y) ? TBN_CVODE_FAILED : TBN_OK;
}

/* CVODE's internal time (after a stop-time return: the target), NaN if it cannot say. */
double tbn_internal_time(tbn *h) {
    double t;
    return h->s.get_current_time(h->mem, &t) ? NAN : t;
}

/*
 * Integrate to target (stopping exactly there when exact), leave the FMU at the
 * reached time with its inputs and the returned states, and call
 * fmi3CompletedIntegratorStep when the FMU needs it. *reached is the time reached.
 */
static int step(tbn *h, double target, int exact, double *reached);

int tbn_step(tbn *h, double target, int exact, double *reached) {
    double c0 = thread_cpu();
    int code = step(h, target, exact, reached);
    cpu_total += thread_cpu() - c0;
    return code;
}

static int step(tbn *h, double target, int exact, double *reached) {
    h->failed_call = NULL;
    h->error[0] = '\0';
    double *py = h->s.nv_data(h->y);
    int st = h->get_states(h->fmu, py, h->nx);
    if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_CVODE_FAILED;
    if (exact && h->s.set_stop_time(h->mem, target)) {
        snprintf(h->error, sizeof h->error, "CVodeSetStopTime(%.17g) failed", target);
        return TBN_CVODE_FAILED;
    }
    double tret = target;
    int flag = h->s.cvode(h->mem, target, h->y, &tret, 1 /* CV_NORMAL */);
    *reached = tret;
    st = h->set_states(h->fmu, py, h->nx);
    if (flag < 0) return TBN_CVODE_FAILED;
    if (st > 1) return fail(h, "fmi3SetContinuousStates", st), TBN_CVODE_FAILED;
    if (at_time(h, tret)) return TBN_FMU_FAILED;
    int code = TBN_OK;
    if (h->needs_completed) {
        bool event = false, terminate = false;
        st = h->completed(h->fmu, true, &event, &terminate);
        if (st > 1) return fail(h, "fmi3CompletedIntegratorStep", st), TBN_FMU_FAILED;
        if (terminate) return TBN_TERMINATE;
        if (event) code = TBN_STEP_EVENT;
    }
    if (code == TBN_OK)
        for (size_t i = 0; i < h->nx; i++)
            if (!isfinite(py[i])) return TBN_NONFINITE;
    return code;
}

/*
 * Set n Float64 tunable parameters and/or inputs between steps, as the Python path's
 * ModelExchangeStepper.set does: with event (some are parameters) event mode, the values, the event
 * iteration (fmi3UpdateDiscreteStates until it needs no more), continuous-time mode; without (inputs
 * only) just the values, and *next_defined = -1 (the next time event is unchanged). The change is carried (CVODE goes on) when carry is asked for, CVODE
 * stands exactly at time (it stopped there) and the event left the states unchanged; otherwise
 * CVODE is re-initialised at time. Returns 1 carried, 0 restarted, TBN_TERMINATE, TBN_FMU_FAILED
 * (tbn_failed_call) or TBN_CVODE_FAILED; *next_defined / *next_time: the FMU's next time event.
 */
static int set_parameters(tbn *h, size_t n, const uint32_t *vr, const double *values, int event, int carry,
                          double time, int *next_defined, double *next_time);

int tbn_set_parameters(tbn *h, size_t n, const uint32_t *vr, const double *values, int event, int carry,
                       double time, int *next_defined, double *next_time) {
    double c0 = thread_cpu();
    int code = set_parameters(h, n, vr, values, event, carry, time, next_defined, next_time);
    cpu_total += thread_cpu() - c0;
    return code;
}

static int set_parameters(tbn *h, size_t n, const uint32_t *vr, const double *values, int event, int carry,
                          double time, int *next_defined, double *next_time) {
    h->failed_call = NULL;
    h->error[0] = '\0';
    *next_defined = 0;
    int st;
    if (carry) {
        double t_int;
        carry = h->s.get_current_time(h->mem, &t_int) == 0 &&
                fabs(t_int - time) <= 1e-12 * fmax(1.0, fabs(time));
    }
    if (carry) {
        st = h->get_states(h->fmu, h->x_before, h->nx);
        if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_FMU_FAILED;
    }
    if (event) {
        st = h->enter_event_mode(h->fmu);
        if (st > 1) return fail(h, "fmi3EnterEventMode", st), TBN_FMU_FAILED;
    }
    st = h->set_f64(h->fmu, vr, n, values, n);
    if (st > 1) return fail(h, "fmi3SetFloat64", st), TBN_FMU_FAILED;
    if (event) {
        bool needed = true, terminate = false, nominals, states_changed, defined = false;
        double when = 0.0;
        while (needed && !terminate) {
            st = h->update_discrete_states(h->fmu, &needed, &terminate, &nominals, &states_changed, &defined,
                                           &when);
            if (st > 1) return fail(h, "fmi3UpdateDiscreteStates", st), TBN_FMU_FAILED;
        }
        if (terminate) return TBN_TERMINATE;
        *next_defined = defined;
        *next_time = when;
        st = h->enter_continuous_time_mode(h->fmu);
        if (st > 1) return fail(h, "fmi3EnterContinuousTimeMode", st), TBN_FMU_FAILED;
    } else {
        *next_defined = -1;  /* no event iteration: the next time event is unchanged */
    }
    double *py = h->s.nv_data(h->y);
    if (carry) {
        st = h->get_states(h->fmu, py, h->nx);
        if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_FMU_FAILED;
        /* the event must have left the states where CVODE has them (equal values, as the
         * Python path's numpy.array_equal asks), else it restarts */
        for (size_t i = 0; carry && i < h->nx; i++) carry = py[i] == h->x_before[i];
    }
    if (carry) return 1;
    int code = tbn_reset(h, time);
    return code == TBN_OK ? 0 : code;
}

/*
 * One call for what the tracking runtime does between two reads of a twin: set n Float64 values as
 * tbn_set_parameters does (when n > 0; flags: TBN_EVENT, TBN_CARRY), step to target as tbn_step
 * does (TBN_EXACT), then read the continuous states and the Float64 variables of the last
 * tbn_advance_reads (fmi3GetContinuousStates, then fmi3GetFloat64: the calls, in that order, that
 * NativeStepper.set, .step, .get_continuous_states and a reader make one by one).
 *
 * Returns TBN_OK when all of it ran; TBN_SET_FAILED when the set did not succeed (*set_code: its
 * code); TBN_AFTER_SET when the set announced a time event (*next_defined = 1: the caller steps
 * towards it itself, nothing else ran); a code of tbn_step other than TBN_OK (the caller finishes
 * the step as after tbn_step; nothing is read); TBN_READ_FAILED when a read failed (tbn_failed_call
 * names it). *set_code is tbn_set_parameters's code, TBN_NO_SET without values; *next_defined and
 * *next_time as there (-1: unchanged). The set and the step count as integrator CPU (tbn_cpu_seconds),
 * as in tbn_set_parameters and tbn_step; the reads do not.
 */
#define TBN_NO_SET -100
#define TBN_SET_FAILED 10
#define TBN_AFTER_SET 11
#define TBN_READ_FAILED 12
#define TBN_EVENT 1
#define TBN_CARRY 2
#define TBN_EXACT 4

/* Where tbn_advance puts what it reads and returns (kept by the caller until the next call of this). */
void tbn_advance_reads(tbn *h, size_t nout, const uint32_t *out_vr, double *out, double *x_out, int *set_code,
                       int *next_defined, double *next_time, double *reached) {
    h->adv.nout = nout; h->adv.out_vr = out_vr; h->adv.out = out; h->adv.x_out = x_out;
    h->adv.set_code = set_code; h->adv.next_defined = next_defined; h->adv.next_time = next_time;
    h->adv.reached = reached;
}

/* the set and the step of tbn_advance (the part counted as integrator CPU) */
static int set_and_step(tbn *h, size_t n, const uint32_t *vr, const double *values, int flags, double time,
                        double target) {
    struct advance_io *io = &h->adv;
    *io->set_code = TBN_NO_SET;
    *io->next_defined = -1;
    if (n > 0) {
        int sc = set_parameters(h, n, vr, values, flags & TBN_EVENT, (flags & TBN_CARRY) != 0, time,
                                io->next_defined, io->next_time);
        *io->set_code = sc;
        if (sc < 0 || sc == TBN_TERMINATE) return TBN_SET_FAILED;
        if (*io->next_defined == 1) return TBN_AFTER_SET;
    }
    return step(h, target, (flags & TBN_EXACT) != 0, io->reached);
}

int tbn_advance(tbn *h, size_t n, const uint32_t *vr, const double *values, int flags, double time, double target) {
    struct advance_io *io = &h->adv;
    double c0 = thread_cpu();
    int code = set_and_step(h, n, vr, values, flags, time, target);
    cpu_total += thread_cpu() - c0;
    if (code != TBN_OK) return code;
    int st = h->get_states(h->fmu, io->x_out, h->nx);
    if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_READ_FAILED;
    if (io->nout) {
        st = h->get_f64(h->fmu, io->out_vr, io->nout, io->out, io->nout);
        if (st > 1) return fail(h, "fmi3GetFloat64", st), TBN_READ_FAILED;
    }
    return TBN_OK;
}

/* Copy the FMU's continuous states into out (nx values). */
int tbn_get_states(tbn *h, double *out) {
    int st = h->get_states(h->fmu, out, h->nx);
    return st > 1 ? (h->failed_call = "fmi3GetContinuousStates", h->failed_status = st, TBN_FMU_FAILED) : TBN_OK;
}

const char *tbn_error(tbn *h) { return h->error; }

const char *tbn_failed_call(tbn *h, int *status) {
    *status = h->failed_status;
    return h->failed_call;
}

void tbn_stats(tbn *h, long *steps, long *rhs_evals) {
    h->s.get_num_steps(h->mem, steps);
    h->s.get_num_rhs_evals(h->mem, rhs_evals);
}
