/* A planar two-link arm as a co-simulation FMU (FMI 2.0 or, built with
 * -DFMI3, FMI 3.0).
 *
 * Two uniform links on revolute joints, the first one's axis fixed at
 * (base_x, base_y); q1 is link 1's angle from +x, q2 link 2's angle from
 * link 1 (counter-clockwise positive), gravity g along -y.  The tip of link 2
 * is the port: its position and velocity are outputs, the force on it
 * (fx, fy) an input.  doStep integrates M(q) ddq + c(q, dq) + G(q) = J^T f
 * with fixed RK4 sub-steps of at most max_step.  Under FMI 2.0 the force may
 * vary over a step: fmi2SetRealInputDerivatives gives its first and second
 * time derivatives at the step's start (canInterpolateInputs); under FMI 3.0
 * it is held.  The state (q, dq, time, input) can be saved and restored
 * (fmi2GetFMUstate / fmi3GetFMUState) unless built with -DNO_STATE.
 *
 * The value references are the indices of `v` below; tests/test_fmu.py and
 * examples/fmu/build.py list the same variables.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifdef FMI3
#include "fmi3Functions.h"
#else
#include "fmi2Functions.h"
#endif

enum { L1, L2, M1, M2, I1, I2, LC1, LC2, BASE_X, BASE_Y, G, Q1_START, Q2_START, DQ1_START,
       DQ2_START, MAX_STEP, FX, FY, X, Y, VX, VY, Q1, Q2, DQ1, DQ2, ENERGY, MASS_Y, NV };

static const double START[NV] = {
    0.2, 0.15, 1.0, 0.5, 1.0 * 0.2 * 0.2 / 12.0, 0.5 * 0.15 * 0.15 / 12.0, 0.1, 0.075,
    0.2, 0.06, 9.81, 0.0, -0.3, -3.0, 0.0, 1e-5, 0.0, 0.0};

typedef struct {
    double v[NV];
    double s[4];          /* q1, q2, dq1, dq2 */
    double t;
    double du[2][2];      /* input derivatives: [order - 1][fx, fy] */
} Arm;

/* mass matrix, the rest of the equations (c + G), the tip's Jacobian */
static void terms(const double *v, const double *s, double M[2][2], double h[2],
                  double J[2][2]) {
    double c1 = cos(s[0]), s1 = sin(s[0]), c12 = cos(s[0] + s[1]), s12 = sin(s[0] + s[1]);
    double c2 = cos(s[1]), s2 = sin(s[1]);
    double m2l = v[M2] * v[L1] * v[LC2];
    M[0][0] = v[M1] * v[LC1] * v[LC1] + v[I1] + v[M2] * (v[L1] * v[L1] + v[LC2] * v[LC2])
              + 2.0 * m2l * c2 + v[I2];
    M[0][1] = M[1][0] = v[M2] * v[LC2] * v[LC2] + m2l * c2 + v[I2];
    M[1][1] = v[M2] * v[LC2] * v[LC2] + v[I2];
    h[0] = -m2l * s2 * (2.0 * s[2] * s[3] + s[3] * s[3])
           + (v[M1] * v[LC1] + v[M2] * v[L1]) * v[G] * c1 + v[M2] * v[LC2] * v[G] * c12;
    h[1] = m2l * s2 * s[2] * s[2] + v[M2] * v[LC2] * v[G] * c12;
    J[0][0] = -v[L1] * s1 - v[L2] * s12;  J[0][1] = -v[L2] * s12;
    J[1][0] = v[L1] * c1 + v[L2] * c12;   J[1][1] = v[L2] * c12;
}

static void rhs(const Arm *a, double tau, const double *s, double *ds) {
    double M[2][2], h[2], J[2][2], f[2], r[2];
    terms(a->v, s, M, h, J);
    for (int i = 0; i < 2; i++)
        f[i] = a->v[FX + i] + a->du[0][i] * tau + 0.5 * a->du[1][i] * tau * tau;
    r[0] = J[0][0] * f[0] + J[1][0] * f[1] - h[0];
    r[1] = J[0][1] * f[0] + J[1][1] * f[1] - h[1];
    double det = M[0][0] * M[1][1] - M[0][1] * M[1][0];
    ds[0] = s[2];
    ds[1] = s[3];
    ds[2] = (M[1][1] * r[0] - M[0][1] * r[1]) / det;
    ds[3] = (M[0][0] * r[1] - M[1][0] * r[0]) / det;
}

