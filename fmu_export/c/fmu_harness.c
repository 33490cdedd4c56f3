/* fmu_harness: runs a script of FMI calls on an FMI 2.0 (or, with -3, FMI 3.0) co-simulation binary
   and writes every result to a text file, so that one script can run on the linux64 binary natively
   and on the win64 binary under wine and the two outputs can be compared number for number.

   Usage: fmu_harness [-3] <binary> <script> <output>
   Exit code 0: the script ran to the end (FMI calls that fail are recorded, not harness failures);
   2: usage error, missing file, binary that cannot be loaded, missing FMI function or malformed
   script line (a one-line reason goes to stderr).

   Doubles, in the script and the output, are the 16 lowercase hex digits of their IEEE-754 bit
   pattern (1.0 is 3ff0000000000000), converted with integer operations only; integers are decimal.
   Each command writes one line "<command> <status> [values...]"; values follow only where the FMI
   call defines them (status OK or warning; for an FMI 3 step also discard). Logger messages are
   lines "log <status> <category> <message>". Paths are passed to the binary exactly as given. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef _WIN32
#include <windows.h>
#else
#include <dlfcn.h>
#endif

#include "fmi2FunctionTypes.h"
#include "fmi3FunctionTypes.h"

#define MAX_LINE 65536  /* longest script line, newline included */
#define MAX_TOKENS 4096 /* most tokens in one line */
#define N_SLOTS 8       /* FMU state slots of savestate and friends */

typedef void (*Proc)(void); /* a function of the binary before it is cast to its FMI type */

/* ---- loading the binary ---- */

#ifdef _WIN32
static HMODULE library;
static int open_library(const char *path) { return (library = LoadLibraryA(path)) != NULL; }
static Proc find(const char *name) { return (Proc)GetProcAddress(library, name); }
static void close_library(void) { FreeLibrary(library); }
static const char *load_error(void)
{
    static char reason[64];
    snprintf(reason, sizeof reason, "Windows error %lu", (unsigned long)GetLastError());
    return reason;
}
#else
static void *library;
static int open_library(const char *path) { return (library = dlopen(path, RTLD_NOW | RTLD_LOCAL)) != NULL; }
static Proc find(const char *name)
{
    void *address = dlsym(library, name);
    Proc function;
    memcpy(&function, &address, sizeof function); /* object pointer to function pointer, as POSIX allows */
    return function;
}
static void close_library(void) { dlclose(library); }
static const char *load_error(void) { return dlerror(); }
#endif

static struct {
    fmi2InstantiateTYPE *Instantiate;
    fmi2FreeInstanceTYPE *FreeInstance;
    fmi2SetDebugLoggingTYPE *SetDebugLogging;
    fmi2SetupExperimentTYPE *SetupExperiment;
    fmi2EnterInitializationModeTYPE *EnterInitializationMode;
    fmi2ExitInitializationModeTYPE *ExitInitializationMode;
    fmi2TerminateTYPE *Terminate;
    fmi2ResetTYPE *Reset;
    fmi2SetRealTYPE *SetReal;
    fmi2GetRealTYPE *GetReal;
    fmi2GetBooleanTYPE *GetBoolean;
    fmi2SetRealInputDerivativesTYPE *SetRealInputDerivatives;
    fmi2DoStepTYPE *DoStep;
    fmi2GetRealStatusTYPE *GetRealStatus;
    fmi2GetDirectionalDerivativeTYPE *GetDirectionalDerivative;
    fmi2GetFMUstateTYPE *GetFMUstate;
    fmi2SetFMUstateTYPE *SetFMUstate;
    fmi2FreeFMUstateTYPE *FreeFMUstate;
    fmi2SerializedFMUstateSizeTYPE *SerializedFMUstateSize;
    fmi2SerializeFMUstateTYPE *SerializeFMUstate;
    fmi2DeSerializeFMUstateTYPE *DeSerializeFMUstate;
} f2;

