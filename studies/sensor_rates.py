"""How often the sensor checks of :mod:`shipid.logs.sensors` fire on good logs, and how often they find an
injected gyro scale error.

    python -m studies.sensor_rates

Good logs: the bundled KCS logs, the MARIN KVLCC2 runs except the held-back zz+-20 (never read here) and the
33 Esso Osaka runs.  Injected: the yaw rate of each bundled and MARIN log multiplied by 1.02, 1.03, 1.05 and
1.10 (above 10 % the yaw-rate consistency check already warns).
"""
from __future__ import annotations

import warnings
from pathlib import Path

from shipid.datasets import bundled_kcs_logs
from shipid.logs import TrialLog, read_log
from shipid.logs.sensors import check_sensors, yaw_rate_scale

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
HELD_BACK = ("zz_20_m", "zz_-20_m")


def _read(p: Path):
    kw = {"schema": "esso-frt"} if "esso" in str(p) else {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_log(p, consistency_checks=False, **kw)


def good_logs() -> dict:
    marin = [p for p in sorted((SHARED / "kvlcc2_marin").glob("*.dat")) if not any(h in p.name for h in HELD_BACK)]
    return {"bundled": [Path(p) for p in bundled_kcs_logs()], "marin": marin,
            "esso": sorted((SHARED / "esso_osaka_frt").glob("*/*.csv"))}


def main() -> None:
    groups = good_logs()
    for name, paths in groups.items():
        fired, zs, n = 0, [], 0
        for p in paths:
            log = _read(p)
            n += 1
            fired += any(f.level == "warning" for f in check_sensors(log))
            e = yaw_rate_scale(log.time, log.data["psi"], log.data["r"])
            if e is not None:
                zs.append(abs(e["scale"] - 1) / e["scale_std"])
        print(f"{name}: a sensor warning on {fired} of {n} logs; largest |scale - 1| / its std {max(zs):.2f}")
    for pct in (2, 3, 5, 10):
        hit = n = 0
        for p in groups["bundled"] + groups["marin"]:
            log = _read(p)
            d = log.data
            chans = {c: d[c].to_numpy() * (1 + pct / 100 if c == "r" else 1.0) for c in d.columns if c != "time"}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                bad = TrialLog.from_arrays(d["time"].to_numpy(), name=log.name, ship=log.ship, unit_checks=False,
                                           consistency_checks=False, **chans)
            e = yaw_rate_scale(bad.time, bad.data["psi"], bad.data["r"])
            n += 1
            hit += any(f.check == "yaw_rate_scale" for f in check_sensors(bad)) or abs(e["scale"] - 1) > 0.1
        print(f"yaw rate {pct:+d} %: found in {hit} of {n} logs (bundled + MARIN)")


if __name__ == "__main__":
    main()
