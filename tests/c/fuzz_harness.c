/* An FMI 2.0 co-simulation importer that is not fmpy: loads a binary and makes CALLS calls of its
   FMI functions in a random order with random arguments (fixed SEED): NaN, inf and huge values, h <= 0,
   the wrong communication point, calls in the wrong FMI state, NULL arrays, unknown value references,
   corrupt serialized states, up to four instances at a time, instances freed and made again; where the
   binary offers Model Exchange, its calls too (on instances of either type, arrays of any length). Every call
   must return a valid fmi2Status and every logged message must be a short string under a declared
   category; the importer itself never passes a pointer that is not its own (as FMI requires).
   usage: fuzz_harness BINARY GUID CALLS SEED N_REALS
   (N_REALS: the number of Real value references, so that most random ones are valid).
   Exit 0 when everything held; prints the count of each status returned. */
#include <dlfcn.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fuzz_random.h"

static int bad_messages;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    (void)name;
    if (!message || !category || strlen(message) > 1023 || status < fmi2OK || status > fmi2Pending ||
        (strcmp(category, "logStatusWarning") && strcmp(category, "logStatusError") && strcmp(category, "logAll")))
        ++bad_messages;
}

#define N_SLOTS 4
#define N_STATES_KEPT 3
#define MAX_N 8

/* phase: what the importer believes the instance is in (0 instantiated, 1 initialization mode, 2 stepping,
   3 terminated, 4 error), from the calls it made and what they returned; half of the calls go on from there */
typedef struct {
    fmi2Component c;
    fmi2FMUstate states[N_STATES_KEPT];
    int phase;
} Slot;

#define FUNCTIONS(X)                                                                                             \
    X(fmi2Instantiate) X(fmi2FreeInstance) X(fmi2SetDebugLogging) X(fmi2SetupExperiment)                         \
    X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode) X(fmi2Terminate) X(fmi2Reset) X(fmi2GetReal)     \
    X(fmi2SetReal) X(fmi2GetBoolean) X(fmi2SetBoolean) X(fmi2GetInteger) X(fmi2SetInteger) X(fmi2GetString)       \
    X(fmi2SetString) X(fmi2DoStep) X(fmi2CancelStep) X(fmi2GetStatus) X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) \
    X(fmi2GetBooleanStatus) X(fmi2GetStringStatus) X(fmi2SetRealInputDerivatives) X(fmi2GetRealOutputDerivatives) \
    X(fmi2GetDirectionalDerivative) X(fmi2GetFMUstate) X(fmi2SetFMUstate) X(fmi2FreeFMUstate)                     \
    X(fmi2SerializedFMUstateSize) X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate) X(fmi2GetTypesPlatform)     \
    X(fmi2GetVersion)

#define ME_FUNCTIONS(X)                                                                                          \
    X(fmi2SetTime) X(fmi2SetContinuousStates) X(fmi2GetContinuousStates) X(fmi2GetDerivatives)                    \
    X(fmi2GetEventIndicators) X(fmi2GetNominalsOfContinuousStates) X(fmi2EnterEventMode) X(fmi2NewDiscreteStates) \
    X(fmi2EnterContinuousTimeMode) X(fmi2CompletedIntegratorStep)

#define DECLARE(name) name##TYPE *name;
static struct { FUNCTIONS(DECLARE) } F; /* the binary's functions */
static struct { ME_FUNCTIONS(DECLARE) } M; /* its Model Exchange functions, where it has them (else NULL) */

static double random_value(void)
{
    static const double special[] = {0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 1e300, -1e300, 1e-9, 0.5};
    switch (below(10)) {
    case 0: return NAN;
    case 1: return below(2) ? INFINITY : -INFINITY;
    case 2: return special[below(10)];
    case 3: return (uniform() - 0.5) * 20.0;
    default: return 0.8 + 0.4 * uniform(); /* an ordinary voltage, angle or tolerance-sized value */
    }
}

static fmi2ValueReference random_vr(int n_reals)
{
    switch (below(8)) {
    case 0: return (fmi2ValueReference)next_random();
    case 1: return (fmi2ValueReference)(n_reals + below(4));
    default: return (fmi2ValueReference)below(n_reals);
    }
}