/* outputs from the state */
static void update(Arm *a) {
    double *v = a->v, *s = a->s, M[2][2], h[2], J[2][2];
    terms(v, s, M, h, J);
    double c1 = cos(s[0]), s1 = sin(s[0]), c12 = cos(s[0] + s[1]), s12 = sin(s[0] + s[1]);
    v[X] = v[BASE_X] + v[L1] * c1 + v[L2] * c12;
    v[Y] = v[BASE_Y] + v[L1] * s1 + v[L2] * s12;
    v[VX] = J[0][0] * s[2] + J[0][1] * s[3];
    v[VY] = J[1][0] * s[2] + J[1][1] * s[3];
    v[Q1] = s[0]; v[Q2] = s[1]; v[DQ1] = s[2]; v[DQ2] = s[3];
    double kin = 0.5 * (M[0][0] * s[2] * s[2] + 2.0 * M[0][1] * s[2] * s[3]
                        + M[1][1] * s[3] * s[3]);
    double y1 = v[BASE_Y] + v[LC1] * s1, y2 = v[BASE_Y] + v[L1] * s1 + v[LC2] * s12;
    v[ENERGY] = kin + v[G] * (v[M1] * y1 + v[M2] * y2);
    /* effective mass of the tip along y: 1 / (e_y^T J M^-1 J^T e_y) */
    double det = M[0][0] * M[1][1] - M[0][1] * M[1][0];
    double a0 = J[1][0], a1 = J[1][1];
    v[MASS_Y] = det / (M[1][1] * a0 * a0 - 2.0 * M[0][1] * a0 * a1 + M[0][0] * a1 * a1);
}

static void start(Arm *a) {
    a->s[0] = a->v[Q1_START]; a->s[1] = a->v[Q2_START];
    a->s[2] = a->v[DQ1_START]; a->s[3] = a->v[DQ2_START];
    update(a);
}

static int step(Arm *a, double t, double h) {
    if (!(h > 0.0) || !(a->v[MAX_STEP] > 0.0)) return 0;
    int n = (int)ceil(h / a->v[MAX_STEP] - 1e-9);
    if (n < 1) n = 1;
    double dt = h / n, k1[4], k2[4], k3[4], k4[4], y[4];
    for (int i = 0; i < n; i++) {
        double tau = i * dt;
        rhs(a, tau, a->s, k1);
        for (int j = 0; j < 4; j++) y[j] = a->s[j] + 0.5 * dt * k1[j];
        rhs(a, tau + 0.5 * dt, y, k2);
        for (int j = 0; j < 4; j++) y[j] = a->s[j] + 0.5 * dt * k2[j];
        rhs(a, tau + 0.5 * dt, y, k3);
        for (int j = 0; j < 4; j++) y[j] = a->s[j] + dt * k3[j];
        rhs(a, tau + dt, y, k4);
        for (int j = 0; j < 4; j++)
            a->s[j] += dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
    }
    /* the input at the step's end, its derivatives spent */
    for (int i = 0; i < 2; i++) {
        a->v[FX + i] += a->du[0][i] * h + 0.5 * a->du[1][i] * h * h;
        a->du[0][i] = a->du[1][i] = 0.0;
    }
    a->t = t + h;
    update(a);
    return 1;
}

static int set_reals(Arm *a, const unsigned int *vr, size_t n, const double *value) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= X) return 0;            /* outputs are not set */
        a->v[vr[i]] = value[i];
        if (vr[i] == FX || vr[i] == FY) a->du[0][vr[i] - FX] = a->du[1][vr[i] - FX] = 0.0;
    }
    if (a->t == 0.0) start(a);               /* start values change the initial state */
    return 1;
}

static int get_reals(Arm *a, const unsigned int *vr, size_t n, double *value) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= NV) return 0;
        value[i] = a->v[vr[i]];
    }
    return 1;
}

