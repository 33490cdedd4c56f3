"""ESDC1A: the IEEE 421.5 DC1A exciter: ESDC2A's equations (esdc2a.py) with constant regulator limits
VRMIN <= LA_y <= VRMAXc (VRMAXc = VRMAX, or 999 where VRMAX = 0), with their reset.

States  x = (LG_y, LL_x, LA_y, INT_y, WF_x) [pu] as ESDC2A (LG_y computed, not used)
Inputs  u = (Vt [pu] input voltage, Vref [pu] set point, Vss [pu] stabiliser signal)
Outputs y = (Efd [pu] field voltage = INT_y)

    vi = Vref - Vt - WF_y + Vss,  lead-lag (1 + s TC) / (1 + s TB),
    TA dLA_y/dt = KA LL_y - LA_y within [VRMIN, VRMAXc],
    TE dINT_y/dt = LA_y - KE INT_y - B (INT_y - A)^2 [INT_y >= A],  WF: s KF / (1 + s TF1) of INT_y

The differences from EXDC2 are ESDC2A's (esdc2a.py: no speed term, vi from Vt unfiltered, KF);
the limits are EXDC2's, constant.

The component is esdc2a.esdc_exciter's with constant limits (ESDC2A's: limits proportional to Vt).

As ANDES 2.0.0 means it, not as it runs: ANDES' ESDC1A derives from ESDC2A and replaces the limits
VRU = VRMAXc v, VRL = VRMIN v by the constants VRMAXc, VRMIN after its regulator lag has built its
anti-windup limiter from the old ones; the limiter keeps the dropped services, which are never
evaluated again (ss.ESDC1A.LA.lim.upper.v and .lower.v are the scalar 0.0). Its TDS.init then
fails (ieee14/ieee14_esdc1a.xlsx: TypeError in the limiter's adjustment of a limit below the
regulator's start, 1.97 pu > 0); with the limiter pointed at the new services (ss.ESDC1A.LA.lim.upper =
ss.ESDC1A.VRU, .lower = VRL) it initialises and runs with constant limits, the model this is, which
the tests compare with (tests/test_dc_exciters_and_compensator.py).
"""
from __future__ import annotations

from .esdc2a import ESDC2AParams, esdc_exciter

ESDC1AParams = ESDC2AParams

ESDC1A = esdc_exciter("esdc1a", "ESDC1A IEEE DC1A exciter (PSS/E, ANDES 2.0.0 as it means it)", False)
