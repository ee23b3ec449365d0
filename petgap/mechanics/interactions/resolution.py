"""Whether a grid resolves an interaction law.

Two lengths must span pixels for the discrete problem to represent the
continuum one: the law's length scale itself (its stress changes over it), and
the adhesive process zone at a contact edge, where the attractive stress acts.
For a cohesive law of strength ``sigma0`` (its largest attractive stress) the
zone length is of order ``l_pz = E* w / sigma0^2`` (Maugis, J. Colloid
Interface Sci. 150 (1992) 243; Müser, Beilstein J. Nanotechnol. 5 (2014) 419,
on pixel resolution of adhesive BEM): ``E* rho^2 / w`` for the exponential.
With ``l_pz`` below a couple of pixels the edge is unresolved and the solution
depends on the grid (and is prone to lattice trapping).  Each law gives both
lengths (``length_scale``, ``process_zone``) and how its messages name them.
"""
import warnings


class ResolutionError(ValueError):
    """The grid does not resolve the interaction (raised when the scene asks to refuse)."""


class ResolutionWarning(UserWarning):
    """The grid does not resolve the interaction."""


#: Smallest resolved interaction range, in pixels.
MIN_RANGE_PIXELS = 1.0
#: Smallest resolved adhesive process zone, in pixels.
MIN_PROCESS_ZONE_PIXELS = 2.0


def resolution_report(interaction, pixel_size, contact_modulus):
    """How well a grid resolves an interaction law (see the module docstring).

    Returns
    -------
    dict
        ``range_pixels``, ``process_zone``, ``process_zone_pixels``, ``resolved``
        and a ``message`` that states the numbers and the rule.
    """
    if not interaction.adhesive:
        return {"resolved": True, "message": "hard wall: nothing to resolve"}
    length, symbol, w = interaction.length_scale, interaction.LENGTH, interaction.work
    range_px = length / pixel_size
    zone = interaction.process_zone(contact_modulus)
    zone_px = zone / pixel_size
    problems = []
    if range_px < MIN_RANGE_PIXELS:
        problems.append(f"range {symbol} = {length:g} is {range_px:.3g} pixels (rule: {symbol} >= "
                        f"{MIN_RANGE_PIXELS:g} a0, a0 = {pixel_size:g})")
    if zone_px < MIN_PROCESS_ZONE_PIXELS:
        problems.append(f"process zone {interaction.ZONE} = {zone:.3g} is {zone_px:.3g} pixels "
                        f"(rule: >= {MIN_PROCESS_ZONE_PIXELS:g} a0; E* = {contact_modulus:g}, "
                        f"w = {w:g})")
    message = ("interaction not resolved by the grid: " + "; ".join(problems) +
               f". Refine the grid or lengthen {symbol}" if problems else
               f"resolved: {symbol} = {range_px:.3g} a0, process zone = {zone_px:.3g} a0")
    return {"range_pixels": range_px, "process_zone": zone, "process_zone_pixels": zone_px,
            "resolved": not problems, "message": message}


def check_resolution(interaction, pixel_size, contact_modulus, mode="warn"):
    """Warn, refuse or stay silent (``mode``) when the interaction is unresolved.

    Deterministic, so every rank reaches the same verdict and raises together.
    """
    if mode not in ("warn", "error", "off"):
        raise ValueError(f"resolution check mode {mode!r} is not one of warn, error, off")
    report = resolution_report(interaction, pixel_size, contact_modulus)
    if not report["resolved"] and mode == "error":
        raise ResolutionError(report["message"])
    if not report["resolved"] and mode == "warn":
        warnings.warn(report["message"], ResolutionWarning, stacklevel=2)
    return report