static double random_step(void)
{
    static const double steps[] = {0.01, 0.001, 0.05, 0.02, 0.0, -0.01, 1e-12, 0.3, 2.0};
    if (below(20) == 0) return below(2) ? NAN : INFINITY;
    return steps[below(9)];
}

static fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
static long counts[8], steps_done;
static int invalid;

static void count(fmi2Status status)
{
    if (status < fmi2OK || status > fmi2Pending) {
        ++invalid;
        return;
    }
    ++counts[status];
}

static void free_slot(Slot *s)
{
    for (int k = 0; k < N_STATES_KEPT; ++k)
        if (s->states[k]) count(F.fmi2FreeFMUstate(s->c, &s->states[k]));
    F.fmi2FreeInstance(s->c);
    memset(s, 0, sizeof *s);
}

static fmi2Component instantiate(const char *guid)
{
    static const char *names[] = {"fuzz", "", NULL, "a much longer instance name with spaces and % signs %s %n"};
    const char *name = below(6) ? "fuzz" : names[below(4)];
    fmi2Type type = below(10) ? fmi2CoSimulation : fmi2ModelExchange;
    const char *g = below(10) ? guid : (below(2) ? "{wrong-guid}" : NULL);
    const fmi2CallbackFunctions *cb = below(20) ? &callbacks : NULL;
    return F.fmi2Instantiate(name, type, g, "file:///nonexistent", cb, fmi2False, below(2) ? fmi2True : fmi2False);
}

