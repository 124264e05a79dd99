"""Light estimation from fitted bodies and segmented shadows (thesis ch. 5, §5.4-5.7).

:func:`estimate_light` finds the point or directional light(s) whose shadows of the given bodies
best match the observed shadows (eq. 5.9: coarse grid of 288, 7×7×7 refinements, emcee
posterior); :func:`estimate_session_light` does it for a session and writes ``light/light.json``;
:func:`load_light` reads it back.
"""

from studio.light.estimate import LightError, LightEstimate, estimate_light
from studio.light.objective import ShadowFrame, ShadowObjective, predicted_shadows
from studio.light.session import estimate_session_light, light_uncertainty, load_light

__all__ = ["LightError", "LightEstimate", "ShadowFrame", "ShadowObjective", "estimate_light",
           "estimate_session_light", "light_uncertainty", "load_light", "predicted_shadows"]
