"""Regenerate the bundled synthetic KCS logs in this folder.

    python data/make_synthetic.py [--force]

The recipe (manoeuvres, rpm schedules, noise levels, seed) lives in
``shipid.synthetic`` so that the tests use exactly the same data; the truth is
the ``kcs-response`` parameter set ``synthetic-truth``.  See data/README.md.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

from shipid.logs import ShipParticulars, TrialLog
from shipid.models import get_model
from shipid.synthetic import KCS_MMG_RECIPES, KCS_RECIPES, make_kcs_logs

HERE = Path(__file__).resolve().parent
SEED = 20261123

#: KCS model particulars (scale 52.67, Lpp 4.36 m, the SIMMAN 2008 KCS model).
KCS_MODEL = ShipParticulars(
    lpp=4.36, beam=0.61, draught=0.20, displacement=0.356, design_speed=1.7,
    rudder_rate=0.29321531433504733, rudder_max=0.6108652381980153, name="KCS model 1:52.67", scale=52.67,
    extra={"source": "KCS model particulars, scale 1:52.67 (SIMMAN 2008 KCS model)"},
)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--force", action="store_true", help="overwrite existing files")
    ap.add_argument("--out", default=str(HERE), help="output folder (default: this folder)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    logs = make_kcs_logs(get_model("kcs-response", "synthetic-truth"), seed=SEED)
    logs.update(make_kcs_logs(get_model("mmg", "kcs"), seed=SEED + 1, recipes=KCS_MMG_RECIPES))
    for name, (noisy, _truth) in logs.items():
        cols = {c: noisy[c].to_numpy() for c in noisy.columns if c != "time"}
        log = TrialLog.from_arrays(noisy["time"].to_numpy(), name=name, ship=KCS_MODEL, **cols)
        log.to_csv(out / f"{name}.csv", force=args.force)
        print(f"wrote {out / (name + '.csv')} ({len(log)} samples)")
    ship = out / "kcs_model_ship.json"
    if args.force or not ship.exists():
        ship.write_text(json.dumps(KCS_MODEL.to_dict(), indent=2) + "\n")
    print(f"recipes: {[r.name for r in KCS_RECIPES + KCS_MMG_RECIPES]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