static struct {
    fmi3InstantiateCoSimulationTYPE *InstantiateCoSimulation;
    fmi3FreeInstanceTYPE *FreeInstance;
    fmi3SetDebugLoggingTYPE *SetDebugLogging;
    fmi3EnterInitializationModeTYPE *EnterInitializationMode;
    fmi3ExitInitializationModeTYPE *ExitInitializationMode;
    fmi3TerminateTYPE *Terminate;
    fmi3ResetTYPE *Reset;
    fmi3SetFloat64TYPE *SetFloat64;
    fmi3GetFloat64TYPE *GetFloat64;
    fmi3GetBooleanTYPE *GetBoolean;
    fmi3DoStepTYPE *DoStep;
    fmi3GetDirectionalDerivativeTYPE *GetDirectionalDerivative;
    fmi3GetFMUStateTYPE *GetFMUState;
    fmi3SetFMUStateTYPE *SetFMUState;
    fmi3FreeFMUStateTYPE *FreeFMUState;
    fmi3SerializedFMUStateSizeTYPE *SerializedFMUStateSize;
    fmi3SerializeFMUStateTYPE *SerializeFMUState;
    fmi3DeserializeFMUStateTYPE *DeserializeFMUState;
} f3;

static int missing(const char *name)
{
    fprintf(stderr, "fmu_harness: the binary does not export %s\n", name);
    return 0;
}

