"""The standard dynamic models of PSS/E and ANDES as components (reference_models.component):
machines GENCLS, GENROU; exciters IEEEX1, EXDC2, EXST1, ESST3A, SEXS; governors TGOV1, TGOV1N,
IEEEG1; the stabiliser IEEEST. ANDES 2.0's model reference is the source of their equations
(docs/standard-models.md). `STANDARD_MODELS`: model name (ANDES' spelling) -> Component.

Machines give `operating_point(Vs, theta_vs, P, Q, params)` (the steady state from the load flow
and the Pm, Efd holding it); controllers give `initialise(output, inputs, params)` (the state at
rest giving an output and the set point holding it), each in its model's module.
"""
from .ac8b import AC8B
from .esac1a import ESAC1A
from .esd1 import ESD1
from .esdc1a import ESDC1A
from .esdc2a import ESDC2A
from .esst1a import ESST1A
from .esst3a import ESST3A
from .esst4b import ESST4B
from .exac1 import EXAC1
from .exac4 import EXAC4
from .exdc2 import EXDC2
from .exst1 import EXST1
from .fload import FLoad
from .gast import GAST
from .gencls import GENCLS
from .genrou import GENROU
from .hygov import HYGOV
from .hygov4 import HYGOV4
from .hygovdb import HYGOVDB
from .ieeeg1 import IEEEG1
from .ieesgo import IEESGO
from .ieeest import IEEEST
from .ieeet1 import IEEET1
from .ieeet3 import IEEET3
from .ieeevc import IEEEVC
from .ieeex1 import IEEEX1
from .motor import Motor3, Motor5
from .pll1 import PLL1
from .pll2 import PLL2
from .pvd1 import PVD1
from .reeca1 import REECA1
from .reecb1 import REECB1
from .regca1 import REGCA1
from .regcp1 import REGCP1
from .regf1 import REGF1
from .regf2 import REGF2
from .regf3 import REGF3
from .repca1 import REPCA1
from .sexs import SEXS
from .shaft5 import SHAFT5
from .shuntsw import SHUNTSW
from .st2cut import ST2CUT
from .static_generator import PV, SLACK
from .tg2 import TG2
from .tgov1 import TGOV1
from .tgov1n import TGOV1N
from .wtara1 import WTARA1
from .wtds import WTDS
from .wtdta1 import WTDTA1
from .wtpta1 import WTPTA1
from .wttqa1 import WTTQA1
from .zip import ZIP

STANDARD_MODELS = {
    "GENCLS": GENCLS, "GENROU": GENROU,
    "IEEEX1": IEEEX1, "EXDC2": EXDC2, "EXST1": EXST1, "ESST3A": ESST3A, "SEXS": SEXS,
    "EXAC1": EXAC1, "EXAC4": EXAC4, "ESAC1A": ESAC1A, "ESST1A": ESST1A, "ESST4B": ESST4B,
    "ESDC1A": ESDC1A, "ESDC2A": ESDC2A, "IEEET1": IEEET1, "IEEET3": IEEET3, "AC8B": AC8B,
    "TGOV1": TGOV1, "TGOV1N": TGOV1N, "IEEEG1": IEEEG1,
    "TG2": TG2, "GAST": GAST, "HYGOV": HYGOV, "HYGOV4": HYGOV4, "HYGOVDB": HYGOVDB, "IEESGO": IEESGO,
    "IEEEST": IEEEST, "ST2CUT": ST2CUT,
    "IEEEVC": IEEEVC,
    "FLoad": FLoad, "Motor5": Motor5, "Motor3": Motor3,
    "ZIP": ZIP,
    "PV": PV, "Slack": SLACK, "ShuntSw": SHUNTSW,
    "REGCA1": REGCA1, "REECA1": REECA1,
    "PLL1": PLL1, "PLL2": PLL2, "REGCP1": REGCP1, "REECB1": REECB1,
    "PVD1": PVD1, "ESD1": ESD1,
    "REPCA1": REPCA1,
    "WTDTA1": WTDTA1, "WTARA1": WTARA1, "WTPTA1": WTPTA1, "WTTQA1": WTTQA1,
    "WTDS": WTDS, "SHAFT5": SHAFT5,
    "REGF1": REGF1, "REGF2": REGF2, "REGF3": REGF3,
}
