"""How the focus metrics depend on the skin's attenuation: the documented sensitivity table.

For each skin (by default the presets ``low``, ``nominal``, ``high`` and ``voigt-fit``,
:data:`vibrofocus.skin.SKIN_PRESETS`, in order of attenuation), a nominal, noise-free
simulated forearm is built, every method is designed from its exact transfer
at every location and played, and the medians over the locations are reported. The
table in ``docs/skin-model.md`` is this function's output; a test recomputes it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..defaults import METHODS
from ..errors import ValidationError

__all__ = ["attenuation_sensitivity", "sensitivity_markdown"]

_COLUMNS = ("fidelity", "contrast_db", "contrast_all_points_db", "predicted_energy_contrast_db", "bound_own_db", "bound_db",
            "target_peak_m")


_PRESETS = ("low", "nominal", "high", "voigt-fit")  # the skin presets, in order of attenuation


def attenuation_sensitivity(laws: Mapping[str, object] | None = None, *,
                            methods: Sequence[str] = METHODS, peak_bounds: bool = True,
                            skins: Sequence[str] | None = None) -> list[dict]:
    """Focus metrics of each method on nominal forearms with different wave laws.

    Parameters
    ----------
    laws : mapping of str to ViscoelasticLaw, optional
        Label to a homogeneous law; default: the skin presets (label = preset name).
    methods : sequence of str
        Rendering methods.
    peak_bounds : bool
        Also compute the peak bound at each location (a minimax design each, about 2 s).
    skins : sequence of str, optional
        Without ``laws``: only these presets' rows, in the default order (the table's
        rows of one skin do not depend on the others; a test recomputes them a skin at a
        time). Default: all four.

    Returns
    -------
    list of dict
        One per (law, method): ``law``, ``c250_m_s``, ``alpha250_np_m``, ``method`` and
        the medians over the locations of ``fidelity`` (to the desired waveform: the tap,
        or for ``combination`` funneling's displacement at the target), ``contrast_db`` (against the
        other locations), ``contrast_all_points_db`` (against every calibrated point),
        ``predicted_energy_contrast_db`` (target energy over the other locations', in
        the design window), ``bound_own_db`` (the most any drive allows for the
        waveform the method delivers at the target), ``bound_db`` (the same for the
        asked tap), ``peak_bound_db`` (the most peak contrast against every calibrated
        point at the pseudo-inverse's fidelity, :func:`~vibrofocus.demo.peak_bound`; only
        with ``peak_bounds``) and ``target_peak_m`` (every method at the same 10 V peak
        drive).
    """
    from ..rigs.simulated import SimulatedForearm
    from ..skin import SKIN_PRESETS, ForearmParameters
    from .frontier import peak_frontiers
    from .run import model_transfer, run_demo

    if laws is None:
        assert set(_PRESETS) == set(SKIN_PRESETS)
        if skins is not None and not set(skins) <= set(_PRESETS):
            raise ValidationError(f"skins must be among {', '.join(_PRESETS)}, got {', '.join(map(str, skins))}")
        cases = {name: ForearmParameters.nominal(4, skin=name) for name in _PRESETS if skins is None or name in skins}
    elif skins is not None:
        raise ValidationError("skins selects among the presets: give it without laws")
    else:
        cases = {label: ForearmParameters.from_law(law, 4) for label, law in laws.items()}
    rows = []
    for label, params in cases.items():
        rig = SimulatedForearm(participant=params, noise_m=0.0, dropout_rate=0.0)
        result = run_demo(rig, methods=methods, transfer=model_transfer)
        bounds = [f.peak_bound_db for f in peak_frontiers(result, fidelities=()).values()] if peak_bounds else []
        for method in methods:
            sub = [r for r in result.rows if r["method"] == method]
            row = {"law": label, "c250_m_s": params.c250_m_s, "alpha250_np_m": params.alpha250_np_m,
                   "method": method}
            row.update({key: float(np.median([r[key] for r in sub])) for key in _COLUMNS})
            if peak_bounds:
                row["peak_bound_db"] = float(np.median(bounds))
            rows.append(row)
    return rows


def sensitivity_markdown(rows: Sequence[dict]) -> str:
    """The rows of :func:`attenuation_sensitivity` as a Markdown table."""
    lines = [
        "| skin | c(250 Hz) m/s | α(250 Hz) Np/m | method | fidelity to the tap (combination: to funneling's "
        "displacement) | contrast vs locations dB "
        "| contrast vs all points dB | energy contrast dB | bound, own waveform dB | bound, tap dB "
        "| peak bound dB | target peak µm |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['law']} | {r['c250_m_s']:.2f} | {r['alpha250_np_m']:.0f} | {r['method']} | {r['fidelity']:.2f} "
            f"| {r['contrast_db']:.1f} | {r['contrast_all_points_db']:.1f} | {r['predicted_energy_contrast_db']:.1f} "
            f"| {r['bound_own_db']:.1f} | {r['bound_db']:.1f} | {r.get('peak_bound_db', float('nan')):.1f} "
            f"| {1e6 * r['target_peak_m']:.3f} |"
        )
    return "\n".join(lines)
