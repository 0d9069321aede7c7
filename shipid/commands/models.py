"""Core sub-commands: ``models`` (and, from the identification module, ``fit`` and ``demo``)."""
from __future__ import annotations

#: Plain meanings of the state and input names the registered models use.
MEANINGS = {
    "x": "position x (earth-fixed)", "y": "position y (earth-fixed)", "z": "depth", "psi": "heading",
    "theta": "pitch angle", "phi": "roll angle", "u": "surge speed", "v": "sway speed", "w": "heave speed",
    "p": "roll rate", "q": "pitch rate", "r": "yaw rate", "delta": "rudder angle",
    "n": "propeller revolutions", "T": "thrust", "phi_p": "thrust direction angle",
}
#: What the parameters of a model are (the term each multiplies), for ``shipid models``.
PARAMETER_NOTES = {
    "kcs-response": ("du/dt = (a1 + a8 n) u + a2 v^2 + a3 r^2 + a4 delta^2 + (a5 r + a6 delta) v + a7 r delta + a9 n^2; "
                     "dv/dt = b1 v + (b2 + b4 u) r + b3 delta; dr/dt = c1 v + c2 r + c3 delta (Hajizadeh et al.)"),
    "mmg": ("non-dimensional (prime) hull derivatives X.., Y.., N.., added masses mx, my, Jz, propeller (tP, wP0, "
            "k0-k2, xP) and rudder (tR, aH, xH, gammaR, lR, eps, kappa, f_alpha) coefficients in the notation of "
            "Yasukawa & Yoshimura (2015)"),
}
#: Per-model exceptions to :data:`MEANINGS`.
MODEL_MEANINGS = {"glider": {"delta": "fin incidence", "x": "horizontal position"}}


def register(sub) -> None:
    p = sub.add_parser("models", help="list the registered models: states, inputs and parameters with units",
                       description="List the registered models, their states and inputs (meaning, unit), their "
                                   "parameters (unit) and published parameter sets.")
    p.set_defaults(handler=_models)


def _first_line(obj) -> str:
    doc = (obj.__doc__ or "").strip()
    return doc.splitlines()[0].rstrip(".") if doc else ""


def _models(args) -> int:
    from .. import models

    for name in models.available_models():
        cls = models.model_class(name)
        m = cls()
        units = getattr(m, "units", {}) or {}

        def label(n):
            return f"{n} [{units[n]}]" if units.get(n) else n

        print(f"{name}: {_first_line(cls)}")
        for kind, names in (("states", m.state_names), ("inputs", m.input_names)):
            mean = {**MEANINGS, **MODEL_MEANINGS.get(name, {})}
            print(f"  {kind}: " + ", ".join(f"{label(n)} {mean[n]}" if n in mean else label(n) for n in names))
        print(f"  parameters ({m.np}): {', '.join(label(n) for n in m.param_names)}")
        if name in PARAMETER_NOTES:
            print(f"    {PARAMETER_NOTES[name]}")
        print(f"    (equations and sources: help({cls.__module__}.{cls.__name__}))")
        sets = cls.parameter_sets()
        if sets:
            print(f"  parameter sets: {', '.join(sets)}")
    return 0
