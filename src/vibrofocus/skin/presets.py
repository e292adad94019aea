"""Named skin presets of the simulated forearm, each with the evidence behind its numbers.

``nominal``, ``low`` and ``high`` share one layered dispersion (:class:`.LayeredLaw`) and
differ in loss; ``voigt-fit`` is the earlier homogeneous Voigt law fitted to phase speeds
alone, kept as the pessimistic preset (it attributes all of the measured dispersion to
loss). ``scripts/fit_skin_model.py`` fits the layered dispersion and prints its
residuals; docs/skin-model.md lists every source.

Sources (each read in a stored copy; what was not verified is said so):

- Phase speed 3.25 +/- 0.19 m/s at 200 Hz on the forearm: Zhang X, Osborn TG, Kinnick
  RR, Greenleaf JF, "Quantitative assessment of scleroderma by surface wave technique",
  Med. Eng. Phys. 33(1):31-37, 2011, doi:10.1016/j.medengphy.2010.08.016 (abstract).
- Speed plateau near 7 m/s: Manfredi LR et al., "The effect of surface wave propagation
  on neural responses to vibration in primate glabrous skin", PLoS ONE 7(2):e31203,
  2012, doi:10.1371/journal.pone.0031203 (abstract; fingertip, not forearm): the top
  layer's Rayleigh speed.
- Substrate: hypodermis Young's modulus about 15 kPa at 0.2-1 kHz on the volar forearm,
  Feng X, Li G-Y, Ramier A, Eltony AM, Yun S-H, "In vivo stiffness measurement of
  epidermis, dermis, and hypodermis using broadband Rayleigh-wave optical coherence
  elastography", Acta Biomater. 146:295-305, 2022 (arXiv preprint abstract read;
  journal, pages, authors and DOI 10.1016/j.actbio.2022.04.030 read on one
  bibliographic listing): shear modulus E/3 = 5 kPa
  (incompressible; our arithmetic).
- Loss, nominal and low: tan delta = 0.14 +/- 0.07 from the exponential decay of surface
  waves, Kirkpatrick SJ, Duncan DD, Fang L, "Low-frequency surface wave propagation and
  the viscoelastic behavior of porcine skin", J. Biomed. Opt. 9(6):1311, 2004,
  doi:10.1117/1.1803843 (abstract; porcine skin at 1 Hz: a direct decay measurement,
  but far below the band and another species). Nominal 0.14, low 0.07 (mean - 1 SD).
- Loss, high: spring-pot order 0.253 +/- 0.009 of relaxed human thigh muscle at
  25-62.5 Hz, Klatt D, Papazoglou S, Braun J, Sack I, "Viscoelasticity-based MR
  elastography of skeletal muscle", Phys. Med. Biol. 55(21):6445-6459, 2010,
  doi:10.1088/0031-9155/55/21/007 (abstract): loss tangent tan(0.253 pi / 2) = 0.42
  (our arithmetic), the deepest, lossiest layer taken for the whole arm.
- Assumptions (no source): one loss tangent for every layer and frequency (a constant-Q
  law); the effective-depth weighting of :class:`.LayeredLaw`; the density 1100 kg/m^3
  (inside the single-layer range of Burns 43(5):909-932, 2017, doi:10.1016/j.burns.2016.11.014,
  Table 1).
"""

from __future__ import annotations

from dataclasses import dataclass

from .._validation import check_choice
from .layered import LayeredLaw
from .viscoelastic import RAYLEIGH_FACTOR_INCOMPRESSIBLE

__all__ = ["SkinPreset", "SKIN_PRESETS", "DEFAULT_SKIN", "skin_preset", "LAYERED_NOMINAL"]

#: Density of every layer, kg/m^3 (see the module docstring).
_DENSITY = 1100.0
#: Top layer: Rayleigh speed 7.0 m/s (Manfredi et al. 2012's plateau).
_TOP_SHEAR_PA = _DENSITY * (7.0 / RAYLEIGH_FACTOR_INCOMPRESSIBLE) ** 2
#: Substrate: E / 3 of Feng et al. 2022's hypodermis (15 kPa).
_SUBSTRATE_SHEAR_PA = 15e3 / 3
#: Effective depth of the top layer, m: fitted by ``scripts/fit_skin_model.py`` so that
#: the nominal preset's phase speed at 200 Hz is Zhang et al. 2011's 3.25 m/s.
_TOP_DEPTH_M = 0.3966e-3

#: The nominal layered law (loss tangent 0.14).
LAYERED_NOMINAL = LayeredLaw(top_shear_pa=_TOP_SHEAR_PA, substrate_shear_pa=_SUBSTRATE_SHEAR_PA,
                             top_depth_m=_TOP_DEPTH_M, loss_tangent=0.14, density_kg_m3=_DENSITY)


@dataclass(frozen=True)
class SkinPreset:
    """One named skin of the simulated forearm.

    Attributes
    ----------
    name : str
        The name ``--skin`` takes and every output carries.
    law : LayeredLaw or None
        The wave law; None for ``voigt-fit`` (the homogeneous
        :data:`vibrofocus.skin.parameters.NOMINAL_LAW` of :class:`ForearmParameters`).
    anchor_distance_m : float
        Where 10 V of the base tap on one nominal actuator gives 2 µm peak, m from its
        centre: 0 (on the actuator, the paper's anchor for its 0.002 mm target) for the
        evidence presets; 6 mm for ``voigt-fit``, as the earlier model had it.
    description : str
        One line for people.
    """

    name: str
    law: LayeredLaw | None
    anchor_distance_m: float
    description: str


SKIN_PRESETS: dict[str, SkinPreset] = {
    "nominal": SkinPreset("nominal", LAYERED_NOMINAL, 0.0,
                          "layered arm, loss tangent 0.14 (the weight of the evidence)"),
    "low": SkinPreset("low", LAYERED_NOMINAL.scaled(loss=0.5), 0.0,
                      "layered arm, loss tangent 0.07 (least lossy end of the evidence)"),
    "high": SkinPreset("high", LAYERED_NOMINAL.scaled(loss=0.42 / 0.14), 0.0,
                       "layered arm, loss tangent 0.42 (muscle's loss for the whole arm)"),
    "voigt-fit": SkinPreset("voigt-fit", None, 6e-3,
                            "homogeneous Voigt law fitted to phase speeds (pessimistic: ~190 Np/m at 250 Hz)"),
}
#: The preset of ``SimulatedForearm()`` and of every simulating command.
DEFAULT_SKIN = "nominal"


def skin_preset(name: str) -> SkinPreset:
    """The preset called ``name``, or a ValidationError naming the choices.

    Parameters
    ----------
    name : str
        One of :data:`SKIN_PRESETS` (``"nominal"``, ``"low"``, ``"high"``, ``"voigt-fit"``).

    Returns
    -------
    SkinPreset
    """
    return SKIN_PRESETS[check_choice(name, "skin", tuple(SKIN_PRESETS))]
