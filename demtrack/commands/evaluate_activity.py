"""``demtrack evaluate-activity``: precision and recall of each activity detector."""

from __future__ import annotations

import argparse
import dataclasses
import json
from typing import TYPE_CHECKING

from .choices import ACTIVITY_CASE_NAMES, ACTIVITY_SEED, DEFAULT_METHOD, TRACKING_METHODS
from .common import add_site_argument, non_negative_int

if TYPE_CHECKING:
    from demtrack.samplesite.activity_eval import CaseResult, DetectorScore

__all__ = ["format_scores", "register"]


def _fmt(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def format_scores(scores: list[DetectorScore]) -> str:
    """Scores per detector as a Markdown table."""
    lines = [
        "| detector | true | detected | found | correct | precision | recall | near-misses fired |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for s in scores:
        lines.append(
            f"| {s.detector} | {s.n_true} | {s.n_detected} | {s.n_found} | {s.n_correct}"
            f" | {_fmt(s.precision)} | {_fmt(s.recall)}"
            f" | {s.near_misses_fired} of {s.near_misses} |"
        )
    return "\n".join(lines)


def _case_lines(r: CaseResult) -> list[str]:
    out = [f"{r.name}: {r.n_tracks} track(s), {len(r.detected)} event(s)"]
    for e, m in zip(r.detected, r.matches, strict=True):
        targets = ",".join(str(r.truth_of.get(t)) for t in e.track_ids)
        verdict = "ok" if m is not None else "FALSE"
        out.append(
            f"  {e.kind:<11} {e.t_start_s:7.1f}-{e.t_end_s:7.1f} s  targets {targets:<8} {verdict}"
        )
    found = {m for m in r.matches if m is not None}
    for k, te in enumerate(r.true_events):
        if k not in found:
            out.append(f"  MISSED {te.kind} targets {te.target_ids} ({te.note})")
    for n, fired in r.near_misses_fired:
        if fired:
            out.append(f"  NEAR-MISS FIRED {n.kind}: {n.note}")
    return out


def _run(args: argparse.Namespace) -> int:
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.activity_eval import evaluate_case, score_detectors
    from demtrack.samplesite.activity_scenarios import (
        DEFAULT_ACTIVITY_PARAMS,
        make_activity_scenario,
    )

    site = load_site(args.site)
    params = dataclasses.replace(DEFAULT_ACTIVITY_PARAMS, seed=args.seed)
    names = args.case or list(ACTIVITY_CASE_NAMES)
    source = "truth" if args.on_truth else "tracks"
    results = []
    for name in names:
        activity = make_activity_scenario(site, name, params)
        results.append(evaluate_case(site, activity, args.method, source=source))
    scores = score_detectors(results)
    if args.json:
        doc = {
            "method": None if args.on_truth else args.method,
            "source": source,
            "seed": args.seed,
            "scores": [s.to_dict() for s in scores],
            "cases": [r.to_dict() for r in results],
        }
        print(json.dumps(doc, indent=2))
        return 0
    for r in results:
        print("\n".join(_case_lines(r)))
    what = "true paths" if args.on_truth else f"{args.method} tracks"
    print(f"\ndetectors on {what}, {len(results)} case(s), seed {args.seed}:")
    print(format_scores(scores))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``evaluate-activity`` command."""
    p = sub.add_parser(
        "evaluate-activity", help="precision and recall of the activity detectors on test cases"
    )
    add_site_argument(p)
    p.add_argument(
        "--case",
        action="append",
        choices=list(ACTIVITY_CASE_NAMES),
        help="a case (repeatable; default: all)",
    )
    p.add_argument(
        "--method",
        choices=list(TRACKING_METHODS),
        default=DEFAULT_METHOD,
        help=f"tracking method (default {DEFAULT_METHOD})",
    )
    p.add_argument(
        "--on-truth",
        action="store_true",
        help="run the detectors on the true paths instead of tracks",
    )
    p.add_argument(
        "--seed", type=non_negative_int, default=ACTIVITY_SEED, help="random seed (default 0)"
    )
    p.add_argument("--json", action="store_true", help="print scores and events as JSON")
    p.set_defaults(func=_run)
