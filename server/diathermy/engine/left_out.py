"""Whether an effect the scene leaves out would have acted.

A scene simulates only the effects it calls for (DESIGN.md), and that is exact only while the
state stays where the left-out effects do nothing: without ``vaporization`` the tissue must stay
below boiling (above it the EOS would take latent heat and raise a vapor pressure), without
``mechanics`` the vapor pressure must stay at ambient, without ``dissection`` the strain energy
must stay below the damage threshold kappa, and without ``thermal`` no Joule heat may be
delivered. Each step report names the left-out effects whose threshold the state passed, so a
scene that outgrows its effects says so instead of reporting, say, a coagulation lesion at
2000 K. ``desiccation`` and ``thermal_damage`` have no such threshold (a conductivity law that
acts from the first kelvin, a diagnostic that feeds nothing back), so they are not checked.
"""

from __future__ import annotations

from collections.abc import Collection

from diathermy.physics.materials import Tissue


def left_out_acting(
    effects: Collection[str],
    tissue: Tissue,
    *,
    max_temperature_k: float,
    max_pressure_pa: float,
    max_strain_energy_j_per_m3: float,
    delivered_power_w: float,
) -> dict[str, str]:
    """The effects missing from ``effects`` (the scene's, closed) that would act on a state with
    these maxima (K, Pa, J/m^3 over healthy tets, W), each with why; empty when none would."""
    acting: dict[str, str] = {}
    if "thermal" not in effects and "electric" in effects and delivered_power_w > 0:
        acting["thermal"] = (
            f"{delivered_power_w:.3g} W of Joule heat is delivered but does not heat the tissue"
        )
    if "vaporization" not in effects and max_temperature_k > tissue.t_boil_k:
        acting["vaporization"] = (
            f"T up to {max_temperature_k:.1f} K passes boiling ({tissue.t_boil_k:.2f} K), "
            "where vapor would take latent heat and raise a pressure"
        )
    if (
        "mechanics" not in effects
        and "vaporization" in effects
        and max_pressure_pa > tissue.p_atm_pa
    ):
        acting["mechanics"] = (
            f"vapor pressure up to {max_pressure_pa / 1e3:.1f} kPa (ambient "
            f"{tissue.p_atm_pa / 1e3:.1f} kPa) would deform the tissue"
        )
    kappa = tissue.damage_kappa_j_per_m3
    if (
        "dissection" not in effects
        and "mechanics" in effects
        and max_strain_energy_j_per_m3 > kappa
    ):
        acting["dissection"] = (
            f"strain energy up to {max_strain_energy_j_per_m3:.3g} J/m^3 passes the damage "
            f"threshold kappa ({kappa:.3g} J/m^3), where the tissue would be cut"
        )
    return acting
