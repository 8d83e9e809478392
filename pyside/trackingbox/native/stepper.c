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
typedef int (*CVLsJacFn)(double t, N_Vector y, N_Vector fy, SUNMatrix J, void *user, N_Vector t1, N_Vector t2,
                         N_Vector t3);
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
    int (*set_jac_eval_frequency)(void *, long);
    int (*get_current_time)(void *, double *);
    int (*get_num_steps)(void *, long *);
    int (*get_num_rhs_evals)(void *, long *);
    int (*cvode)(void *, double, N_Vector, double *, int);
    /* the Jacobian kept across a restart (tbn_keep_jacobian) */
    int (*set_jac_fn)(void *, CVLsJacFn);
    int (*dq_jac)(double, N_Vector, N_Vector, SUNMatrix, void *, N_Vector, N_Vector, N_Vector);
    double *(*dense_data)(SUNMatrix);
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
    /* tbn_keep_jacobian: keep (1) the last difference-quotient Jacobian for the first step after a restart
     * of set_parameters; reuse_next: the next Jacobian evaluation takes it; saved: nx*nx values (valid) */
    int keep_jac, reuse_next, saved_ok;
    double *saved;
    long jac_reused, jac_computed;
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

/* right-hand-side evaluations of all instances of this process (CVODE's steps, Newton iterations and
 * difference-quotient Jacobians: the integrator's work in FMU calls), for the benchmarks */
static long rhs_total;
long tbn_rhs_evaluations(void) { return rhs_total; }

/* The FMI call in progress, for the watchdog (trackingbox.supervise.Watchdog, through native.fmi_call):
 * every call of the FMU's C functions from this library goes through FMI(name, call), so fmi_seq is odd
 * while one runs and even between them, and fmi_name names the latest. A call that hangs leaves both
 * unchanged; a long run of calls that return moves fmi_seq on. Written by the stepping thread, read by
 * the watchdog's: a stale read can only delay a report by one look. */
static volatile unsigned long fmi_seq;
static const char *volatile fmi_name = "";
#define FMI(name, call) __extension__ ({ fmi_name = (name); fmi_seq++; int st_ = (call); fmi_seq++; st_; })
void tbn_fmi_call(unsigned long *seq, const char **name) { *seq = fmi_seq; *name = (const char *)fmi_name; }

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
    int st = FMI("fmi3SetFloat64", h->set_f64(h->fmu, h->in_vr, h->nin, row, h->nin));
    return st > 1 ? fail(h, "fmi3SetFloat64", st) : 0;
}

static int at_time(tbn *h, double t) {
    int st = FMI("fmi3SetTime", h->set_time(h->fmu, t));
    if (st > 1) return fail(h, "fmi3SetTime", st);
    return set_inputs(h, t);
}

static int rhs(double t, N_Vector y, N_Vector ydot, void *user) {
    tbn *h = user;
    rhs_total++;
    if (at_time(h, t)) return -1;
    int st = FMI("fmi3SetContinuousStates", h->set_states(h->fmu, h->s.nv_data(y), h->nx));
    if (st > 1) return fail(h, "fmi3SetContinuousStates", st);
    st = FMI("fmi3GetContinuousStateDerivatives", h->get_derivatives(h->fmu, h->s.nv_data(ydot), h->nx));
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
    free(h->saved);
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
    SYM(s->set_jac_eval_frequency, libs[4], "CVodeSetJacEvalFrequency");
    SYM(s->get_current_time, libs[4], "CVodeGetCurrentTime");
    SYM(s->get_num_steps, libs[4], "CVodeGetNumSteps");
    SYM(s->get_num_rhs_evals, libs[4], "CVodeGetNumRhsEvals");
    SYM(s->cvode, libs[4], "CVode");
    SYM(s->set_jac_fn, libs[4], "CVodeSetJacFn");
    SYM(s->dq_jac, libs[4], "cvLsDQJac");
    SYM(s->dense_data, libs[2], "SUNDenseMatrix_Data");
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
    int st = FMI("fmi3GetContinuousStates", h->get_states(h->fmu, py, nx));
    if (st > 1) { snprintf(err, errlen, "fmi3GetContinuousStates failed with status %d", st); tbn_free(h); return NULL; }
    st = FMI("fmi3GetNominalsOfContinuousStates", h->get_nominals(h->fmu, pa, nx));
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
    int st = FMI("fmi3GetContinuousStates", h->get_states(h->fmu, h->s.nv_data(h->y), h->nx));
    if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_FMU_FAILED;
    return h->s.reinit(h->mem, t, h->y) ? TBN_CVODE_FAILED : TBN_OK;
}

/*
 * The Jacobian CVODE asks for (it asks only when it finds its saved one bad: the first step after an
 * initialisation, every 20 steps, a convergence failure): CVODE's own difference quotient (cvLsDQJac,
 * the function it uses without a user Jacobian, called with its own memory as it calls it, so the
 * values are the same bits), except for the first request after a restart of set_parameters
 * (reuse_next), which gets the last one computed. The Jacobian only steers the Newton iteration, not
 * the error test: a stale one costs iterations, and when the iteration fails CVODE asks again
 * (reuse_next is cleared by then) and gets a fresh one.
 */
static int jacobian(double t, N_Vector y, N_Vector fy, SUNMatrix J, void *user, N_Vector t1, N_Vector t2,
                    N_Vector t3) {
    tbn *h = user;
    size_t n = h->nx * h->nx;
    if (h->reuse_next && h->saved_ok) {
        h->reuse_next = 0;
        memcpy(h->s.dense_data(J), h->saved, n * sizeof(double));
        h->jac_reused++;
        return 0;
    }
    h->reuse_next = 0;
    int r = h->s.dq_jac(t, y, fy, J, h->mem, t1, t2, t3);
    h->saved_ok = r == 0;
    if (r == 0) memcpy(h->saved, h->s.dense_data(J), n * sizeof(double));
    h->jac_computed++;
    return r;
}

/* Keep (on != 0) the last Jacobian across the restarts of set_parameters (see jacobian), or CVODE's own
 * difference quotient throughout (on == 0, the default). Returns 0, or -1 (out of memory, CVODE refused). */
int tbn_keep_jacobian(tbn *h, int on) {
    if (on && !h->saved) {
        h->saved = calloc(h->nx * h->nx + 1, sizeof(double));
        if (!h->saved) return -1;
    }
    h->keep_jac = on != 0;
    h->reuse_next = h->saved_ok = 0;
    return h->s.set_jac_fn(h->mem, on ? jacobian : NULL) ? -1 : 0;
}

/* Forget the kept Jacobian: the next restart's first step evaluates a new one (before a large change) */
void tbn_forget_jacobian(tbn *h) { h->saved_ok = 0; }

