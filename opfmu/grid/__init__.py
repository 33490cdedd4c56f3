"""Grid co-simulation: one FMU per machine and exciter, coupled through a network solved at every
communication point (master.py), with transient-stability tools on top (stability.py, screening.py)."""
