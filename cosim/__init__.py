"""The co-simulation library: FMUs over fmpy (`fmu`), the FMU files of a case's devices (`fmus`), the
grid master (`master`), the monolithic and master runners (`runners`), critical clearing times
(`stability`), contingency screening (`screening`) and result files (`outputs`).

Layer: above `fmu_export`, below the command line (`opfmu`)."""
