"""``shipid log``: check trial logs (print what was read) and convert them to the SI CSV schema."""
from __future__ import annotations

from ._common import add_log_options, check_output_path, read_logs


def register(sub) -> None:
    p = sub.add_parser(
        "log",
        help="check trial logs and print their summary; -o converts one to the SI CSV schema",
        description="Read and validate trial logs exactly as `shipid fit` would, print a summary of each "
                    "(samples, channels, units converted, missing samples with their rows, dropouts), "
                    "and optionally write one as a clean CSV in SI units and radians.",
    )
    p.add_argument("logs", nargs="+", metavar="LOG", help="trial log files (.csv, MARIN .dat)")
    p.add_argument("-o", "--output", default=None, metavar="OUT.csv",
                   help="write the (single) log as CSV in the default schema, SI units, radians")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    add_log_options(p)
    p.set_defaults(handler=_log)


def _log(args) -> int:
    if args.output and len(args.logs) != 1:
        raise ValueError(f"-o/--output converts one log; got {len(args.logs)}: give one LOG with -o")
    if args.output:  # never over the log itself (nor the ship/schema file), even with --force
        check_output_path(args.output, force=args.force, inputs=[*args.logs, args.ship, args.schema])
    for log in read_logs(args.logs, args):
        print(log)
        if args.output:
            out = log.to_csv(args.output, force=args.force)
            print(f"wrote {out} ({len(log)} samples, SI units, radians, body-axis velocities)")
    return 0