static void call_one(Slot *slots, const char *guid, int n_reals)
{
    Slot *s = &slots[below(N_SLOTS)];
    fmi2Component c = s->c;
    fmi2ValueReference vr[MAX_N], vr2[MAX_N];
    fmi2Real values[MAX_N], values2[MAX_N];
    fmi2Integer orders[MAX_N];
    fmi2Boolean booleans[MAX_N];
    fmi2String strings[MAX_N];
    size_t n = (size_t)below(MAX_N), n2 = (size_t)below(MAX_N);
    int null_arrays = below(12) == 0;
    for (int i = 0; i < MAX_N; ++i) {
        vr[i] = random_vr(n_reals);
        vr2[i] = random_vr(n_reals);
        values[i] = random_value();
        values2[i] = random_value();
        orders[i] = below(4) ? 1 : below(4) - 1;
        booleans[i] = fmi2True;
        strings[i] = "x";
    }
    if (!c) { /* mostly make an instance; sometimes call with none */
        if (below(4)) {
            s->c = instantiate(guid);
            return;
        }
    }
    double now = 0.0;
    if (c) F.fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &now);
    if (c && below(2)) { /* a call an orderly importer would make next */
        fmi2Status status;
        switch (s->phase) {
        case 0:
            if (below(2)) count(F.fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
            status = F.fmi2EnterInitializationMode(c);
            if (status == fmi2OK) s->phase = 1;
            break;
        case 1:
            status = F.fmi2ExitInitializationMode(c);
            s->phase = status == fmi2OK ? 2 : 4;
            break;
        case 2: {
            /* SM4's inputs Vs, theta_vs, Pm, Efd (value references 0-3, fmu_export/variables.py); Pm and
               Efd near their start values 0.7048 and 1.08 */
            fmi2ValueReference inputs[4] = {0, 1, 2, 3};
            fmi2Real u[4] = {0.2 + uniform(), uniform() - 0.5, 0.6548 + 0.1 * uniform(), 0.98 + 0.2 * uniform()};
            count(F.fmi2SetReal(c, inputs, 4, u));
            status = F.fmi2DoStep(c, now, below(2) ? 0.01 : 0.001 + 0.05 * uniform(), fmi2True);
            steps_done += status == fmi2OK;
            if (status == fmi2Error) s->phase = 4;
            break;
        }
        default:
            status = F.fmi2Reset(c);
            if (status == fmi2OK) s->phase = 0;
            break;
        }
        count(status);
        return;
    }
    const fmi2ValueReference *v = null_arrays ? NULL : vr;
    switch (below(32)) {
    case 0:
        if (c) free_slot(s);
        break;
    case 1: {
        static const char *categories[] = {"logAll", "logStatusError", "logStatusWarning", "bogus", NULL};
        fmi2String chosen[3] = {categories[below(5)], categories[below(5)], categories[below(5)]};
        count(F.fmi2SetDebugLogging(c, below(2) ? fmi2True : fmi2False, (size_t)below(4), null_arrays ? NULL : chosen));
        break;
    }
    case 2: count(F.fmi2SetupExperiment(c, below(2), random_value(), below(3) ? 0.0 : random_value(), below(2),
                                      random_value())); break;
    case 3: {
        fmi2Status status = F.fmi2EnterInitializationMode(c);
        if (status == fmi2OK) s->phase = 1;
        count(status);
        break;
    }
    case 4: case 5: {
        fmi2Status status = F.fmi2ExitInitializationMode(c);
        if (status == fmi2OK) s->phase = 2;
        if (status == fmi2Error && s->phase == 1) s->phase = 4;
        count(status);
        break;
    }
    case 6: {
        fmi2Status status = F.fmi2Terminate(c);
        if (status == fmi2OK) s->phase = 3;
        count(status);
        break;
    }
    case 7: {
        fmi2Status status = F.fmi2Reset(c);
        if (status == fmi2OK) s->phase = 0;
        count(status);
        break;
    }
    case 8: count(F.fmi2GetReal(c, v, n, null_arrays ? NULL : values)); break;
    case 9: case 10: count(F.fmi2SetReal(c, v, n, null_arrays ? NULL : values)); break;
    case 11: count(F.fmi2GetBoolean(c, v, n, null_arrays ? NULL : booleans)); break;
    case 12:
        switch (below(5)) {
        case 0: count(F.fmi2SetBoolean(c, v, n, booleans)); break;
        case 1: count(F.fmi2GetInteger(c, v, n, orders)); break;
        case 2: count(F.fmi2SetInteger(c, v, n, orders)); break;
        case 3: count(F.fmi2GetString(c, v, n, strings)); break;
        default: count(F.fmi2SetString(c, v, n, strings)); break;
        }
        break;
    case 13: case 14: case 15: case 16: case 17: {
        double t = below(8) ? now : now + random_value();
        fmi2Status status = F.fmi2DoStep(c, t, random_step(), below(2) ? fmi2True : fmi2False);
        count(status);
        steps_done += status == fmi2OK;
        if (status == fmi2Error && s->phase == 2) s->phase = 4;
        break;
    }
    case 18: count(F.fmi2CancelStep(c)); break;
    case 19: {
        fmi2Status status_value;
        fmi2Real real_value;
        fmi2Integer integer_value;
        fmi2Boolean boolean_value;
        fmi2String string_value;
        fmi2StatusKind kind = (fmi2StatusKind)below(5);
        switch (below(5)) {
        case 0: count(F.fmi2GetStatus(c, kind, null_arrays ? NULL : &status_value)); break;
        case 1: count(F.fmi2GetRealStatus(c, kind, null_arrays ? NULL : &real_value)); break;
        case 2: count(F.fmi2GetIntegerStatus(c, kind, null_arrays ? NULL : &integer_value)); break;
        case 3: count(F.fmi2GetBooleanStatus(c, kind, null_arrays ? NULL : &boolean_value)); break;
        default: count(F.fmi2GetStringStatus(c, kind, null_arrays ? NULL : &string_value)); break;
        }
        break;
    }
    case 20: count(F.fmi2SetRealInputDerivatives(c, v, n, null_arrays ? NULL : orders, values)); break;
    case 21: count(F.fmi2GetRealOutputDerivatives(c, v, n, orders, values)); break;
    case 22: case 23:
        count(F.fmi2GetDirectionalDerivative(c, v, n, below(12) ? vr2 : NULL, n2, values2, null_arrays ? NULL : values));
        break;
    case 24: {
        fmi2FMUstate *state = &s->states[below(N_STATES_KEPT)];
        count(F.fmi2GetFMUstate(c, null_arrays ? NULL : state));
        break;
    }
    case 25: {
        fmi2Status status = F.fmi2SetFMUstate(c, s->states[below(N_STATES_KEPT)]);
        if (status == fmi2OK) s->phase = 5; /* whatever the state was: unknown until the next result */
        count(status);
        break;
    }
    case 26: {
        fmi2FMUstate *state = &s->states[below(N_STATES_KEPT)];
        count(F.fmi2FreeFMUstate(c, below(8) ? state : NULL));
        break;
    }
    case 27: case 28: { /* Model Exchange, where the binary offers it */
        if (!M.fmi2GetDerivatives) break;
        fmi2Real *a = null_arrays ? NULL : values;
        fmi2EventInfo info;
        fmi2Boolean enter, terminate;
        switch (below(10)) {
        case 0: count(M.fmi2SetTime(c, below(4) ? now + uniform() : random_value())); break;
        case 1: count(M.fmi2SetContinuousStates(c, a, n)); break;
        case 2: count(M.fmi2GetContinuousStates(c, a, n)); break;
        case 3: count(M.fmi2GetDerivatives(c, a, n)); break;
        case 4: count(M.fmi2GetEventIndicators(c, a, n)); break;
        case 5: count(M.fmi2GetNominalsOfContinuousStates(c, a, n)); break;
        case 6: count(M.fmi2EnterEventMode(c)); break;
        case 7: count(M.fmi2NewDiscreteStates(c, null_arrays ? NULL : &info)); break;
        case 8: count(M.fmi2EnterContinuousTimeMode(c)); break;
        default: count(M.fmi2CompletedIntegratorStep(c, fmi2True, null_arrays ? NULL : &enter, &terminate)); break;
        }
        break;
    }
    default: { /* serialize, maybe corrupt, deserialize */
        fmi2FMUstate state = s->states[below(N_STATES_KEPT)];
        size_t size = 0;
        count(F.fmi2SerializedFMUstateSize(c, state, null_arrays ? NULL : &size));
        if (!c || !state || size == 0 || size > (1u << 30)) break;
        size_t buffer_size = size + 16;
        fmi2Byte *bytes = (fmi2Byte *)calloc(1, buffer_size);
        if (!bytes) break;
        size_t told = below(6) ? size : (size_t)below((int)buffer_size);
        count(F.fmi2SerializeFMUstate(c, state, bytes, told));
        if (below(3) == 0) bytes[below((int)size)] ^= (fmi2Byte)(1 + below(255));
        fmi2FMUstate *into = &s->states[below(N_STATES_KEPT)];
        count(F.fmi2DeSerializeFMUstate(c, bytes, below(6) ? size : (size_t)below((int)buffer_size), into));
        free(bytes);
        break;
    }
    }
}

