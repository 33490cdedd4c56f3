/* Loads an FMI 2.0 CS binary, and `rounds` times: instantiates, runs and frees it `cycles` times
   (with FMU states taken, serialised and freed), then unloads it. Run under valgrind to find leaks.
   usage: lifecycle_harness BINARY GUID CYCLES ROUNDS */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env; (void)name; (void)status; (void)category; (void)message;
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)dlsym(lib, #name); if (!name) return 2;

int main(int argc, char **argv)
{
    if (argc != 5) return 2;
    int cycles = atoi(argv[3]), rounds = atoi(argv[4]);
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    for (int r = 0; r < rounds; ++r) {
        void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
        if (!lib) return 2;
        LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
        LOAD(fmi2ExitInitializationMode) LOAD(fmi2SetReal) LOAD(fmi2DoStep) LOAD(fmi2GetReal)
        LOAD(fmi2GetFMUstate) LOAD(fmi2SerializedFMUstateSize) LOAD(fmi2SerializeFMUstate)
        LOAD(fmi2DeSerializeFMUstate) LOAD(fmi2FreeFMUstate) LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)
        for (int c = 0; c < cycles; ++c) {
            fmi2Component fmu = fmi2Instantiate("leak", fmi2CoSimulation, argv[2], "", &callbacks, fmi2False, fmi2False);
            if (!fmu) return 1;
            /* SM4's value references (fmu_export/variables.py): inputs Vs, theta_vs, Pm, Efd 0-3, states 4-7 */
            fmi2ValueReference vr[4] = {0, 1, 2, 3};
            fmi2Real u[4] = {0.95, 0.1, 0.7048, 1.08}, x[4];
            fmi2ValueReference states[4] = {4, 5, 6, 7};
            fmi2SetupExperiment(fmu, fmi2False, 0.0, 0.0, fmi2False, 0.0);
            fmi2EnterInitializationMode(fmu);
            fmi2ExitInitializationMode(fmu);
            fmi2SetReal(fmu, vr, 4, u);
            for (int k = 0; k < 3; ++k)
                if (fmi2DoStep(fmu, 0.01 * k, 0.01, fmi2True) != fmi2OK) return 1;
            fmi2GetReal(fmu, states, 4, x);
            fmi2DoStep(fmu, 1.0, -1.0, fmi2True); /* a bad call: error path */
            fmi2FMUstate state = NULL, copy = NULL;
            size_t size = 0;
            fmi2GetFMUstate(fmu, &state);
            fmi2SerializedFMUstateSize(fmu, state, &size);
            fmi2Byte *bytes = malloc(size);
            fmi2SerializeFMUstate(fmu, state, bytes, size);
            fmi2DeSerializeFMUstate(fmu, bytes, size, &copy);
            free(bytes);
            fmi2FreeFMUstate(fmu, &state);
            fmi2FreeFMUstate(fmu, &copy);
            fmi2Terminate(fmu);
            fmi2FreeInstance(fmu);
        }
        dlclose(lib);
    }
    return 0;
}