static Arm *create(void) {
    Arm *a = calloc(1, sizeof(Arm));
    if (a) { memcpy(a->v, START, sizeof(START)); start(a); }
    return a;
}

static Arm *copy_of(const Arm *a) {
    Arm *c = malloc(sizeof(Arm));
    if (c) memcpy(c, a, sizeof(Arm));
    return c;
}

#ifndef FMI3
/* ------------------------------------------------------------- FMI 2.0 */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    return fmi2OK;
}
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String resources, const fmi2CallbackFunctions *cb,
                              fmi2Boolean visible, fmi2Boolean logging) {
    return type == fmi2CoSimulation ? create() : NULL;
}
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol,
                               fmi2Real t0, fmi2Boolean stopDefined, fmi2Real stop) {
    ((Arm *)c)->t = 0.0;
    return t0 == 0.0 ? fmi2OK : fmi2Error;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { start(c); return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) {
    memcpy(((Arm *)c)->v, START, sizeof(START));
    ((Arm *)c)->t = 0.0;
    start(c);
    return fmi2OK;
}
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real value[]) {
    return get_reals(c, vr, n, value) ? fmi2OK : fmi2Error;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                       const fmi2Real value[]) {
    return set_reals(c, vr, n, value) ? fmi2OK : fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Arm *a = c;
    for (size_t i = 0; i < n; i++) {
        if ((vr[i] != FX && vr[i] != FY) || order[i] < 1 || order[i] > 2) return fmi2Error;
        a->du[order[i] - 1][vr[i] - FX] = value[i];
    }
    return fmi2OK;
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    return step(c, t, h) ? fmi2OK : fmi2Error;
}
#ifndef NO_STATE
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    if (*state) memcpy(*state, c, sizeof(Arm));
    else *state = copy_of(c);
    return *state ? fmi2OK : fmi2Error;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    memcpy(c, state, sizeof(Arm));
    return fmi2OK;
}
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    free(*state);
    *state = NULL;
    return fmi2OK;
}
#endif
#else
/* ------------------------------------------------------------- FMI 3.0 */
const char *fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean on, size_t n, const fmi3String cat[]) {
    return fmi3OK;
}
fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String name, fmi3String token, fmi3String resources, fmi3Boolean visible,
    fmi3Boolean logging, fmi3Boolean eventMode, fmi3Boolean earlyReturn,
    const fmi3ValueReference required[], size_t nRequired, fmi3InstanceEnvironment env,
    fmi3LogMessageCallback log, fmi3IntermediateUpdateCallback update) {
    return create();
}
void fmi3FreeInstance(fmi3Instance c) { free(c); }
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean tolDefined, fmi3Float64 tol,
                                       fmi3Float64 t0, fmi3Boolean stopDefined, fmi3Float64 stop) {
    ((Arm *)c)->t = 0.0;
    return t0 == 0.0 ? fmi3OK : fmi3Error;
}
fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { start(c); return fmi3OK; }
fmi3Status fmi3EnterStepMode(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance c) {
    memcpy(((Arm *)c)->v, START, sizeof(START));
    ((Arm *)c)->t = 0.0;
    start(c);
    return fmi3OK;
}
fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                          fmi3Float64 value[], size_t nValues) {
    return get_reals(c, vr, n, value) ? fmi3OK : fmi3Error;
}
fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n,
                          const fmi3Float64 value[], size_t nValues) {
    return set_reals(c, vr, n, value) ? fmi3OK : fmi3Error;
}
fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean noSetPrior,
                      fmi3Boolean *eventNeeded, fmi3Boolean *terminate, fmi3Boolean *early,
                      fmi3Float64 *last) {
    *eventNeeded = *terminate = *early = fmi3False;
    int ok = step(c, t, h);
    *last = ((Arm *)c)->t;
    return ok ? fmi3OK : fmi3Error;
}
#ifndef NO_STATE
fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *state) {
    if (*state) memcpy(*state, c, sizeof(Arm));
    else *state = copy_of(c);
    return *state ? fmi3OK : fmi3Error;
}
fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState state) {
    memcpy(c, state, sizeof(Arm));
    return fmi3OK;
}
fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *state) {
    free(*state);
    *state = NULL;
    return fmi3OK;
}
#endif
#endif
