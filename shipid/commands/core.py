"""Core sub-commands: ``models`` (and, from the identification module, ``fit`` and ``demo``)."""
from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser("models", help="list the registered models and their parameters")
    p.set_defaults(handler=_models)


def _models(args) -> int:
    from .. import models

    for name in models.available_models():
        cls = models.model_class(name)
        m = cls()
        print(f"{name}: states {', '.join(m.state_names)}; inputs {', '.join(m.input_names)}")
        print(f"  parameters ({m.np}): {', '.join(m.param_names)}")
        sets = cls.parameter_sets()
        if sets:
            print(f"  parameter sets: {', '.join(sets)}")
    return 0
