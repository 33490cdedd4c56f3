"""The components opfmu knows, by the name operator files and datasets record."""
from __future__ import annotations

from .component import Component
from .ieee1 import IEEE1
from .models import STANDARD_MODELS
from .models.subsystem import (SUBSYSTEM, SUBSYSTEM_DIP, SUBSYSTEM_LVG, SUBSYSTEM_LVG_DIP, SUBSYSTEM_MEM, SUBSYSTEM_PC,
                               SUBSYSTEM_PC_DIP, SUBSYSTEM_PC_LVG, SUBSYSTEM_PC_LVG_DIP, SUBSYSTEM_PC_MEM, SUBSYSTEM_UF)
from .sm4 import SM4

COMPONENTS = {c.name: c for c in (SM4, IEEE1, *STANDARD_MODELS.values(), SUBSYSTEM, SUBSYSTEM_PC, SUBSYSTEM_MEM,
                                   SUBSYSTEM_PC_MEM, SUBSYSTEM_UF, SUBSYSTEM_LVG, SUBSYSTEM_PC_LVG, SUBSYSTEM_DIP,
                                   SUBSYSTEM_PC_DIP, SUBSYSTEM_LVG_DIP, SUBSYSTEM_PC_LVG_DIP)}


def component(name) -> Component:
    """The component called `name`; ValueError naming the known ones otherwise."""
    try:
        return COMPONENTS[name]
    except (KeyError, TypeError):
        known = ", ".join(COMPONENTS)
        raise ValueError(f"unknown component {str(name)[:40]!r} (known: {known})") from None
