/* A fuzzer of serialized FMU states for an FMI 2.0 co-simulation binary: an importer that runs the
   FMU a little, serializes its state, and hands fmi2DeSerializeFMUstate and fmi2SetFMUstate broken
   copies of it: every 8-byte slot set to 0, -1, NaN, +-inf, +-1e308 and the smallest subnormal,
   every 4-byte slot to the int32 values -1, 2, INT_MAX and INT_MIN (huge counters, flags that are not
   0/1, indices past their buffers), random bytes (all of them, or all but the header: a half-random
   state), random spans, truncated and oversized buffers, and the bytes of another FMU's state. A
   refused state must leave the instance as it was (its time and Real variables); an accepted one is
   stepped three times, and every call must return a valid fmi2Status (the caller bounds the time).
   It also checks the FMU-state calls with a pointer the instance did not hand out (fmi2FreeFMUstate
   must refuse it and leave it alone) and fmi2SetupExperiment with a tolerance that is not positive
   and finite.

   usage: state_fuzz BINARY GUID SEED CASES N_REALS PROBE_VR PROBE_VALUE [FOREIGN]
     CASES: the slots to corrupt: the first CASES, the last CASES and CASES random ones (0: every slot);
     N_REALS: the number of Real value references (read back to see that a refusal changed nothing);
     PROBE_VR, PROBE_VALUE: a parameter set to this distinctive value in initialization mode; its
     slot is found in the serialized bytes by its bit pattern and every bad value put there must be
     refused (PROBE_VR -1: none);
     FOREIGN: a file holding another FMU's serialized state, which must be refused.
   Prints the counts; exit 0 when every expectation held, 1 otherwise (the first failure on stderr),
   2 for a usage error. */
#include <dlfcn.h>
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fuzz_random.h"

#define FUNCTIONS(X)                                                                                             \
    X(fmi2Instantiate) X(fmi2FreeInstance) X(fmi2SetupExperiment) X(fmi2EnterInitializationMode)                 \
    X(fmi2ExitInitializationMode) X(fmi2GetReal) X(fmi2SetReal) X(fmi2DoStep) X(fmi2GetRealStatus)               \
    X(fmi2GetFMUstate) X(fmi2SetFMUstate) X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize)                      \
    X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate)

#define DECLARE(name) name##TYPE *name;
static struct { FUNCTIONS(DECLARE) } F;

static long refused, accepted, steps, step_errors, failures;
static long logged_errors;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    (void)name;
    (void)category;
    (void)message;
    if (status == fmi2Error) ++logged_errors;
}

static fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

static void failure(const char *what, long detail)
{
    if (!failures) fprintf(stderr, "%s (%ld)\n", what, detail);
    ++failures;
}

static int valid(fmi2Status status) { return status >= fmi2OK && status <= fmi2Pending; }

/* the instance's time and Real variables, to see that a refused call changed nothing */
typedef struct {
    double time;
    double reals[256];
} Seen;

static int n_reals;

static void look(fmi2Component c, Seen *seen)
{
    memset(seen, 0, sizeof *seen);
    F.fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &seen->time);
    for (int vr = 0; vr < n_reals && vr < 256; ++vr) {
        fmi2ValueReference r = (fmi2ValueReference)vr;
        F.fmi2GetReal(c, &r, 1, &seen->reals[vr]);
    }
}

static int same(const Seen *a, const Seen *b) { return !memcmp(a, b, sizeof *a); }

/* hands the bytes to the FMU: deserialize, set, step three times, then back to `good` */
static void attempt(fmi2Component c, fmi2FMUstate good, const unsigned char *bytes, size_t size, int must_refuse)
{
    Seen before, after;
    fmi2FMUstate state = NULL;
    look(c, &before);
    long errors_before = logged_errors;
    fmi2Status status = F.fmi2DeSerializeFMUstate(c, (const fmi2Byte *)bytes, size, &state);
    if (!valid(status)) failure("fmi2DeSerializeFMUstate returned no valid status", (long)status);
    if (status == fmi2OK) status = F.fmi2SetFMUstate(c, state);
    if (!valid(status)) failure("fmi2SetFMUstate returned no valid status", (long)status);
    if (status != fmi2OK) {
        ++refused;
        look(c, &after);
        if (!same(&before, &after)) failure("a refused state changed the instance", (long)size);
        if (logged_errors == errors_before) failure("a refused state logged no reason", (long)size);
    } else {
        ++accepted;
        if (must_refuse) failure("a state that must be refused was accepted", (long)size);
        for (int k = 0; k < 3; ++k) {
            double now = 0.0;
            F.fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &now);
            fmi2Status s = F.fmi2DoStep(c, now, 0.01, fmi2False);
            if (!valid(s)) failure("fmi2DoStep after a restored state returned no valid status", (long)s);
            ++steps;
            if (s == fmi2Error || s == fmi2Fatal) {
                ++step_errors;
                break;
            }
        }
        if (F.fmi2SetFMUstate(c, good) != fmi2OK) failure("the good state could not be restored", 0);
    }
    if (state && F.fmi2FreeFMUstate(c, &state) != fmi2OK) failure("a deserialized state could not be freed", 0);
}

