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


#: Width the listing is wrapped to (continuation lines indented under their label).
WIDTH = 100


def _say(text: str, indent: int) -> None:
    """Print ``text`` wrapped to :data:`WIDTH` columns, continuation lines indented ``indent + 4``; a no-break
    space (U+00A0) joins words that stay on one line and prints as a space."""
    import textwrap

    out = textwrap.fill(text, WIDTH, initial_indent=" " * indent, subsequent_indent=" " * (indent + 4),
                        break_on_hyphens=False, break_long_words=False)
    print(out.replace("\u00a0", " "))


def _models(args) -> int:
    from .. import models

    for name in models.available_models():
        cls = models.model_class(name)
        m = cls()
        units = getattr(m, "units", {}) or {}

        def label(n):
            return f"{n}\u00a0[{units[n]}]".replace(" ", "\u00a0") if units.get(n) else n  # kept on one line

        _say(f"{name}: {_first_line(cls)}", 0)
        for kind, names in (("states", m.state_names), ("inputs", m.input_names)):
            mean = {**MEANINGS, **MODEL_MEANINGS.get(name, {})}
            _say(f"{kind}: " + ", ".join(f"{label(n)} {mean[n]}" if n in mean else label(n) for n in names), 2)
        _say(f"parameters ({m.np}): {', '.join(label(n) for n in m.param_names)}", 2)
        if name in PARAMETER_NOTES:
            _say(PARAMETER_NOTES[name], 4)
        _say(f"(equations and sources: help({cls.__module__}.{cls.__name__}))", 4)
        sets = cls.parameter_sets()
        if sets:
            _say(f"parameter sets: {', '.join(sets)}", 2)
    return 0
