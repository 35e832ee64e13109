"""``workbench demo``: the main job end to end on the embedded records, with a report."""

from __future__ import annotations

import argparse
from typing import Any

from workbench.cli.common import emit, seed_int

__all__ = ["add_demo_parser"]


def _cmd_demo(args: argparse.Namespace) -> int:
    from workbench.demo import run_demo

    summary = run_demo(out_dir=args.out, seed=args.seed, progress=not args.json)
    emit(args, {k: v for k, v in summary.items() if k != "text"}, summary["text"])
    return 0


def add_demo_parser(sub: Any, out_opts: argparse.ArgumentParser) -> None:
    """Register the ``demo`` subcommand on the ``workbench`` parser.

    Parameters
    ----------
    sub : argparse subparsers action
    out_opts : argparse.ArgumentParser
        The shared output options (``--json``).
    """
    p = sub.add_parser(
        "demo",
        parents=[out_opts],
        help="run the main job on the embedded records and write a report",
        description="Run the workbench end to end on the embedded real and synthetic records "
        "and write an HTML and Markdown report.",
    )
    p.add_argument("--out", metavar="DIR", default="reports/demo", help="report folder")
    p.add_argument("--seed", type=seed_int, default=20261122, help="seed for everything random")
    p.set_defaults(handler=_cmd_demo)
