"""What the benchmarks on the sample site share: the site folder and the soak's scenarios."""

from __future__ import annotations

from pathlib import Path

__all__ = ["SOAK_SCENARIOS", "site_or_sample"]

#: The scenarios the console soak, the in-process pipeline replay and ``demtrack demo`` play.
SOAK_SCENARIOS = ("vehicle-run", "pedestrians", "passing-vehicles")


def site_or_sample(site: Path | None, tmp: Path, *, announce: bool = False) -> Path:
    """``site`` if given, else the sample site built under ``tmp`` (``announce``: say so)."""
    if site is not None:
        return Path(site)
    from demtrack.samplesite.build import build_sample_site

    if announce:
        print("building the sample site ...", flush=True)
    return Path(build_sample_site(tmp / "site"))
