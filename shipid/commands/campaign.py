"""``shipid campaign``: many fits and sweeps from a campaign file, on Dask workers (:mod:`shipid.campaign`)."""
from __future__ import annotations

import sys
from pathlib import Path

from ._common import add_progress_option, output_command, progress_on


def register(sub) -> None:
    c = output_command(sub, "campaign", _campaign,
                 "run the fits and sweeps of a campaign file (JSON/YAML) on Dask workers",
                 "Run many fits, each with its own logs and settings, and sweeps (turning-diameter grids, glider "
                 "launch factorials) from a campaign file; an embedded LocalCluster of --workers processes by "
                 "default, an existing cluster with --scheduler, serially with --workers 1.  Writes "
                 "OUTDIR/<name>/result.json (+ predictions.json with draws) per fit, OUTDIR/<name>/sweep.csv per "
                 "sweep and OUTDIR/campaign.json.",
                 positional=[("campaign", "CAMPAIGN", "campaign file (.json, .yaml)")],
                 output_help="output folder (new or empty)", output_metavar="OUTDIR",
                 force_help="run every member again into a used output folder (removes the members' old files)")
    c.add_argument("--resume", action="store_true",
                   help="finish a campaign that was stopped: members OUTDIR/campaign.journal lists as finished "
                        "(files unchanged) are kept, the others run")
    c.epilog = ("exit status: 0 every member ok; 3 some fits flagged (`shipid fit` would exit 3 or 4 on them: not "
                "consistent with their noise model, or diverged) and none failed; 1 some members failed; 2 bad input")
    add_engine_options(c)


def add_engine_options(p) -> None:
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes of the embedded Dask LocalCluster (default: CPUs; 1 = serial)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS", help="existing Dask scheduler, e.g. tcp://host:8786")
    add_progress_option(p)  # --progress / --no-progress, on at a terminal, as every long-running command


def engine_from(args):
    from ..campaign import Engine

    return Engine(args.workers, scheduler=args.scheduler, progress=progress_on(args))


def _member_line(m: dict) -> str:
    if m["status"] == "failed":
        return f"{m['name']}: FAILED: {m['error']}"
    if m["status"] == "flagged":
        why = "; ".join(m.get("reasons") or [])
        return f"{m['name']}: flagged: {why[:200]}{'...' if len(why) > 200 else ''}"
    note = "" if m.get("success", True) else " (did not converge)"
    return f"{m['name']}: ok{note}"


def _campaign(args) -> int:
    from ..campaign import campaign_exit_status, load_campaign, run_campaign

    if args.force and args.resume:
        raise ValueError("--force and --resume: give one (--resume keeps finished members, --force runs them again)")
    camp = load_campaign(args.campaign)  # validate before starting any worker
    with engine_from(args) as eng:
        summary = run_campaign(camp, args.output, engine=eng, force=args.force, resume=args.resume,
                               on_member=lambda m: print(_member_line(m), flush=True))
    for m in summary["members"]:
        for w in m.get("warnings", [])[:3]:
            print(f"{m['name']}: warning: {w}", file=sys.stderr)
    resumed = f", {summary['n_resumed']} kept from the earlier run" if summary.get("n_resumed") else ""
    print(f"{summary['n_members']} members: {summary['n_ok']} ok, {summary['n_flagged']} flagged, "
          f"{summary['n_failed']} failed{resumed} ({summary['engine']}); wrote {Path(args.output) / 'campaign.json'}")
    return campaign_exit_status(summary)


# ----------------------------------------------------------------------------- --draws hunks