#define LOAD(name) F.name = (name##TYPE *)dlsym(lib, #name); if (!F.name) { fprintf(stderr, "no %s\n", #name); return 2; }
#define LOAD_OPTIONAL(name) M.name = (name##TYPE *)dlsym(lib, #name);

int main(int argc, char **argv)
{
    if (argc != 6) return 2;
    const char *guid = argv[2];
    long calls = atol(argv[3]);
    int n_reals = atoi(argv[5]);
    rng_state = (uint64_t)atoll(argv[4]);
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "%s\n", dlerror());
        return 2;
    }
    FUNCTIONS(LOAD)
    ME_FUNCTIONS(LOAD_OPTIONAL)
    Slot slots[N_SLOTS];
    memset(slots, 0, sizeof slots);
    for (long k = 0; k < calls; ++k) call_one(slots, guid, n_reals);
    for (int i = 0; i < N_SLOTS; ++i)
        if (slots[i].c) free_slot(&slots[i]);
    dlclose(lib);
    printf("ok %ld warning %ld discard %ld error %ld fatal %ld pending %ld invalid %d bad_messages %d steps %ld\n",
           counts[0], counts[1], counts[2], counts[3], counts[4], counts[5], invalid, bad_messages, steps_done);
    return invalid || bad_messages ? 1 : 0;
}