/* Jacobians kept across a restart and computed, since the start */
void tbn_jacobians(tbn *h, long *reused, long *computed) {
    *reused = h->jac_reused;
    *computed = h->jac_computed;
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
    int st = FMI("fmi3GetContinuousStates", h->get_states(h->fmu, py, h->nx));
    if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_CVODE_FAILED;
    if (exact && h->s.set_stop_time(h->mem, target)) {
        snprintf(h->error, sizeof h->error, "CVodeSetStopTime(%.17g) failed", target);
        return TBN_CVODE_FAILED;
    }
    double tret = target;
    int flag = h->s.cvode(h->mem, target, h->y, &tret, 1 /* CV_NORMAL */);
    *reached = tret;
    st = FMI("fmi3SetContinuousStates", h->set_states(h->fmu, py, h->nx));
    if (flag < 0) return TBN_CVODE_FAILED;
    if (st > 1) return fail(h, "fmi3SetContinuousStates", st), TBN_CVODE_FAILED;
    if (at_time(h, tret)) return TBN_FMU_FAILED;
    int code = TBN_OK;
    if (h->needs_completed) {
        bool event = false, terminate = false;
        st = FMI("fmi3CompletedIntegratorStep", h->completed(h->fmu, true, &event, &terminate));
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
        st = FMI("fmi3GetContinuousStates", h->get_states(h->fmu, h->x_before, h->nx));
        if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_FMU_FAILED;
    }
    if (event) {
        st = FMI("fmi3EnterEventMode", h->enter_event_mode(h->fmu));
        if (st > 1) return fail(h, "fmi3EnterEventMode", st), TBN_FMU_FAILED;
    }
    st = FMI("fmi3SetFloat64", h->set_f64(h->fmu, vr, n, values, n));
    if (st > 1) return fail(h, "fmi3SetFloat64", st), TBN_FMU_FAILED;
    if (event) {
        bool needed = true, terminate = false, nominals, states_changed, defined = false;
        double when = 0.0;
        while (needed && !terminate) {
            st = FMI("fmi3UpdateDiscreteStates",
                     h->update_discrete_states(h->fmu, &needed, &terminate, &nominals, &states_changed, &defined,
                                               &when));
            if (st > 1) return fail(h, "fmi3UpdateDiscreteStates", st), TBN_FMU_FAILED;
        }
        if (terminate) return TBN_TERMINATE;
        *next_defined = defined;
        *next_time = when;
        st = FMI("fmi3EnterContinuousTimeMode", h->enter_continuous_time_mode(h->fmu));
        if (st > 1) return fail(h, "fmi3EnterContinuousTimeMode", st), TBN_FMU_FAILED;
    } else {
        *next_defined = -1;  /* no event iteration: the next time event is unchanged */
    }
    double *py = h->s.nv_data(h->y);
    if (carry) {
        st = FMI("fmi3GetContinuousStates", h->get_states(h->fmu, py, h->nx));
        if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_FMU_FAILED;
        /* the event must have left the states where CVODE has them (equal values, as the
         * Python path's numpy.array_equal asks), else it restarts */
        for (size_t i = 0; carry && i < h->nx; i++) carry = py[i] == h->x_before[i];
    }
    if (carry) return 1;
    int code = tbn_reset(h, time);
    h->reuse_next = h->keep_jac && code == TBN_OK;
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
    int st = FMI("fmi3GetContinuousStates", h->get_states(h->fmu, io->x_out, h->nx));
    if (st > 1) return fail(h, "fmi3GetContinuousStates", st), TBN_READ_FAILED;
    if (io->nout) {
        st = FMI("fmi3GetFloat64", h->get_f64(h->fmu, io->out_vr, io->nout, io->out, io->nout));
        if (st > 1) return fail(h, "fmi3GetFloat64", st), TBN_READ_FAILED;
    }
    return TBN_OK;
}

