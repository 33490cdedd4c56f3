"""The co-simulation library: one FMU wrapper for FMI 2.0 and 3.0 over fmpy (`fmu`), the FMU kinds
and files of a case's units (`fmus`), the grid master (`master`), a unit on a prescribed bus
(`bus_driven`), the monolithic and master runners (`runners`), critical clearing times
(`stability`), contingency screening (`screening`) and result files (`outputs`).

Layer: above `fmu_export`, below the command line (`opfmu`); the cases it runs are at the ground
(`reference_models.grid`).
"""
