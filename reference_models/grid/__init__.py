"""Grid cases: the case object (`case`: network, load flow, units of devices wired by their ports,
events), the WSCC 9-bus case from its data files (`wscc9`), contingencies (`contingency`), the
monolithic reference simulation of a case (`monolithic`) and the result of a grid run (`result`)."""