/* Copy the FMU's continuous states into out (nx values). */
int tbn_get_states(tbn *h, double *out) {
    int st = FMI("fmi3GetContinuousStates", h->get_states(h->fmu, out, h->nx));
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

/* ===================================================================================================
 * The tracking loop's fast path (tracking/runtime.py, TrackingLoop._native_rows; issue 12).
 *
 * The parameter controllers (ScaledPI with interpolation "linear") and the state compensators
 * (StateCompensator "linear") of tracking/controllers.py, written out with the same floating-point
 * operations in the same order (the library is built with -ffp-contract=off; exp, log, pow and
 * nextafter are the C library's, which Python's math module calls), and the loop of
 * TrackingLoop._row, _step_tracked and _Twin.step over a batch of rows, with the twins advanced by
 * tbn_advance. It returns to Python at the first row that needs Python (a tag going missing or
 * coming back, a time that is not after the last), or inside a row when a twin's tbn_advance did not
 * end with TBN_OK (an event, a failure): the caller then finishes that advance as
 * NativeStepper.advance does and goes on in Python.
 * =================================================================================================== */

/* a PI controller's state (doubles): ScaledPI's u, e_mem (has_mem: not None), e_last (has_last),
 * hold_last; its constants direction*kp, ti, te, span, p_min, p_max; mode_hold (out: mode "hold") */
enum { PI_U, PI_MEM, PI_HAS_MEM, PI_LAST, PI_HAS_LAST, PI_HOLD_LAST, PI_GAIN, PI_TI, PI_TE, PI_SPAN, PI_PMIN,
       PI_PMAX, PI_MODE_HOLD, PI_SIZE };
/* a state compensator's state: m, e_mem, has_mem, e_last, has_last, hold_last; gain, ts, te; mode_hold */
enum { SC_M, SC_MEM, SC_HAS_MEM, SC_LAST, SC_HAS_LAST, SC_HOLD_LAST, SC_GAIN, SC_TS, SC_TE, SC_MODE_HOLD,
       SC_SIZE };

static double clamp100(double u) { return u < 0.0 ? 0.0 : u > 100.0 ? 100.0 : u; }

/* controllers._memory_linear */
static double memory_linear(double e0, double e1, double m0, double ts, double te) {
    double s = (e1 - e0) / ts;
    return e1 - s * te + (m0 - e0 + s * te) * exp(-ts / te);
}

/* controllers._zero_of_rate */
static double zero_of_rate(double a_, double b_, double k, double te, double lo, double hi, double g_lo) {
    int neg_lo = g_lo < 0.0;
    double x = ((g_lo > 0.0) == (k > 0.0)) ? lo : hi;
    double ahead = x == lo ? 1.0 : -1.0;
    double inv_te = 1.0 / te;
    for (int i = 0; i < 100; i++) {
        double ex = k * exp(-x * inv_te);
        double dg = b_ - ex * inv_te;
        if (dg == 0.0) break;
        double x_new = x - (a_ + b_ * x + ex) / dg;
        if (!((x_new - x) * ahead > 0.0)) break;
        if (lo <= x_new && x_new <= hi) x = x_new;
        else {
            double m = lo > x_new ? lo : x_new;  /* Python's max(x_new, lo) */
            x = hi < m ? hi : m;                 /* min(m, hi) */
        }
    }
    double t0, t1, toward;
    if ((a_ + b_ * x + k * exp(-x / te) < 0.0) == neg_lo) { t0 = x; t1 = hi; toward = hi; }
    else { t0 = lo; t1 = x; toward = lo; }
    double d = fabs(nextafter(x, toward) - x);
    while (d > 0.0) {
        if (toward == hi) {
            double y = t0 + d;
            if (y >= t1) break;
            if ((a_ + b_ * y + k * exp(-y / te) < 0.0) != neg_lo) { t1 = y; break; }
            t0 = y;
        } else {
            double y = t1 - d;
            if (y <= t0) break;
            if ((a_ + b_ * y + k * exp(-y / te) < 0.0) == neg_lo) { t0 = y; break; }
            t1 = y;
        }
        d *= 2.0;
    }
    for (int i = 0; i < 200; i++) {
        double mid = 0.5 * (t0 + t1);
        if (mid <= t0 || mid >= t1) break;
        if ((a_ + b_ * mid + k * exp(-mid / te) < 0.0) == neg_lo) t0 = mid;
        else t1 = mid;
    }
    return 0.5 * (t0 + t1);
}

/* controllers._integrate_clamped_linear */
static double integrate_clamped_linear(double u, double gain, double ti, double e0, double e1, double m0,
                                       double ts, double te) {
    double s = (e1 - e0) / ts;
    double a_ = e0 / ti + s;
    double b_ = s / ti;
    double c = e0 - m0 - s * te;
    double k = c / te;
    double t_ext = 0.0;
    if (k != 0.0) {
        double r = b_ * te / k;
        if (0.0 < r && r < 1.0) {
            t_ext = -te * log(r);
            if (!(t_ext < ts)) t_ext = 0.0;
        }
    }
    double g_lo = a_ + b_ * 0.0 + k * exp(-0.0 / te);
    double g_hi = a_ + b_ * ts + k * exp(-ts / te);
    double f_prev = 0.0, lo = 0.0;
    if (t_ext > 0.0) {
        double g_ext = a_ + b_ * t_ext + k * exp(-t_ext / te);
        if (g_lo * g_ext < 0.0) {
            double t = zero_of_rate(a_, b_, k, te, 0.0, t_ext, g_lo);
            f_prev = gain * (a_ * t + 0.5 * b_ * t * t + c * (1.0 - exp(-t / te)));
            u += f_prev - 0.0;
            u = clamp100(u);
        }
        lo = t_ext; g_lo = g_ext;
    }
    if (g_lo * g_hi < 0.0) {
        double t = zero_of_rate(a_, b_, k, te, lo, ts, g_lo);
        double f_t = gain * (a_ * t + 0.5 * b_ * t * t + c * (1.0 - exp(-t / te)));
        u += f_t - f_prev;
        u = clamp100(u);
        f_prev = f_t;
    }
    double f_t = gain * (a_ * ts + 0.5 * b_ * ts * ts + c * (1.0 - exp(-ts / te)));
    u += f_t - f_prev;
    return clamp100(u);
}

/* _ErrorMemory._advance_linear with the block's _integrate_linear (pi: ScaledPI, else StateCompensator) */
static void advance_linear(double *c, int pi, int valid, double e, int hold, double dt) {
    int mem = pi ? PI_MEM : SC_MEM, has_mem = pi ? PI_HAS_MEM : SC_HAS_MEM;
    int last = pi ? PI_LAST : SC_LAST, has_last = pi ? PI_HAS_LAST : SC_HAS_LAST;
    int hold_last = pi ? PI_HOLD_LAST : SC_HOLD_LAST, te = pi ? PI_TE : SC_TE;
    if (!valid) {
        if (pi) {  /* the state compensator keeps its memory (StateCompensator._memory_holds) */
            c[has_mem] = 0.0;
            c[mem] = 0.0;  /* (unused while has_mem is 0) */
        }
    } else if (c[has_last] == 0.0) {
        if (c[has_mem] == 0.0) { c[mem] = e; c[has_mem] = 1.0; }
    } else {
        double e0 = c[last];
        double m0 = c[has_mem] == 0.0 ? e0 : c[mem];
        if (c[hold_last] == 0.0) {
            if (pi) {
                c[PI_U] = integrate_clamped_linear(c[PI_U], c[PI_GAIN], c[PI_TI], e0, e, m0, dt, c[PI_TE]);
            } else {
                double s = (e - e0) / c[SC_TS];
                double cc = e0 - m0 - s * c[SC_TE];
                c[SC_M] += c[SC_GAIN] * (s * c[SC_TS] + cc * (1.0 - exp(-c[SC_TS] / c[SC_TE])));
            }
            c[mem] = memory_linear(e0, e, m0, dt, c[te]);
            c[has_mem] = 1.0;
        } else if (pi) {  /* held: the PI's memory follows the error, the compensator's is frozen */
            c[mem] = memory_linear(e0, e, m0, dt, c[te]);
            c[has_mem] = 1.0;
        }
    }
    c[last] = valid ? e : 0.0;
    c[has_last] = valid ? 1.0 : 0.0;
    c[hold_last] = hold ? 1.0 : 0.0;
    c[pi ? PI_MODE_HOLD : SC_MODE_HOLD] = (hold || !valid) ? 1.0 : 0.0;
}

/* ScaledPI.update(setpoint, process_value, hold=hold, dt=dt) with interpolation "linear": the parameter value */
static double pi_linear(double *c, double sp, double pv, int hold, double dt) {
    int valid = isfinite(sp) && isfinite(pv);
    double e = valid ? 100.0 * (sp - pv) / c[PI_SPAN] : 0.0;
    advance_linear(c, 1, valid, e, hold, dt);
    return c[PI_PMIN] + c[PI_U] / 100.0 * (c[PI_PMAX] - c[PI_PMIN]);
}

/* StateCompensator.update(measured, simulated, hold=hold) with interpolation "linear": the correction */
static double comp_linear(double *c, double meas, double sim, int hold) {
    int valid = isfinite(meas) && isfinite(sim);
    advance_linear(c, 0, valid, valid ? meas - sim : 0.0, hold, c[SC_TS]);
    return c[SC_M];
}

/* the two laws on their own, for the tests against the Python classes */
double tbn_pi_linear(double *state, double setpoint, double process_value, int hold, double dt) {
    return pi_linear(state, setpoint, process_value, hold, dt);
}

double tbn_comp_linear(double *state, double measured, double simulated, int hold) {
    return comp_linear(state, measured, simulated, hold);
}

/* One twin the batch steps (runtime._Twin with its NativeStepper): the values it is given (the
 * tracked twin: the pairs' parameters then the corrections; the untracked twin: the corrections) */
typedef struct tbn_twin_io {
    tbn *h;                    /* NULL: no such twin */
    size_t nv;
    const uint32_t *vr;        /* the values' references */
    const int *is_param;       /* 1: a tunable parameter (event mode), 0: an input */
    double *applied;           /* _Twin.applied (in/out) */
    double *given;             /* _Twin.given (in/out), given_ok: present */
    int *given_ok;
    int *ever_set;             /* out: set by the batch (NativeStepper._last_set and note_changed) */
    const double *limit;       /* carry limits (NaN: none); carry_any: _Twin.carry_limits not empty */
    int carry_any;
    const int *extrap;         /* _Twin.extrapolate: extrapolated, with bounds lo, hi */
    const double *lo, *hi;
    int force_restart;         /* in/out */
    int exact;                 /* the stepper stops exactly at targets (carry mode) */
    double time;               /* NativeStepper.time (in/out) */
    long carried, restarts;    /* out: the set outcomes of the batch's successful advances */
    double seconds;            /* out: wall seconds of the batch's advances (_Twin.step_seconds) */
    double *y;                 /* the read variables after the last advance (in/out), nread values */
    const double *out;         /* where tbn_advance reads them to (tbn_advance_reads's buffer) */
    /* scratch, nv each */
    double *val, *sub;
    uint32_t *sub_vr;
    size_t *sub_idx;
} tbn_twin_io;

typedef struct tbn_batch {
    const double *grid;
    size_t k0, k_stop;         /* rows k0 .. k_stop-1, each written and stepped to the next */
    int substeps;
    double ts, hold_until, recovery_until;
    const unsigned char *stopped;
    int hold_k;                /* in/out: the hold flag of the current row */
    double last_time;          /* in/out: the controllers' last update; has_last_time: not None */
    int has_last_time;
    size_t npairs;
    double *pi;                /* npairs * PI_SIZE */
    const double *const *psamples;
    const size_t *pidx;        /* read index of each pair's variable */
    const int *missing;        /* the pair's tag is missing (runtime: missing[tag] is not None) */
    size_t nstates;
    double *comp_t, *comp_u;   /* nstates * SC_SIZE: tracked and untracked compensators */
    const double *const *ssamples;
    const size_t *sidx;        /* read index of each state's level */
    size_t ntags;
    const size_t *tidx;
    const double *const *tsamples;
    const unsigned char *const *scored;  /* NULL entry: the tag is not fitted */
    double *fits;              /* ntags * 7: _Fit's n, sse_t, sse_u, n_u, sum, lo, hi */
    double *pstats, *cstats, *sstats;    /* 3 each: _Stats's final, min, max */
    size_t nread;
    tbn_twin_io tw[2];         /* tracked, untracked (h NULL: none; its columns NaN) */
    double *rows;              /* cap rows of ncols */
    size_t ncols, cap;
    /* out */
    size_t done;               /* rows written and stepped */
    int status;                /* TBB_* */
    int which, sub, code;      /* TBB_INTERRUPTED: the twin (0 tracked, 1 untracked), sub-step (1..), code */
} tbn_batch;

#define TBB_STOPPED 0      /* reached k_stop or the buffer's end */
#define TBB_PYTHON 1       /* row k0 + done needs Python; nothing of it was done */
#define TBB_INTERRUPTED 2  /* row k0 + done is written (rows[done]); a twin's advance returned code */

static double wall_now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

static void stats_add(double *s, double x) {
    if (isfinite(x)) {
        s[0] = x;
        if (x < s[1]) s[1] = x;
        if (x > s[2]) s[2] = x;
    }
}

static void fit_add(double *f, double meas, double tracked, double untracked) {
    if (!(isfinite(meas) && isfinite(tracked))) return;
    f[0] += 1.0;
    f[1] += pow(tracked - meas, 2.0);
    if (isfinite(untracked)) {
        f[3] += 1.0;
        f[2] += pow(untracked - meas, 2.0);
    }
    f[4] += meas;
    if (meas < f[5]) f[5] = meas;
    if (meas > f[6]) f[6] = meas;
}

/* _Twin.step(t_next, values) on the native path, values = tw->val: TBN_OK, or tbn_advance's code (then
 * nothing of the twin's bookkeeping changed) */
static int twin_step(tbn_twin_io *tw, size_t nread, double t_next) {
    size_t n = 0;
    int any_param = 0, small = !tw->force_restart && tw->carry_any;
    for (size_t i = 0; i < tw->nv; i++) {
        double v = tw->val[i];
        if (tw->extrap && tw->extrap[i] && tw->given_ok[i]) {  /* _Twin._applied */
            double x = v + 0.5 * (v - tw->given[i]);
            v = x < tw->lo[i] ? tw->lo[i] : x > tw->hi[i] ? tw->hi[i] : x;
        }
        if (tw->applied[i] != v) {
            if (small && !(fabs(v - tw->applied[i]) <= tw->limit[i])) small = 0;
            any_param |= tw->is_param[i];
            tw->sub[n] = v;
            tw->sub_vr[n] = tw->vr[i];
            tw->sub_idx[n] = i;
            n++;
        }
    }
    int restart = n == 0 || !small;
    if (n && tw->force_restart) tbn_forget_jacobian(tw->h);  /* _Twin.step: a large change, a new Jacobian */
    int flags = (any_param ? TBN_EVENT : 0) | (tw->exact && !restart ? TBN_CARRY : 0) | (tw->exact ? TBN_EXACT : 0);
    double w0 = wall_now();
    int code = tbn_advance(tw->h, n, n ? tw->sub_vr : NULL, n ? tw->sub : NULL, flags, tw->time, t_next);
    if (code != TBN_OK) return code;
    if (n) {
        if (*tw->h->adv.set_code == 1) tw->carried++; else tw->restarts++;
        for (size_t j = 0; j < n; j++) {
            tw->applied[tw->sub_idx[j]] = tw->sub[j];
            tw->ever_set[tw->sub_idx[j]] = 1;
        }
        tw->force_restart = 0;
    }
    tw->seconds += wall_now() - w0;
    for (size_t i = 0; i < tw->nv; i++) { tw->given[i] = tw->val[i]; tw->given_ok[i] = 1; }
    tw->time = t_next;
    memcpy(tw->y, tw->out, nread * sizeof(double));
    return TBN_OK;
}

static int close_to(double a, double b, double rel) {  /* math.isclose(a, b, rel_tol=rel) */
    if (a == b) return 1;
    if (isinf(a) || isinf(b)) return 0;
    double diff = fabs(b - a);
    return diff <= fabs(rel * b) || diff <= fabs(rel * a);
}

/* _Controllers._dt: the time since the last update, or ts when it is the sample time (or there was none) */
static double since_last(tbn_batch *b, double t) {
    if (!b->has_last_time) return b->ts;
    double dt = t - b->last_time;
    return close_to(dt, b->ts, 1e-12) ? b->ts : dt;
}

int tbn_track_rows(tbn_batch *b) {
    b->done = 0;
    b->status = TBB_STOPPED;
    b->which = b->sub = b->code = 0;
    tbn_twin_io *tw = &b->tw[0], *pl = &b->tw[1];
    size_t np = b->npairs, ns = b->nstates;
    for (size_t k = b->k0; k < b->k_stop && b->done < b->cap; k++) {
        double t = b->grid[k], t_next = b->grid[k + 1];
        /* what needs Python: a tag going missing or coming back (events), a time not after the last */
        int python = b->has_last_time && !(t - b->last_time > 0.0);
        for (size_t i = 0; i < np && !python; i++)
            python = (isfinite(b->psamples[i][k]) != 0) == (b->missing[i] != 0);
        int n = b->substeps;
        double h = (t_next - t) / n, t_from = t;
        for (int j = 1; j <= n && !python; j++) {
            double t_to = j == n ? t_next : t + j * h;
            python = t_to <= t_from + 1e-12 * fmax(1.0, fabs(t_to));
            t_from = t_to;
        }
        if (python) { b->status = TBB_PYTHON; return 0; }

        /* TrackingLoop._row */
        const double *y = tw->y;
        int hold_all = t < b->hold_until - 1e-9 || b->stopped[k] || t < b->recovery_until - 1e-9;
        if (hold_all != b->hold_k) tw->force_restart = 1;
        b->hold_k = hold_all;
        double dt = since_last(b, t);
        for (size_t i = 0; i < np; i++)
            tw->val[i] = pi_linear(b->pi + i * PI_SIZE, b->psamples[i][k], y[b->pidx[i]], hold_all, dt);
        b->last_time = t; b->has_last_time = 1;
        for (size_t i = 0; i < ns; i++) stats_add(b->sstats + 3 * i, y[b->sidx[i]]);
        double *row = b->rows + b->done * b->ncols;
        size_t c = 0;
        row[c++] = t;
        for (size_t i = 0; i < ns; i++) {
            double meas = b->ssamples[i][k];
            tw->val[np + i] = comp_linear(b->comp_t + i * SC_SIZE, meas, y[b->sidx[i]], 0);
            pl->val[i] = pl->h ? comp_linear(b->comp_u + i * SC_SIZE, meas, pl->y[b->sidx[i]], 0) : NAN;
        }
        for (size_t i = 0; i < b->ntags; i++) {
            double m = b->tsamples[i][k], a = y[b->tidx[i]], u = pl->h ? pl->y[b->tidx[i]] : NAN;
            row[c++] = m; row[c++] = a; row[c++] = u;
            if (b->scored[i] && b->scored[i][k]) fit_add(b->fits + 7 * i, m, a, u);
        }
        for (size_t i = 0; i < np; i++) row[c++] = tw->val[i];
        for (size_t i = 0; i < ns; i++) row[c++] = tw->val[np + i];
        for (size_t i = 0; i < ns; i++) row[c++] = pl->val[i];
        for (size_t i = 0; i < np; i++) row[c++] = b->pi[i * PI_SIZE + PI_MODE_HOLD];
        for (size_t i = 0; i < np; i++) stats_add(b->pstats + 3 * i, tw->val[i]);
        for (size_t i = 0; i < ns; i++) stats_add(b->cstats + 3 * i, tw->val[np + i]);

        /* TrackingLoop._step_tracked */
        t_from = t;
        for (int j = 1; j <= n; j++) {
            double t_to = j == n ? t_next : t + j * h;
            int code = twin_step(tw, b->nread, t_to);
            if (code != TBN_OK) {
                b->status = TBB_INTERRUPTED; b->which = 0; b->sub = j; b->code = code;
                return 0;
            }
            if (j < n) {  /* _Controllers.substep */
                double dts = since_last(b, t_to), wj = (double)j / (double)n;
                for (size_t i = 0; i < np; i++) {
                    double sp = (1.0 - wj) * b->psamples[i][k] + wj * b->psamples[i][k + 1];
                    tw->val[i] = pi_linear(b->pi + i * PI_SIZE, sp, tw->y[b->pidx[i]], b->hold_k, dts);
                }
                b->last_time = t_to;
            }
        }
        if (pl->h) {
            int code = twin_step(pl, b->nread, t_next);
            if (code != TBN_OK) {
                b->status = TBB_INTERRUPTED; b->which = 1; b->sub = 1; b->code = code;
                return 0;
            }
        }
        b->done++;
    }
    return 0;
}

/*
 * The rows of tbn_track_rows as the csv module writes them (csv.writer, default dialect): every value
 * by *repr*, Python's own float repr (PyOS_double_to_string(v, 'r', 0, Py_DTSF_ADD_DOT_0, NULL), which
 * float.__repr__ calls and the csv module writes a float with; the caller passes it and PyMem_Free,
 * and calls this holding the GIL), the last nmodes columns as "hold" (non-zero) or "auto", fields
 * joined by ',' and every row ended by "\r\n". Returns the bytes written to out, -1 if cap is too
 * small, -2 if repr failed (out of memory).
 */
typedef char *(*py_repr_fn)(double, char, int, int, int *);
typedef void (*py_free_fn)(void *);

long tbn_format_rows(const double *rows, size_t n, size_t ncols, size_t nmodes, char *out, size_t cap,
                     void *repr_fn, void *free_fn) {
    py_repr_fn repr;
    py_free_fn pfree;
    *(void **)&repr = repr_fn;
    *(void **)&pfree = free_fn;
    size_t at = 0;
    for (size_t r = 0; r < n; r++) {
        const double *row = rows + r * ncols;
        for (size_t c = 0; c < ncols; c++) {
            const char *s;
            char *owned = NULL;
            if (c >= ncols - nmodes) s = row[c] != 0.0 ? "hold" : "auto";
            else {
                owned = repr(row[c], 'r', 0, 0x02 /* Py_DTSF_ADD_DOT_0 */, NULL);
                if (!owned) return -2;
                s = owned;
            }
            size_t len = strlen(s);
            if (at + len + 2 > cap) { if (owned) pfree(owned); return -1; }
            memcpy(out + at, s, len);
            at += len;
            if (owned) pfree(owned);
            if (c + 1 < ncols) out[at++] = ',';
        }
        if (at + 2 > cap) return -1;
        out[at++] = '\r';
        out[at++] = '\n';
    }
    return (long)at;
}

/* ===================================================================================================
 * Tracking with the controllers inside the integrated system (issue 12: controllers="continuous").
 *
 * The compiled TrackingBox's laws (Blocks.ParameterController, Blocks.StateCompensation) as continuous
 * states integrated by one CVODE instance together with the twin's states, in one right-hand side:
 *
 *   per pair:  e = 100 (u_s - u_m)/span,  der(eMem) = (e - eMem)/Te,
 *              rate = d kp (e/Ti + (e - eMem)/Te),
 *              der(u) = 0 if hold or (u >= 100 and rate > 0) or (u <= 0 and rate < 0) else rate,
 *              parameter = pMin + min(max(u, 0), 100)/100 (pMax - pMin);
 *   per level: e = u_s - u_m,  der(eMem) = (e - eMem)/Te,  der(m) = 0 if hold else k (e - eMem)/Te,
 *              correction = m;
 *
 * u_s the measurement interpolated linearly between its samples (as the box sees it), u_m the twin's
 * variable at the current states. The parameters and corrections reach the FMU as Real *inputs*, set
 * in the right-hand side (fmi3SetFloat64 on inputs is allowed in continuous-time mode; a tunable
 * parameter is not, so this mode needs a twin whose tracked parameters are inputs). CVODE stops at
 * every sample (its stop time: the interpolated measurements and inputs have a kink there; measured
 * on the heat exchanger, this is 6x more accurate in the parameter at the same cost as stepping
 * across them), keeping its history; it is re-initialised only where the right-hand side changes its
 * form: a hold starting or ending, a tag going missing or coming back, and at a batch's start.
 * =================================================================================================== */

#define CLOSED_JAC_STEPS 1000L

typedef struct tbn_closed {
    struct sundials s;           /* h's (a copy: freeing this does not need h) */
    tbn *h;                      /* the twin (FMU, its input table) */
    size_t np, ns, n;            /* pairs, levels, CVODE states: nx + 2 np + 2 ns */
    const uint32_t *vr_set;      /* np + ns input references: the pairs' parameters, then the corrections */
    const uint32_t *vr_sim;      /* np + ns references: each pair's variable, then each level */
    double *pi;                  /* np PI_SIZE rows (tbn_batch.pi) or NULL; the constants are read there */
    double *sc;                  /* ns SC_SIZE rows (comp_t or comp_u) */
    const double *const *psamples, *const *ssamples;
    const double *grid;
    size_t ngrid, cursor;
    int *hold;                   /* np + ns: the pair or level holds over the current stretch */
    double *val, *sim;           /* scratch, np + ns */
    double *zk;                  /* the extended state at the last row (n) */
    /* CVODE */
    SUNContext ctx;
    N_Vector y, abstol;
    SUNMatrix A;
    SUNLinearSolver LS;
    void *mem;
    long reinits;                /* CVODE (re-)initialisations */
    double seconds;              /* wall seconds inside CVODE */
} tbn_closed;

/* the measurement of samples at t: linear between the samples, one present sample held, NaN if neither */
static double closed_meas(tbn_closed *c, const double *s, double t) {
    const double *g = c->grid;
    size_t n = c->ngrid;
    if (t <= g[0]) return s[0];
    if (t >= g[n - 1]) return s[n - 1];
    size_t i = c->cursor;
    while (i > 0 && g[i] > t) i--;
    while (i + 1 < n && g[i + 1] <= t) i++;
    c->cursor = i;
    double a = s[i], b = s[i + 1];
    if (isfinite(a) && isfinite(b)) return a + (t - g[i]) / (g[i + 1] - g[i]) * (b - a);
    return isfinite(a) ? a : b;
}

/* the FMU at (t, x) with the controllers' outputs from the extended state z applied */
static int closed_apply(tbn_closed *c, double t, const double *z) {
    tbn *h = c->h;
    size_t nx = h->nx;
    if (at_time(h, t)) return -1;
    for (size_t i = 0; i < c->np; i++) {
        const double *p = c->pi + i * PI_SIZE;
        c->val[i] = p[PI_PMIN] + clamp100(z[nx + 2 * i + 1]) / 100.0 * (p[PI_PMAX] - p[PI_PMIN]);
    }
    for (size_t j = 0; j < c->ns; j++) c->val[c->np + j] = z[nx + 2 * c->np + 2 * j + 1];
    size_t nv = c->np + c->ns;
    int st;
    if (nv) {
        st = FMI("fmi3SetFloat64", h->set_f64(h->fmu, c->vr_set, nv, c->val, nv));
        if (st > 1) return fail(h, "fmi3SetFloat64", st);
    }
    st = FMI("fmi3SetContinuousStates", h->set_states(h->fmu, z, nx));
    if (st > 1) return fail(h, "fmi3SetContinuousStates", st);
    return 0;
}

static int closed_rhs(double t, N_Vector y, N_Vector ydot, void *user) {
    tbn_closed *c = user;
    tbn *h = c->h;
    rhs_total++;
    const double *z = h->s.nv_data(y);
    double *dz = h->s.nv_data(ydot);
    size_t nx = h->nx, np = c->np, ns = c->ns, nv = np + ns;
    if (closed_apply(c, t, z)) return -1;
    int st = FMI("fmi3GetContinuousStateDerivatives", h->get_derivatives(h->fmu, dz, nx));
    if (st > 1) return fail(h, "fmi3GetContinuousStateDerivatives", st);
    if (nv) {
        st = FMI("fmi3GetFloat64", h->get_f64(h->fmu, c->vr_sim, nv, c->sim, nv));
        if (st > 1) return fail(h, "fmi3GetFloat64", st);
    }
    for (size_t i = 0; i < np; i++) {
        const double *p = c->pi + i * PI_SIZE;
        double mem = z[nx + 2 * i], u = z[nx + 2 * i + 1];
        double sp = closed_meas(c, c->psamples[i], t), pv = c->sim[i];
        double *dmem = dz + nx + 2 * i, *du = dmem + 1;
        if (!(isfinite(sp) && isfinite(pv))) { *dmem = 0.0; *du = 0.0; continue; }
        double e = 100.0 * (sp - pv) / p[PI_SPAN];
        *dmem = (e - mem) / p[PI_TE];
        double rate = p[PI_GAIN] * (e / p[PI_TI] + (e - mem) / p[PI_TE]);
        *du = (c->hold[i] || (u >= 100.0 && rate > 0.0) || (u <= 0.0 && rate < 0.0)) ? 0.0 : rate;
    }
    for (size_t j = 0; j < ns; j++) {
        const double *q = c->sc + j * SC_SIZE;
        double mem = z[nx + 2 * np + 2 * j];
        double meas = closed_meas(c, c->ssamples[j], t), lvl = c->sim[np + j];
        double *dmem = dz + nx + 2 * np + 2 * j, *dm = dmem + 1;
        if (!(isfinite(meas) && isfinite(lvl))) { *dmem = 0.0; *dm = 0.0; continue; }
        double e = meas - lvl;
        *dmem = (e - mem) / q[SC_TE];
        *dm = c->hold[np + j] ? 0.0 : q[SC_GAIN] * (e - mem) / q[SC_TE];
    }
    return 0;
}

void tbn_closed_free(tbn_closed *c) {
    if (!c) return;
    struct sundials *s = &c->s;
    if (c->mem) s->free(&c->mem);
    if (c->LS) s->linsol_free(c->LS);
    if (c->A) s->mat_destroy(c->A);
    if (c->y) s->nv_destroy(c->y);
    if (c->abstol) s->nv_destroy(c->abstol);
    if (c->ctx) s->context_free(&c->ctx);
    free(c->hold); free(c->val); free(c->sim); free(c->zk);
    free(c);
}

/*
 * A closed-loop integrator for twin h with np pairs and ns levels: vr_set / vr_sim as in tbn_closed
 * (kept by the caller), nominal: the 2 np + 2 ns controller states' nominal values (absolute
 * tolerance rtol * nominal, as for the FMU's states); CVODE's settings are h's (tbn_new).
 */
tbn_closed *tbn_closed_new(tbn *h, size_t np, size_t ns, const uint32_t *vr_set, const uint32_t *vr_sim,
                           const double *nominal, double max_step, long max_num_steps, char *err, size_t errlen) {
    tbn_closed *c = calloc(1, sizeof *c);
    size_t nv = np + ns;
    if (!c) { snprintf(err, errlen, "out of memory"); return NULL; }
    c->s = h->s; c->h = h; c->np = np; c->ns = ns; c->n = h->nx + 2 * nv;
    c->vr_set = vr_set; c->vr_sim = vr_sim;
    c->hold = calloc(nv + 1, sizeof *c->hold);
    c->val = calloc(nv + 1, sizeof *c->val);
    c->sim = calloc(nv + 1, sizeof *c->sim);
    c->zk = calloc(c->n + 1, sizeof *c->zk);
    struct sundials *s = &h->s;
    const char *step = "calloc";
    if (!c->hold || !c->val || !c->sim || !c->zk) goto failed;
    step = "SUNContext_Create";
    if (s->context_create(0, &c->ctx)) goto failed;
    step = "N_VNew_Serial";
    c->y = s->nv_new((int64_t)c->n, c->ctx);
    c->abstol = s->nv_new((int64_t)c->n, c->ctx);
    if (!c->y || !c->abstol) goto failed;
    double *pa = s->nv_data(c->abstol), *py = s->nv_data(c->y);
    int st = FMI("fmi3GetNominalsOfContinuousStates", h->get_nominals(h->fmu, pa, h->nx));
    if (st > 1) { step = "fmi3GetNominalsOfContinuousStates"; goto failed; }
    st = FMI("fmi3GetContinuousStates", h->get_states(h->fmu, py, h->nx));
    if (st > 1) { step = "fmi3GetContinuousStates"; goto failed; }
    for (size_t i = 0; i < 2 * nv; i++) { pa[h->nx + i] = nominal[i]; py[h->nx + i] = 0.0; }
    for (size_t i = 0; i < c->n; i++) pa[i] *= h->rtol;
    step = "CVodeCreate";
    c->mem = s->create(2 /* CV_BDF */, c->ctx);
    if (!c->mem) goto failed;
    step = "CVodeInit";
    if (s->init(c->mem, closed_rhs, 0.0, c->y)) goto failed;
    step = "CVodeSVtolerances";
    if (s->sv_tolerances(c->mem, h->rtol, c->abstol)) goto failed;
    step = "SUNDenseMatrix/SUNLinSol_Dense";
    c->A = s->dense_matrix((int64_t)c->n, (int64_t)c->n, c->ctx);
    c->LS = c->A ? s->linsol_dense(c->y, c->A, c->ctx) : NULL;
    if (!c->LS) goto failed;
    step = "CVodeSetLinearSolver";
    if (s->set_linear_solver(c->mem, c->LS, c->A)) goto failed;
    step = "CVodeSetMaxStep";
    if (s->set_max_step(c->mem, max_step)) goto failed;
    step = "CVodeSetMaxNumSteps";
    if (s->set_max_num_steps(c->mem, max_num_steps)) goto failed;
    step = "CVodeSetUserData";
    if (s->set_user_data(c->mem, c)) goto failed;
    /* the difference-quotient Jacobian (n right-hand sides) at most every CLOSED_JAC_STEPS steps, or
     * when Newton fails to converge: measured on heat production (2 h, 41 states), 163 -> 9
     * evaluations, no more convergence failures, 15 % less integrator CPU (CVODE's default is 51) */
    step = "CVodeSetJacEvalFrequency";
    if (s->set_jac_eval_frequency(c->mem, CLOSED_JAC_STEPS)) goto failed;
    step = "SUNContext_PushErrHandler";
    if (s->push_err_handler(c->ctx, on_error, h)) goto failed;
    return c;
failed:
    snprintf(err, errlen, "%s failed", step);
    tbn_closed_free(c);
    return NULL;
}

/* the hold and presence pattern of row k: changes of it are where CVODE stops and restarts */
static unsigned long closed_pattern(tbn_batch *b, size_t k) {
    double t = b->grid[k];
    int hold_all = t < b->hold_until - 1e-9 || b->stopped[k] || t < b->recovery_until - 1e-9;
    unsigned long h = (unsigned long)hold_all * 1000003UL;
    for (size_t i = 0; i < b->npairs; i++) h = h * 31UL + (isfinite(b->psamples[i][k]) ? 1UL : 2UL);
    for (size_t j = 0; j < b->nstates; j++) h = h * 31UL + (isfinite(b->ssamples[j][k]) ? 1UL : 2UL);
    return h;
}

/* set the holds of row k (constant until the next stop) */
static void closed_holds(tbn_closed *c, tbn_batch *b, size_t k, int hold_all) {
    for (size_t i = 0; i < c->np; i++) c->hold[i] = hold_all || !isfinite(b->psamples[i][k]);
    for (size_t j = 0; j < c->ns; j++) c->hold[c->np + j] = !isfinite(b->ssamples[j][k]);
}

/* the controller states from their discrete form (memory: the error now when there is none) */
static void closed_load(tbn_closed *c, double t, double *z) {
    tbn *h = c->h;
    size_t nx = h->nx;
    for (size_t i = 0; i < c->np; i++) {
        const double *p = c->pi + i * PI_SIZE;
        double sp = closed_meas(c, c->psamples[i], t), pv = c->sim[i];
        double e = (isfinite(sp) && isfinite(pv)) ? 100.0 * (sp - pv) / p[PI_SPAN] : 0.0;
        z[nx + 2 * i] = p[PI_HAS_MEM] != 0.0 ? p[PI_MEM] : e;
        z[nx + 2 * i + 1] = p[PI_U];
    }
    for (size_t j = 0; j < c->ns; j++) {
        const double *q = c->sc + j * SC_SIZE;
        double meas = closed_meas(c, c->ssamples[j], t), lvl = c->sim[c->np + j];
        double e = (isfinite(meas) && isfinite(lvl)) ? meas - lvl : 0.0;
        z[nx + 2 * c->np + 2 * j] = q[SC_HAS_MEM] != 0.0 ? q[SC_MEM] : e;
        z[nx + 2 * c->np + 2 * j + 1] = q[SC_M];
    }
}

/* the controller states back into their discrete form: nothing to integrate up to now, the memory kept */
static void closed_store(tbn_closed *c, const double *z, const int *hold) {
    size_t nx = c->h->nx;
    for (size_t i = 0; i < c->np; i++) {
        double *p = c->pi + i * PI_SIZE;
        p[PI_MEM] = z[nx + 2 * i]; p[PI_HAS_MEM] = 1.0;
        p[PI_U] = clamp100(z[nx + 2 * i + 1]);
        p[PI_LAST] = 0.0; p[PI_HAS_LAST] = 0.0;
        p[PI_HOLD_LAST] = hold[i] ? 1.0 : 0.0;
        p[PI_MODE_HOLD] = hold[i] ? 1.0 : 0.0;
    }
    for (size_t j = 0; j < c->ns; j++) {
        double *q = c->sc + j * SC_SIZE;
        q[SC_MEM] = z[nx + 2 * c->np + 2 * j]; q[SC_HAS_MEM] = 1.0;
        q[SC_M] = z[nx + 2 * c->np + 2 * j + 1];
        q[SC_LAST] = 0.0; q[SC_HAS_LAST] = 0.0;
        q[SC_HOLD_LAST] = hold[c->np + j] ? 1.0 : 0.0;
        q[SC_MODE_HOLD] = hold[c->np + j] ? 1.0 : 0.0;
    }
}

/* (re-)initialise CVODE at t from z */
static int closed_reinit(tbn_closed *c, double t) {
    c->reinits++;
    return c->h->s.reinit(c->mem, t, c->y) ? TBN_CVODE_FAILED : TBN_OK;
}

/* put the FMU at (t, z), read the loop's variables into tw->y and the states into tw->out's x buffer */
static int closed_read(tbn_closed *c, tbn_twin_io *tw, size_t nread, double t, const double *z) {
    tbn *h = c->h;
    if (closed_apply(c, t, z)) return TBN_READ_FAILED;
    int st;
    if (h->adv.nout) {
        st = FMI("fmi3GetFloat64", h->get_f64(h->fmu, h->adv.out_vr, h->adv.nout, h->adv.out, h->adv.nout));
        if (st > 1) return fail(h, "fmi3GetFloat64", st), TBN_READ_FAILED;
    }
    memcpy(tw->y, tw->out, nread * sizeof(double));
    size_t nv = c->np + c->ns;
    if (nv) {
        st = FMI("fmi3GetFloat64", h->get_f64(h->fmu, c->vr_sim, nv, c->sim, nv));
        if (st > 1) return fail(h, "fmi3GetFloat64", st), TBN_READ_FAILED;
    }
    memcpy(h->adv.x_out, z, h->nx * sizeof(double));
    for (size_t i = 0; i < nv; i++) tw->applied[i] = c->val[i];
    return TBN_OK;
}

/* CVODE of c from its time to t, stopping exactly there (CVodeSetStopTime: a sample, where the
 * interpolated measurements and inputs have their kinks; the solver's history is kept) */
static int closed_advance(tbn_closed *c, double t) {
    tbn *h = c->h;
    h->failed_call = NULL;
    h->error[0] = '\0';
    double w0 = wall_now(), c0 = thread_cpu();
    int flag = 0;
    if (h->s.set_stop_time(c->mem, t)) {
        snprintf(h->error, sizeof h->error, "CVodeSetStopTime(%.17g) failed", t);
        flag = -1;
    }
    double tret = t;
    if (flag == 0) flag = h->s.cvode(c->mem, t, c->y, &tret, 1 /* CV_NORMAL */);
    cpu_total += thread_cpu() - c0;
    c->seconds += wall_now() - w0;
    if (flag < 0) return TBN_CVODE_FAILED;
    const double *z = h->s.nv_data(c->y);
    for (size_t i = 0; i < c->n; i++)
        if (!isfinite(z[i])) return TBN_NONFINITE;
    return TBN_OK;
}

/*
 * tbn_track_rows with the controllers inside the integrated system: rows k0 .. k_stop-1 of b (its
 * grid and samples ngrid long), the tracked twin integrated by ct (b->pi, b->comp_t), the untracked one by cu (b->comp_u; NULL: none).
 * Both CVODE instances are initialised at row k0 from the twins' states and the controllers' discrete
 * state, and at every change of the hold and presence pattern; between, they stop at every sample
 * without re-initialisation. The row values at t_k are those of the integrated system at t_k. At the end (or before a row that needs Python) the controllers' states
 * are stored back in their discrete form, each twin's FMU is left at the time reached with those
 * states and its own CVODE (tbn_step's) re-initialised there, so the Python path goes on from it.
 * status: TBB_STOPPED, TBB_PYTHON (row k0 + done needs Python: a tag going missing or coming back,
 * or CVODE failed on its way to the next row: the row is then not written; b->code, b->which say why).
 */
int tbn_closed_rows(tbn_batch *b, size_t ngrid, tbn_closed *ct, tbn_closed *cu) {
    b->done = 0;
    b->status = TBB_STOPPED;
    b->which = b->sub = b->code = 0;
    tbn_twin_io *tw = &b->tw[0], *pl = &b->tw[1];
    tbn_closed *cs[2] = {ct, cu};
    tbn_twin_io *ios[2] = {tw, pl};
    size_t np = b->npairs, ns = b->nstates;
    size_t nfit = b->ntags * 7, nst = 3 * (np + 2 * ns);
    double saved[4096];
    if (nfit + nst > sizeof saved / sizeof saved[0]) { b->status = TBB_PYTHON; b->code = TBN_FMU_FAILED; return 0; }
    ct->pi = b->pi; ct->sc = b->comp_t;
    if (cu) { cu->pi = NULL; cu->sc = b->comp_u; }
    size_t k = b->k0;
    double t = b->grid[k];
    int hold_all = t < b->hold_until - 1e-9 || b->stopped[k] || t < b->recovery_until - 1e-9;
    int failed = 0;
    for (int w = 0; w < 2 && !failed; w++) {
        tbn_closed *c = cs[w];
        if (!c) continue;
        c->psamples = b->psamples; c->ssamples = b->ssamples; c->grid = b->grid; c->ngrid = ngrid;
        c->cursor = k < ngrid ? k : 0;
        closed_holds(c, b, k, hold_all);
        double *z = c->h->s.nv_data(c->y);
        int st = FMI("fmi3GetContinuousStates", c->h->get_states(c->h->fmu, z, c->h->nx));
        if (st > 1) { fail(c->h, "fmi3GetContinuousStates", st); failed = 1; b->which = w; b->code = TBN_READ_FAILED;
                      break; }
        /* the variables the controllers read, at the twin's present state (read with its last step) */
        for (size_t i = 0; i < c->np; i++) c->sim[i] = ios[w]->y[b->pidx[i]];
        for (size_t j = 0; j < c->ns; j++) c->sim[c->np + j] = ios[w]->y[b->sidx[j]];
        closed_load(c, t, z);
        memcpy(c->zk, z, c->n * sizeof(double));
        int code = closed_read(c, ios[w], b->nread, t, z);
        if (code == TBN_OK) code = closed_reinit(c, t);
        if (code != TBN_OK) { failed = 1; b->which = w; b->code = code; }
    }
    unsigned long pattern = closed_pattern(b, k);
    int row_hold = b->hold_k;
    for (; !failed && k < b->k_stop && b->done < b->cap; k++) {
        t = b->grid[k];
        double t_next = b->grid[k + 1];
        int python = !(t_next > t);
        for (size_t i = 0; i < np && !python; i++)
            python = (isfinite(b->psamples[i][k]) != 0) == (b->missing[i] != 0);
        if (python) break;
        hold_all = t < b->hold_until - 1e-9 || b->stopped[k] || t < b->recovery_until - 1e-9;
        const double *y = tw->y;
        /* the row at t_k: the integrated system's values there (the twins were read at t_k) */
        memcpy(saved, b->fits, nfit * sizeof(double));
        memcpy(saved + nfit, b->pstats, 3 * np * sizeof(double));
        memcpy(saved + nfit + 3 * np, b->cstats, 3 * ns * sizeof(double));
        memcpy(saved + nfit + 3 * np + 3 * ns, b->sstats, 3 * ns * sizeof(double));
        for (size_t i = 0; i < ns; i++) stats_add(b->sstats + 3 * i, y[b->sidx[i]]);
        double *row = b->rows + b->done * b->ncols;
        size_t col = 0;
        row[col++] = t;
        for (size_t i = 0; i < b->ntags; i++) {
            double m = b->tsamples[i][k], a = y[b->tidx[i]], u = cu ? pl->y[b->tidx[i]] : NAN;
            row[col++] = m; row[col++] = a; row[col++] = u;
            if (b->scored[i] && b->scored[i][k]) fit_add(b->fits + 7 * i, m, a, u);
        }
        for (size_t i = 0; i < np; i++) row[col++] = tw->applied[i];
        for (size_t i = 0; i < ns; i++) row[col++] = tw->applied[np + i];
        for (size_t i = 0; i < ns; i++) row[col++] = cu ? pl->applied[i] : NAN;
        for (size_t i = 0; i < np; i++) row[col++] = ct->hold[i];
        for (size_t i = 0; i < np; i++) stats_add(b->pstats + 3 * i, tw->applied[i]);
        for (size_t i = 0; i < ns; i++) stats_add(b->cstats + 3 * i, tw->applied[np + i]);
        /* on to t_k+1; a re-initialisation there where the pattern changes (a hold, a tag missing or back) */
        unsigned long next = closed_pattern(b, k + 1);
        int stop = next != pattern;
        for (int w = 0; w < 2 && !failed; w++) {
            tbn_closed *c = cs[w];
            if (!c) continue;
            int code = closed_advance(c, t_next);
            if (code == TBN_OK) code = closed_read(c, ios[w], b->nread, t_next, c->h->s.nv_data(c->y));
            if (code != TBN_OK) { failed = 1; b->which = w; b->code = code; }
        }
        if (failed) {
            /* back to t_k: the row is not written, both twins go back to their state there */
            memcpy(b->fits, saved, nfit * sizeof(double));
            memcpy(b->pstats, saved + nfit, 3 * np * sizeof(double));
            memcpy(b->cstats, saved + nfit + 3 * np, 3 * ns * sizeof(double));
            memcpy(b->sstats, saved + nfit + 3 * np + 3 * ns, 3 * ns * sizeof(double));
            for (int w = 0; w < 2; w++) {
                tbn_closed *c = cs[w];
                if (!c) continue;
                memcpy(c->h->s.nv_data(c->y), c->zk, c->n * sizeof(double));
                closed_read(c, ios[w], b->nread, t, c->zk);
                ios[w]->time = t;
            }
            break;
        }
        row_hold = hold_all;
        for (int w = 0; w < 2; w++) {
            tbn_closed *c = cs[w];
            if (!c) continue;
            ios[w]->time = t_next;
            memcpy(c->zk, c->h->s.nv_data(c->y), c->n * sizeof(double));
        }
        b->done++;
        if (stop) {
            pattern = next;
            double tn = b->grid[k + 1];
            int h_next = tn < b->hold_until - 1e-9 || b->stopped[k + 1] || tn < b->recovery_until - 1e-9;
            for (int w = 0; w < 2 && !failed; w++) {
                tbn_closed *c = cs[w];
                if (!c) continue;
                closed_holds(c, b, k + 1, h_next);
                if (closed_reinit(c, t_next) != TBN_OK) { failed = 1; b->which = w; b->code = TBN_CVODE_FAILED; }
            }
        }
    }
    if (failed || k < b->k_stop) b->status = b->done < b->cap ? TBB_PYTHON : TBB_STOPPED;
    /* hand over at each twin's time: the controllers in their discrete form, the FMU at that time with
     * those states and the twin's own CVODE (tbn_step's) re-initialised there */
    b->hold_k = row_hold;
    b->has_last_time = 0;
    for (int w = 0; w < 2; w++) {
        tbn_closed *c = cs[w];
        if (!c) continue;
        tbn_twin_io *io = ios[w];
        closed_store(c, c->zk, c->hold);
        if (closed_apply(c, io->time, c->zk) == 0) tbn_reset(c->h, io->time);
        memcpy(c->h->adv.x_out, c->zk, c->h->nx * sizeof(double));
        io->restarts += c->reinits;
        c->reinits = 0;
        io->seconds += c->seconds;
        c->seconds = 0.0;
    }
    return 0;
}

/* CVODE's step and right-hand-side counts of a closed-loop integrator (since its creation) */
void tbn_closed_stats(tbn_closed *c, long *steps, long *rhs_evals) {
    c->s.get_num_steps(c->mem, steps);
    c->s.get_num_rhs_evals(c->mem, rhs_evals);
}
