"""``demtrack handoff``: score hand-off predictions on a sample-site scenario's truth."""

from __future__ import annotations

import argparse
import time

from .common import add_site_argument, positive

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    import numpy as np

    from demtrack.core.site.folder import load_site
    from demtrack.core.visibility.handoff import evaluate_handoffs
    from demtrack.samplesite.scenarios import SCENARIOS, SIZES_M, make_scenario

    site = load_site(args.site)
    names = [args.scenario] if args.scenario else sorted(SCENARIOS)
    print(
        f"{'scenario':<18}{'class':<9}{'hand-offs':>10}{'right':>7}{'accuracy':>10}"
        f"{'median early s':>16}{'scored lead s':>15}"
    )
    for name in names:
        scenario = make_scenario(site, name, fixed_cameras=True)  # the truth is what counts
        for cls in sorted({t.cls for t in scenario.truths}):
            truths = [t for t in scenario.truths if t.cls == cls]
            t0 = time.perf_counter()
            score = evaluate_handoffs(
                site.dem,
                site.sensors,
                truths,
                height_m=SIZES_M[cls][2],
                lead_s=args.lead,
                roads=site.roads if cls == "vehicle" else None,
            )
            early = f"{np.median(score.early_s):.1f}" if score.early_s else "-"
            lead = f"{np.median(score.leads_s):.1f}" if score.leads_s else "-"
            print(
                f"{name:<18}{cls:<9}{score.handoffs:>10}{score.correct:>7}"
                f"{score.accuracy:>10.2f}{early:>16}{lead:>15}"
                f"   ({time.perf_counter() - t0:.1f} s)"
            )
    print(
        f"(scored prediction made {args.lead:g} s before each real exit, or when the camera "
        "took the target over if later; vehicles follow the road)"
    )
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``handoff`` command."""
    p = sub.add_parser("handoff", help="score sensor hand-off predictions on a scenario")
    add_site_argument(p)
    p.add_argument("--scenario", help="a sample-site scenario (default: all)")
    p.add_argument(
        "--lead",
        type=positive,
        default=2.0,
        metavar="S",
        help="how long before the exit the prediction is made (default 2 s)",
    )
    p.set_defaults(func=_run)
