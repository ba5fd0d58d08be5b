"""The warm-up jobs compile exactly the kernels the sample-site build uses, and no index."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from demtrack.samplesite.kernel_warmup import KernelWarmers

# In a fresh process: which specialisations each numba kernel holds after each step.
PROBE = r"""
import json, sys
from numba.core.dispatcher import Dispatcher
from demtrack.core import angular_kernels, camera, raycast_kernels, viewshed_kernels
from demtrack.samplesite.build import build_sample_site
from demtrack.samplesite.kernel_warmup import run_job

def held():
    out = {}
    for mod in (angular_kernels, camera, raycast_kernels, viewshed_kernels):
        for name, obj in vars(mod).items():
            if isinstance(obj, Dispatcher):
                out[f"{mod.__name__.rsplit('.', 1)[1]}.{name}"] = [str(s) for s in obj.signatures]
    return out

steps = {"start": held(), "stopped": False}

class InProcessWarmers:
    # Stands in for the child processes: the jobs run here when the build waits for them.
    def wait(self):
        steps["at_wait"] = held()
        run_job("pyramid")
        steps["pyramid"] = held()
        run_job("cast")
        steps["cast"] = held()
        return [0, 0]

    def stop(self):
        steps["stopped"] = True

build_sample_site(sys.argv[1], warmers=InProcessWarmers())
steps["build"] = held()
print(json.dumps(steps))
"""


@pytest.fixture(scope="module")
def steps(tmp_path_factory):
    out = tmp_path_factory.mktemp("warm") / "site"
    done = subprocess.run(
        [sys.executable, "-c", PROBE, str(out)],
        capture_output=True,
        text=True,
        check=True,
        timeout=900,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def _added(before: dict, after: dict) -> dict:
    return {k: v for k, v in after.items() if len(v) > len(before.get(k, []))}


def test_the_build_waits_for_the_jobs_before_casting_rays(steps):
    assert _added(steps["start"], steps["at_wait"]) == {}
    assert not steps["stopped"]


def test_the_build_compiles_nothing_after_the_jobs(steps):
    assert _added(steps["cast"], steps["build"]) == {}


def test_each_job_compiles_its_share(steps):
    # The probe can see a kernel being added: each job adds the ones it owns.
    pyr = _added(steps["start"], steps["pyramid"])
    cast = _added(steps["pyramid"], steps["cast"])
    assert "raycast_kernels.build_pyramid_kernel" in pyr
    assert "raycast_kernels.cast_kernel" not in pyr
    assert {"raycast_kernels.cast_kernel", "camera._undistort_kernel"} <= set(cast)
    assert "raycast_kernels.build_pyramid_kernel" not in cast
    # One specialisation per kernel.
    assert all(len(v) == 1 for v in steps["build"].values() if v)


def test_no_angular_index_kernel_is_compiled(steps):
    held = steps["build"]
    angular = {k: v for k, v in held.items() if k.startswith("angular_kernels.") and v}
    # The run detector is the only angular-module kernel on this path (every server cast).
    assert set(angular) == {"angular_kernels.origin_runs_kernel"}


def test_a_refused_build_stops_the_warmers(tmp_path):
    from demtrack.core.errors import SiteError
    from demtrack.samplesite.build import build_sample_site

    class Recorder:
        stopped = False

        def stop(self) -> None:
            self.stopped = True

    (tmp_path / "notes.txt").write_text("not a site", encoding="utf-8")
    w = Recorder()
    with pytest.raises(SiteError, match="non-empty folder"):
        build_sample_site(tmp_path, warmers=w)
    assert w.stopped


def test_warmers_report_exit_status():
    w = KernelWarmers.start(["pyramid"])
    assert w.wait() == [0]
    with pytest.raises(ValueError, match="unknown warm-up job"):
        KernelWarmers.start(["nope"])