/* looks up the function prefix##name into table.name; returns 0 from the caller if it is missing */
#define LOAD(table, prefix, name) \
    if (!(table.name = (prefix##name##TYPE *)find(#prefix #name))) return missing(#prefix #name)

static int load2(void)
{
    LOAD(f2, fmi2, Instantiate);
    LOAD(f2, fmi2, FreeInstance);
    LOAD(f2, fmi2, SetDebugLogging);
    LOAD(f2, fmi2, SetupExperiment);
    LOAD(f2, fmi2, EnterInitializationMode);
    LOAD(f2, fmi2, ExitInitializationMode);
    LOAD(f2, fmi2, Terminate);
    LOAD(f2, fmi2, Reset);
    LOAD(f2, fmi2, SetReal);
    LOAD(f2, fmi2, GetReal);
    LOAD(f2, fmi2, GetBoolean);
    LOAD(f2, fmi2, SetRealInputDerivatives);
    LOAD(f2, fmi2, DoStep);
    LOAD(f2, fmi2, GetRealStatus);
    LOAD(f2, fmi2, GetDirectionalDerivative);
    LOAD(f2, fmi2, GetFMUstate);
    LOAD(f2, fmi2, SetFMUstate);
    LOAD(f2, fmi2, FreeFMUstate);
    LOAD(f2, fmi2, SerializedFMUstateSize);
    LOAD(f2, fmi2, SerializeFMUstate);
    LOAD(f2, fmi2, DeSerializeFMUstate);
    return 1;
}

static int load3(void)
{
    LOAD(f3, fmi3, InstantiateCoSimulation);
    LOAD(f3, fmi3, FreeInstance);
    LOAD(f3, fmi3, SetDebugLogging);
    LOAD(f3, fmi3, EnterInitializationMode);
    LOAD(f3, fmi3, ExitInitializationMode);
    LOAD(f3, fmi3, Terminate);
    LOAD(f3, fmi3, Reset);
    LOAD(f3, fmi3, SetFloat64);
    LOAD(f3, fmi3, GetFloat64);
    LOAD(f3, fmi3, GetBoolean);
    LOAD(f3, fmi3, DoStep);
    LOAD(f3, fmi3, GetDirectionalDerivative);
    LOAD(f3, fmi3, GetFMUState);
    LOAD(f3, fmi3, SetFMUState);
    LOAD(f3, fmi3, FreeFMUState);
    LOAD(f3, fmi3, SerializedFMUStateSize);
    LOAD(f3, fmi3, SerializeFMUState);
    LOAD(f3, fmi3, DeserializeFMUState);
    return 1;
}

/* ---- output ---- */

static FILE *out;

static void put_double(double value)
{
    char digits[17];
    uint64_t bits;
    memcpy(&bits, &value, sizeof bits);
    for (int i = 15; i >= 0; --i, bits >>= 4) digits[i] = "0123456789abcdef"[bits & 15u];
    digits[16] = '\0';
    fprintf(out, " %s", digits);
}

static void put_size(size_t value)
{
    char digits[24];
    int i = (int)sizeof digits - 1;
    digits[i] = '\0';
    do digits[--i] = (char)('0' + value % 10); while (value /= 10);
    fprintf(out, " %s", digits + i);
}

/* ends an output line and flushes it, so that a crash of the FMU keeps everything before it */
static void end_line(void)
{
    fputc('\n', out);
    fflush(out);
}

/* a logger message as its own line; line breaks inside the message become spaces */
static void write_log(int status, const char *category, const char *message)
{
    fprintf(out, "log %d %s ", status, category ? category : "-");
    for (const char *c = message ? message : ""; *c; ++c) fputc(*c == '\n' || *c == '\r' ? ' ' : *c, out);
    end_line();
}

/* FMI 2's logger is variadic; the message is written as it is, never used as a format */
static void logger2(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                    fmi2String message, ...)
{
    (void)env;
    (void)name;
    write_log((int)status, category, message);
}

static void logger3(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    (void)env;
    write_log((int)status, category, message);
}

/* ---- parsing ---- */

static int hex_digit(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* exactly 16 hex digits into the double with that bit pattern */
static int parse_double(const char *s, double *value)
{
    uint64_t bits = 0;
    for (int i = 0; i < 16; ++i) {
        int digit = hex_digit(s[i]);
        if (digit < 0) return 0;
        bits = bits << 4 | (uint64_t)digit;
    }
    if (s[16]) return 0;
    memcpy(value, &bits, sizeof bits);
    return 1;
}

/* a decimal number from 0 to max */
static int parse_uint(const char *s, uint32_t max, uint32_t *value)
{
    uint64_t v = 0;
    if (!*s) return 0;
    for (; *s; ++s) {
        if (*s < '0' || *s > '9') return 0;
        v = v * 10 + (uint64_t)(*s - '0');
        if (v > max) return 0;
    }
    *value = (uint32_t)v;
    return 1;
}

/* splits a line at single spaces; returns the token count, -1 for an empty token or too many */
static int split(char *line, char **tokens)
{
    int n = 0;
    for (char *s = line;;) {
        char *space = strchr(s, ' ');
        if (n == MAX_TOKENS) return -1;
        if (space) *space = '\0';
        if (!*s) return -1;
        tokens[n++] = s;
        if (!space) return n;
        s = space + 1;
    }
}

/* ---- running the script ---- */

static int fmi3;               /* 1: the binary is FMI 3.0 */
static void *instance;         /* fmi2Component or fmi3Instance; NULL if none */
static void *slots[N_SLOTS];   /* fmi2FMUstate or fmi3FMUState */
static double start_time;      /* FMI 3: the start time of setup, used by enter_init */
static fmi2CallbackFunctions callbacks2; /* must outlive the instance */

static fmi2ValueReference vr2[MAX_TOKENS], known2[MAX_TOKENS];
static fmi3ValueReference vr3[MAX_TOKENS], known3[MAX_TOKENS];
static double values[MAX_TOKENS], seeds[MAX_TOKENS];
static fmi2Integer orders[MAX_TOKENS];
static fmi2Boolean booleans2[MAX_TOKENS];
static fmi3Boolean booleans3[MAX_TOKENS];

/* n value references into vr2 and vr3 (or known2 and known3) */
static int parse_vrs(char **tokens, int n, fmi2ValueReference *a2, fmi3ValueReference *a3)
{
    uint32_t vr;
    for (int i = 0; i < n; ++i) {
        if (!parse_uint(tokens[i], UINT32_MAX, &vr)) return 0;
        a2[i] = (fmi2ValueReference)vr;
        a3[i] = (fmi3ValueReference)vr;
    }
    return 1;
}

/* "vr value vr value ..." into vr2, vr3 and values */
static int parse_pairs(char **tokens, int n)
{
    for (int i = 0; i < n; ++i) {
        uint32_t vr;
        if (!parse_uint(tokens[2 * i], UINT32_MAX, &vr) || !parse_double(tokens[2 * i + 1], &values[i])) return 0;
        vr2[i] = (fmi2ValueReference)vr;
        vr3[i] = (fmi3ValueReference)vr;
    }
    return 1;
}

static int worse(int a, int b) { return a > b ? a : b; }

/* FreeFMUstate of every filled slot */
static void free_slots(void)
{
    for (int k = 0; k < N_SLOTS; ++k) {
        if (!slots[k]) continue;
        if (fmi3) f3.FreeFMUState(instance, &slots[k]);
        else f2.FreeFMUstate(instance, &slots[k]);
        slots[k] = NULL;
    }
}

/* the states, then the instance */
static void free_instance(void)
{
    free_slots();
    if (fmi3) f3.FreeInstance(instance);
    else f2.FreeInstance(instance);
    instance = NULL;
}

/* runs one command of n tokens and writes its output line; returns why it is malformed, or NULL */
static const char *run_command(char **tok, int n)
{
    const char *cmd = tok[0];
    int status = 0, shown = 0; /* shown: the number of values to write after the status */
    uint32_t k = 0;
    double t, h;

    if (!strcmp(cmd, "instantiate")) {
        if (n != 4) return "instantiate takes <name> <guid> <resource>";
        if (instance) return "an instance exists already (free it first)";
        const char *resource = strcmp(tok[3], "-") ? tok[3] : NULL;
        if (fmi3) {
            instance = f3.InstantiateCoSimulation(tok[1], tok[2], resource, fmi3False, fmi3False, fmi3False,
                                                  fmi3False, NULL, 0, out, logger3, NULL);
        } else {
            callbacks2.logger = logger2;
            callbacks2.allocateMemory = calloc;
            callbacks2.freeMemory = free;
            callbacks2.stepFinished = NULL;
            callbacks2.componentEnvironment = out;
            instance = f2.Instantiate(tok[1], fmi2CoSimulation, tok[2], resource, &callbacks2, fmi2False, fmi2False);
        }
        start_time = 0.0;
        fprintf(out, "instantiate %s", instance ? "ok" : "null");
        end_line();
        return NULL;
    }
    if (!strcmp(cmd, "free")) {
        if (n != 1) return "free takes no arguments";
        free_instance();
        fprintf(out, "free");
        end_line();
        return NULL;
    }

    if (!strcmp(cmd, "debug")) {
        if (n != 2 || !parse_uint(tok[1], 1, &k)) return "debug takes 0 or 1";
        status = fmi3 ? (int)f3.SetDebugLogging(instance, k ? fmi3True : fmi3False, 0, NULL)
                      : (int)f2.SetDebugLogging(instance, k ? fmi2True : fmi2False, 0, NULL);
    } else if (!strcmp(cmd, "setup")) {
        if (n != 2 || !parse_double(tok[1], &t)) return "setup takes <start>";
        if (fmi3) start_time = t; /* FMI 3 gets it with fmi3EnterInitializationMode */
        else status = (int)f2.SetupExperiment(instance, fmi2False, 0.0, t, fmi2False, 0.0);
    } else if (!strcmp(cmd, "enter_init")) {
        if (n != 1) return "enter_init takes no arguments";
        status = fmi3 ? (int)f3.EnterInitializationMode(instance, fmi3False, 0.0, start_time, fmi3False, 0.0)
                      : (int)f2.EnterInitializationMode(instance);
    } else if (!strcmp(cmd, "exit_init")) {
        if (n != 1) return "exit_init takes no arguments";
        status = fmi3 ? (int)f3.ExitInitializationMode(instance) : (int)f2.ExitInitializationMode(instance);
    } else if (!strcmp(cmd, "terminate")) {
        if (n != 1) return "terminate takes no arguments";
        status = fmi3 ? (int)f3.Terminate(instance) : (int)f2.Terminate(instance);
    } else if (!strcmp(cmd, "reset")) {
        if (n != 1) return "reset takes no arguments";
        status = fmi3 ? (int)f3.Reset(instance) : (int)f2.Reset(instance);
        start_time = 0.0;
    } else if (!strcmp(cmd, "set")) {
        int m = (n - 1) / 2;
        if (n < 3 || n % 2 == 0 || !parse_pairs(tok + 1, m)) return "set takes <vr> <value> pairs";
        status = fmi3 ? (int)f3.SetFloat64(instance, vr3, (size_t)m, values, (size_t)m)
                      : (int)f2.SetReal(instance, vr2, (size_t)m, values);
    } else if (!strcmp(cmd, "setder")) {
        int m = (n - 1) / 2;
        if (n < 3 || n % 2 == 0 || !parse_pairs(tok + 1, m)) return "setder takes <vr> <value> pairs";
        for (int i = 0; i < m; ++i) orders[i] = 1;
        status = fmi3 ? (int)fmi3Error /* FMI 3 co-simulation has no input derivatives */
                      : (int)f2.SetRealInputDerivatives(instance, vr2, (size_t)m, orders, values);
    } else if (!strcmp(cmd, "step")) {
        if (n != 3 || !parse_double(tok[1], &t) || !parse_double(tok[2], &h)) return "step takes <t> <h>";
        if (fmi3) {
            fmi3Boolean event = fmi3False, terminate = fmi3False, early = fmi3False;
            values[0] = 0.0;
            status = (int)f3.DoStep(instance, t, h, fmi3True, &event, &terminate, &early, &values[0]);
            shown = status <= (int)fmi3Discard ? 1 : 0; /* the last successful time */
        } else {
            status = (int)f2.DoStep(instance, t, h, fmi2True);
        }
    } else if (!strcmp(cmd, "lasttime")) {
        if (n != 1) return "lasttime takes no arguments";
        values[0] = 0.0;
        status = fmi3 ? (int)fmi3Error /* FMI 3: the time comes with the step */
                      : (int)f2.GetRealStatus(instance, fmi2LastSuccessfulTime, &values[0]);
        shown = status <= 1 ? 1 : 0;
    } else if (!strcmp(cmd, "get")) {
        int m = n - 1;
        if (m < 1 || !parse_vrs(tok + 1, m, vr2, vr3)) return "get takes value references";
        memset(values, 0, sizeof values);
        status = fmi3 ? (int)f3.GetFloat64(instance, vr3, (size_t)m, values, (size_t)m)
                      : (int)f2.GetReal(instance, vr2, (size_t)m, values);
        shown = status <= 1 ? m : 0;
    } else if (!strcmp(cmd, "getbool")) {
        int m = n - 1;
        if (m < 1 || !parse_vrs(tok + 1, m, vr2, vr3)) return "getbool takes value references";
        memset(booleans2, 0, sizeof booleans2);
        memset(booleans3, 0, sizeof booleans3);
        status = fmi3 ? (int)f3.GetBoolean(instance, vr3, (size_t)m, booleans3, (size_t)m)
                      : (int)f2.GetBoolean(instance, vr2, (size_t)m, booleans2);
        fprintf(out, "%s %d", cmd, status);
        for (int i = 0; status <= 1 && i < m; ++i) fprintf(out, " %d", fmi3 ? booleans3[i] != 0 : booleans2[i] != 0);
        end_line();
        return NULL;
    } else if (!strcmp(cmd, "dd")) {
        uint32_t nu, nk;
        if (n < 3 || !parse_uint(tok[1], MAX_TOKENS, &nu) || (int)nu + 3 > n ||
            !parse_uint(tok[2 + nu], MAX_TOKENS, &nk) || n != 3 + (int)nu + 2 * (int)nk ||
            !parse_vrs(tok + 2, (int)nu, vr2, vr3) || !parse_vrs(tok + 3 + nu, (int)nk, known2, known3))
            return "dd takes <n_unknown> <vr>... <n_known> <vr>... <seed>...";
        for (uint32_t i = 0; i < nk; ++i)
            if (!parse_double(tok[3 + nu + nk + i], &seeds[i])) return "dd: a seed is not 16 hex digits";
        memset(values, 0, sizeof values);
        status = fmi3 ? (int)f3.GetDirectionalDerivative(instance, vr3, nu, known3, nk, seeds, nk, values, nu)
                      : (int)f2.GetDirectionalDerivative(instance, vr2, nu, known2, nk, seeds, values);
        shown = status <= 1 ? (int)nu : 0;
    } else if (!strcmp(cmd, "savestate") || !strcmp(cmd, "loadstate") || !strcmp(cmd, "freestate")) {
        if (n != 2 || !parse_uint(tok[1], N_SLOTS - 1, &k)) return "state commands take a slot 0..7";
        if (cmd[0] == 's') {
            status = fmi3 ? (int)f3.GetFMUState(instance, &slots[k]) : (int)f2.GetFMUstate(instance, &slots[k]);
        } else if (cmd[0] == 'l') {
            status = fmi3 ? (int)f3.SetFMUState(instance, slots[k]) : (int)f2.SetFMUstate(instance, slots[k]);
        } else {
            status = fmi3 ? (int)f3.FreeFMUState(instance, &slots[k]) : (int)f2.FreeFMUstate(instance, &slots[k]);
            slots[k] = NULL;
        }
    } else if (!strcmp(cmd, "serialize")) {
        size_t size = 0;
        void *bytes = NULL;
        if (n != 2 || !parse_uint(tok[1], N_SLOTS - 1, &k)) return "serialize takes a slot 0..7";
        /* the size, the bytes, free the state, then the state again from the bytes */
        status = fmi3 ? (int)f3.SerializedFMUStateSize(instance, slots[k], &size)
                      : (int)f2.SerializedFMUstateSize(instance, slots[k], &size);
        if (status <= 1) {
            if (!(bytes = malloc(size ? size : 1))) {
                fprintf(stderr, "fmu_harness: out of memory for a serialized state\n");
                exit(2);
            }
            status = worse(status, fmi3 ? (int)f3.SerializeFMUState(instance, slots[k], (fmi3Byte *)bytes, size)
                                        : (int)f2.SerializeFMUstate(instance, slots[k], (fmi2Byte *)bytes, size));
        }
        if (status <= 1) {
            status = worse(status, fmi3 ? (int)f3.FreeFMUState(instance, &slots[k])
                                        : (int)f2.FreeFMUstate(instance, &slots[k]));
            slots[k] = NULL;
            status = worse(status, fmi3 ? (int)f3.DeserializeFMUState(instance, (fmi3Byte *)bytes, size, &slots[k])
                                        : (int)f2.DeSerializeFMUstate(instance, (fmi2Byte *)bytes, size, &slots[k]));
        }
        free(bytes);
        fprintf(out, "%s %d", cmd, status);
        if (status <= 1) put_size(size);
        end_line();
        return NULL;
    } else {
        return "unknown command";
    }

    fprintf(out, "%s %d", cmd, status);
    for (int i = 0; i < shown; ++i) put_double(values[i]);
    end_line();
    return NULL;
}

/* runs the script to its end; returns the exit code */
static int run_script(FILE *script)
{
    static char line[MAX_LINE];
    static char *tokens[MAX_TOKENS];
    const char *reason = NULL;
    long number = 0;
    while (fgets(line, sizeof line, script)) {
        size_t length = strlen(line);
        ++number;
        if (length > 0 && line[length - 1] == '\n') line[--length] = '\0';
        else if (!feof(script)) reason = "line too long";
        if (length > 0 && line[length - 1] == '\r') line[--length] = '\0'; /* a script with CR LF line ends */
        if (!reason && (line[0] == '#' || line[0] == '\0')) continue;  /* comments and empty lines */
        if (!reason) {
            int n = split(line, tokens);
            reason = n < 0 ? "empty token (tokens are separated by single spaces) or too many tokens"
                           : run_command(tokens, n);
        }
        if (reason) {
            fprintf(out, "bad %ld", number);
            end_line();
            fprintf(stderr, "fmu_harness: script line %ld: %s\n", number, reason);
            return 2;
        }
    }
    return 0;
}

int main(int argc, char **argv)
{
    int first = 1, rc;
    if (argc > 1 && !strcmp(argv[1], "-3")) {
        fmi3 = 1;
        first = 2;
    }
    if (argc - first != 3) {
        fprintf(stderr, "usage: fmu_harness [-3] <binary> <script> <output>\n");
        return 2;
    }
    const char *binary = argv[first], *script_path = argv[first + 1], *output_path = argv[first + 2];
#ifdef _WIN32
    SetErrorMode(SEM_FAILCRITICALERRORS | SEM_NOGPFAULTERRORBOX); /* no dialog boxes: fail or crash quietly */
#endif
    FILE *script = fopen(script_path, "rb");
    if (!script) {
        fprintf(stderr, "fmu_harness: cannot open the script %s\n", script_path);
        return 2;
    }
    if (!open_library(binary)) {
        fprintf(stderr, "fmu_harness: cannot load %s: %s\n", binary, load_error());
        fclose(script);
        return 2;
    }
    if (!(fmi3 ? load3() : load2())) {
        fclose(script);
        close_library();
        return 2;
    }
    out = fopen(output_path, "wb"); /* binary mode: LF line ends on every platform */
    if (!out) {
        fprintf(stderr, "fmu_harness: cannot write %s\n", output_path);
        fclose(script);
        close_library();
        return 2;
    }
    rc = run_script(script);
    if (instance) free_instance(); /* what the script left, not recorded */
    fclose(script);
    fclose(out);
    close_library();
    return rc;
}