/* bytes with the 8 bytes at `offset` set to the double value */
static void put_double(unsigned char *bytes, size_t offset, double value) { memcpy(bytes + offset, &value, 8); }
static void put_int(unsigned char *bytes, size_t offset, int32_t value) { memcpy(bytes + offset, &value, 4); }

static const double BAD_DOUBLES[] = {0.0, -1.0, NAN, INFINITY, -INFINITY, 1e308, -1e308, 4.9406564584124654e-324};
static const int32_t BAD_INTS[] = {-1, 2, INT_MAX, INT_MIN};
#define N_BAD_DOUBLES (sizeof BAD_DOUBLES / sizeof *BAD_DOUBLES)
#define N_BAD_INTS (sizeof BAD_INTS / sizeof *BAD_INTS)

/* the offset of the first 8-byte slot holding `value`'s bit pattern, or -1 */
static long find_double(const unsigned char *bytes, size_t size, double value)
{
    for (size_t offset = 0; offset + 8 <= size; offset += 8)
        if (!memcmp(bytes + offset, &value, 8)) return (long)offset;
    return -1;
}

#define LOAD(name) F.name = (name##TYPE *)dlsym(lib, #name); if (!F.name) { fprintf(stderr, "no %s\n", #name); return 2; }

int main(int argc, char **argv)
{
    if (argc != 8 && argc != 9) {
        fprintf(stderr, "usage: state_fuzz BINARY GUID SEED CASES N_REALS PROBE_VR PROBE_VALUE [FOREIGN]\n");
        return 2;
    }
    const char *guid = argv[2];
    rng_state = (uint64_t)atoll(argv[3]);
    long cases = atol(argv[4]);
    n_reals = atoi(argv[5]);
    long probe_vr = atol(argv[6]);
    double probe_value = atof(argv[7]);
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "%s\n", dlerror());
        return 2;
    }
    FUNCTIONS(LOAD)

    fmi2Component c = F.fmi2Instantiate("states", fmi2CoSimulation, guid, "file:///nonexistent", &callbacks,
                                        fmi2False, fmi2False);
    if (!c) {
        fprintf(stderr, "cannot instantiate\n");
        return 2;
    }
    /* a tolerance that is not positive and finite is refused; the instance stays instantiated */
    const double bad_tolerances[] = {-1.0, 0.0, NAN, INFINITY};
    long tolerance_refused = 0;
    for (int k = 0; k < 4; ++k) tolerance_refused += F.fmi2SetupExperiment(c, fmi2True, bad_tolerances[k], 0.0,
                                                                          fmi2False, 0.0) == fmi2Error;
    if (F.fmi2SetupExperiment(c, fmi2False, -1.0, 0.0, fmi2False, 0.0) != fmi2OK)
        failure("an undefined tolerance was not ignored", 0);
    if (F.fmi2EnterInitializationMode(c) != fmi2OK) failure("cannot enter initialization mode", 0);
    if (probe_vr >= 0) {
        fmi2ValueReference vr = (fmi2ValueReference)probe_vr;
        if (F.fmi2SetReal(c, &vr, 1, &probe_value) != fmi2OK) failure("cannot set the probe parameter", probe_vr);
    }
    if (F.fmi2ExitInitializationMode(c) > fmi2Warning) failure("cannot initialize", 0);
    for (int k = 0; k < 30; ++k) F.fmi2DoStep(c, 0.01 * k, 0.01, fmi2True);

    fmi2FMUstate good = NULL;
    size_t size = 0;
    if (F.fmi2GetFMUstate(c, &good) != fmi2OK || F.fmi2SerializedFMUstateSize(c, good, &size) != fmi2OK || !size) {
        fprintf(stderr, "cannot get the FMU state\n");
        return 2;
    }
    unsigned char *saved = (unsigned char *)malloc(size), *bytes = (unsigned char *)malloc(2 * size + 16);
    if (!saved || !bytes || F.fmi2SerializeFMUstate(c, good, (fmi2Byte *)saved, size) != fmi2OK) {
        fprintf(stderr, "cannot serialize the FMU state\n");
        return 2;
    }

    /* the state itself round-trips */
    long refused_before = refused;
    attempt(c, good, saved, size, 0);
    if (refused != refused_before) failure("the FMU's own serialized state was refused", 0);

    /* the probe parameter's slot: every bad value refused */
    long probe_refused = 0, probe_cases = 0;
    if (probe_vr >= 0) {
        long offset = find_double(saved, size, probe_value);
        if (offset < 0) failure("the probe value is not in the serialized state", probe_vr);
        for (size_t v = 0; offset >= 0 && v < N_BAD_DOUBLES; ++v) {
            memcpy(bytes, saved, size);
            put_double(bytes, (size_t)offset, BAD_DOUBLES[v]);
            long r = refused;
            attempt(c, good, bytes, size, 1);
            probe_refused += refused > r;
            ++probe_cases;
        }
    }

    /* single-slot corruptions: every slot, or the first and last CASES (where a state's scalars and small
       arrays lie, around its large buffers) and CASES random ones */
    size_t n_slots = size / 8, ends = (size_t)cases < n_slots / 2 ? (size_t)cases : n_slots / 2;
    long n = cases > 0 && 2 * ends < n_slots ? 3 * cases : (long)n_slots;
    for (long k = 0; k < n; ++k) {
        size_t slot = n == (long)n_slots ? (size_t)k
                      : (size_t)k < ends ? (size_t)k : (size_t)k < 2 * ends ? n_slots - 1 - ((size_t)k - ends)
                      : (size_t)below((int)n_slots);
        for (size_t v = 0; v < N_BAD_DOUBLES; ++v) {
            memcpy(bytes, saved, size);
            put_double(bytes, 8 * slot, BAD_DOUBLES[v]);
            attempt(c, good, bytes, size, 0);
        }
        for (size_t v = 0; v < N_BAD_INTS; ++v) {
            memcpy(bytes, saved, size);
            put_int(bytes, 8 * slot + 4 * (size_t)below(2), BAD_INTS[v]);
            attempt(c, good, bytes, size, 0);
        }
    }

    /* random bytes: all of them (refused: no header), all but the header (a half-random state), or a span */
    for (int k = 0; k < 20; ++k) {
        for (size_t i = 0; i < size; ++i) bytes[i] = (unsigned char)next_random();
        attempt(c, good, bytes, size, 1);
        memcpy(bytes, saved, 64 < size ? 64 : size);
        attempt(c, good, bytes, size, 0);
        memcpy(bytes, saved, size);
        size_t start = (size_t)below((int)size), length = 1 + (size_t)below(64);
        for (size_t i = start; i < size && i < start + length; ++i) bytes[i] = (unsigned char)next_random();
        attempt(c, good, bytes, size, 0);
    }

    /* truncated and oversized buffers, each in an allocation of exactly its size */
    const size_t sizes[] = {0, 1, 8, 64, size / 2, size - 1, size + 1, size + 8, 2 * size};
    for (size_t k = 0; k < sizeof sizes / sizeof *sizes; ++k) {
        unsigned char *buffer = (unsigned char *)malloc(sizes[k] ? sizes[k] : 1);
        if (!buffer) continue;
        for (size_t i = 0; i < sizes[k]; ++i) buffer[i] = i < size ? saved[i] : 0;
        attempt(c, good, buffer, sizes[k], 1);
        free(buffer);
    }

    /* another FMU's state */
    if (argc == 9) {
        FILE *file = fopen(argv[8], "rb");
        if (!file) {
            fprintf(stderr, "cannot read %s\n", argv[8]);
            return 2;
        }
        fseek(file, 0, SEEK_END);
        long length = ftell(file);
        fseek(file, 0, SEEK_SET);
        unsigned char *foreign = (unsigned char *)malloc(length > 0 ? (size_t)length : 1);
        if (!foreign || fread(foreign, 1, (size_t)length, file) != (size_t)length) return 2;
        fclose(file);
        attempt(c, good, foreign, (size_t)length, 1);
        free(foreign);
    }

    /* a pointer the instance did not hand out, made to look like its state: every FMU-state call refuses it
       and fmi2FreeFMUstate leaves it alone (freed here: a second free would be caught by valgrind) */
    unsigned char *lookalike = (unsigned char *)malloc(size);
    fmi2FMUstate foreign_state = lookalike;
    size_t told = 0;
    memcpy(lookalike, saved, size);
    long foreign_refused = 0;
    foreign_refused += F.fmi2FreeFMUstate(c, &foreign_state) == fmi2Error && foreign_state == lookalike;
    foreign_refused += F.fmi2SetFMUstate(c, foreign_state) == fmi2Error;
    foreign_refused += F.fmi2SerializedFMUstateSize(c, foreign_state, &told) == fmi2Error;
    foreign_refused += F.fmi2SerializeFMUstate(c, foreign_state, (fmi2Byte *)bytes, size) == fmi2Error;
    foreign_refused += F.fmi2GetFMUstate(c, &foreign_state) == fmi2Error && foreign_state == lookalike;
    foreign_refused += F.fmi2DeSerializeFMUstate(c, (const fmi2Byte *)saved, size, &foreign_state) == fmi2Error;
    free(lookalike);

    if (F.fmi2FreeFMUstate(c, &good) != fmi2OK || good) failure("the FMU's own state could not be freed", 0);
    F.fmi2FreeInstance(c);
    free(saved);
    free(bytes);
    dlclose(lib);
    printf("size %lu refused %ld accepted %ld steps %ld step_errors %ld probe_refused %ld probe_cases %ld "
           "foreign_refused %ld tolerance_refused %ld failures %ld\n", (unsigned long)size, refused, accepted, steps,
           step_errors, probe_refused, probe_cases, foreign_refused, tolerance_refused, failures);
    return failures ? 1 : 0;
}
