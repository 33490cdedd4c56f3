"""The step mirror (fmu_export.step_mirror) of a surrogate FMU evaluated on the FMU's own compiled
kernel instead of onnxruntime, so that what is left between the mirror and the FMU is round-off."""
import ctypes

import numpy as np


def on_the_fmus_kernel(mirror, unzipped):
    """The StepMirror `mirror` of the FMU unzipped = (directory, model description), with its network
    evaluated by the FMU's compiled kernel (opfmu_operator, in double) instead of onnxruntime (float32)."""
    library = ctypes.CDLL(f"{unzipped[0]}/binaries/linux64/{unzipped[1].coSimulation.modelIdentifier}.so")
    double_p = ctypes.POINTER(ctypes.c_double)
    library.opfmu_operator.argtypes = [double_p, double_p, ctypes.c_double, double_p]

    def network(x0_f, sensors_f, tau):
        x0, u, out = np.array(x0_f, np.float64), np.ascontiguousarray(sensors_f, np.float64), np.zeros(len(x0_f))
        library.opfmu_operator(x0.ctypes.data_as(double_p), u.ctypes.data_as(double_p), float(tau),
                               out.ctypes.data_as(double_p))
        return out

    mirror.network = network
    return mirror
