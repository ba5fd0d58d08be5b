"""The warm-up jobs compile exactly the kernels the sample-site build and a cold console use."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from demtrack.samplesite.kernel_warmup import KernelWarmers

# In a fresh process: which specialisations each numba kernel holds after each step.
PROBE = r"""
import json, sys
import numpy as np
from numba.core.dispatcher import Dispatcher
from demtrack.core.camera import _lens_kernels, lens
from demtrack.core.raycast import (
    _angular_index_kernels, _angular_kernels, _angular_walk_kernels, _hit_kernels, _kernels,
    _light_kernels, _pyramid_kernels, _ray_kernels, _walk_kernels,
)
from demtrack.core.raycast import cast as raycast
from demtrack.core.visibility import _viewshed_kernels
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec
from demtrack.core.site.folder import load_site
from demtrack.samplesite.build import build_sample_site
from demtrack.samplesite.kernel_warmup import run_job
from demtrack.server.footprints import footprint

def held():
    out = {}
    # The kernel modules under the names of the flat modules they were split from.
    mods = {
        "angular_kernels": (_angular_index_kernels, _angular_walk_kernels, _angular_kernels),
        "camera": (lens, _lens_kernels),
        "raycast_kernels": (_walk_kernels, _pyramid_kernels, _kernels, _hit_kernels, _ray_kernels),
        "raycast_light_kernels": (_light_kernels,),
        "viewshed_kernels": (_viewshed_kernels,),
    }
    for label, group in mods.items():
        for mod in group:
            for name, obj in vars(mod).items():
                if isinstance(obj, Dispatcher):
                    out[f"{label}.{name}"] = [str(s) for s in obj.signatures]
    return out

steps = {"start": held(), "stopped": False}

class InProcessWarmers:
    # Stands in for the child processes: the jobs run here when the build waits for them.
    def wait(self):
        steps["at_wait"] = held()
        run_job("cast")
        steps["cast"] = held()
        return [0]

    def stop(self):
        steps["stopped"] = True

build_sample_site(sys.argv[1], warmers=InProcessWarmers())
steps["build"] = held()
# What a cold console casts before its warm-up is done: footprints (/api/sensors), a
# geolocation of every hit, and an all-hits cast with more hits than the first pass keeps.
site = load_site(sys.argv[1])
with raycast.light_kernels():
    for sensor in site.sensors.values():
        footprint(sensor.camera, site.dem.ray_caster(), site.frame)
        site.geolocator().geolocate(sensor.camera, [640.0, 100.0], [500.0, 400.0], rule="all")
    zig = np.tile(np.array([0.0, 10.0], np.float32), 8)
    teeth = Dem(GridSpec(0.0, 2.0, 1.0, 2, 16), np.vstack([zig, zig]))
    hits = raycast.cast_rays(teeth, np.array([[0.5, 1.0, 5.0]]), np.array([[1.0, 0.0, 0.0]]))
    steps["teeth_hits"] = int(hits.counts[0])
steps["light_session"] = held()
run_job("pyramid")
steps["pyramid"] = held()
raycast.use_light_kernels(True)
run_job("server")
steps["server"] = held()
steps["light_after_server"] = raycast.light_kernels_on()
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
    cast = _added(steps["start"], steps["cast"])
    pyr = _added(steps["light_session"], steps["pyramid"])
    # The build renders with the light kernels and a numpy pyramid: no fast kernel.
    assert set(cast) == {
        "camera._undistort_kernel",
        "raycast_kernels.check_rays_kernel",
        "raycast_kernels.gather_hits_kernel",
        "raycast_light_kernels.cast_kernel_light",
    }
    assert set(pyr) == {"raycast_kernels.build_pyramid_kernel"}
    # One specialisation per kernel.
    assert all(len(v) == 1 for v in steps["build"].values() if v)


def test_a_cold_console_casts_with_what_the_jobs_compiled(steps):
    # Footprints, geolocation and many-hit re-casts: nothing more compiles with light kernels.
    assert steps["teeth_hits"] == 8
    assert _added(steps["build"], steps["light_session"]) == {}


def test_the_server_job_compiles_the_fast_kernels_and_switches_to_them(steps):
    server = _added(steps["pyramid"], steps["server"])
    assert {"raycast_kernels.cast_kernel", "raycast_kernels.cast_all_refill_kernel"} <= set(server)
    assert not steps["light_after_server"]
    angular = {k for k, v in steps["server"].items() if k.startswith("angular_kernels.") and v}
    assert angular == {"angular_kernels.origin_runs_kernel"}  # the run detector only


def test_no_angular_index_kernel_is_compiled(steps):
    held = steps["light_session"]
    angular = {k: v for k, v in held.items() if k.startswith("angular_kernels.") and v}
    # Light casts do not even look for runs of one origin.
    assert angular == {}


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


def test_wait_can_join_the_children_of_some_jobs_only():
    class Proc:
        def __init__(self, status: int) -> None:
            self.status = status
            self.waited = False

        def wait(self) -> int:
            self.waited = True
            return self.status

    tracker, server = Proc(3), Proc(0)
    warmers = KernelWarmers([tracker, server], ["tracker", "server"])  # type: ignore[list-item]
    assert warmers.wait(["tracker"]) == [3]
    assert tracker.waited and not server.waited
    assert warmers.wait() == [3, 0] and server.waited


def test_each_job_runs_at_its_priority():
    # The tracker's shares yield to the build (nice 15), the fast kernels to them (19).
    warmers = KernelWarmers.start(["pyramid", "kalman", "server"])
    try:
        base = os.getpriority(os.PRIO_PROCESS, 0)
        nice = [os.getpriority(os.PRIO_PROCESS, p.pid) - base for p in warmers.procs]
        assert nice == [min(5, 19 - base), min(15, 19 - base), 19 - base]
        assert warmers.jobs == ["pyramid", "kalman", "server"]
        if hasattr(os, "SCHED_IDLE"):
            assert os.sched_getscheduler(warmers.procs[2].pid) == os.SCHED_IDLE
    finally:
        warmers.stop()


TRACKER_PROBE = r"""
import json
from numba.core.dispatcher import Dispatcher
from demtrack.core.tracking import fusion_kernels, hypothesiser_kernels, kalman_kernels
from demtrack.core.warm import warm_tracking as warm_up
from demtrack.samplesite.kernel_warmup import run_job

def held():
    out = {}
    for mod in (fusion_kernels, hypothesiser_kernels, kalman_kernels):
        for name, obj in vars(mod).items():
            if isinstance(obj, Dispatcher):
                out[f"{mod.__name__.rsplit('.', 1)[1]}.{name}"] = [str(s) for s in obj.signatures]
    return out

steps = {"start": held()}
run_job("fusion")
steps["fusion"] = held()
run_job("kalman")
steps["kalman"] = held()
warm_up()  # what the server's warm-up and the live tracker use
steps["warm"] = held()
print(json.dumps(steps))
"""


def test_the_tracker_jobs_share_what_the_tracker_warm_up_compiles():
    done = subprocess.run(
        [sys.executable, "-c", TRACKER_PROBE],
        capture_output=True,
        text=True,
        check=True,
        timeout=900,
    )
    steps = json.loads(done.stdout.strip().splitlines()[-1])
    fusion = _added(steps["start"], steps["fusion"])
    kalman = _added(steps["fusion"], steps["kalman"])
    assert set(fusion) == {
        "fusion_kernels.screen_pairs_kernel",
        "fusion_kernels.triangulation_cov_kernel",
    }
    assert kalman and not set(kalman) & set(fusion)  # two shares, no kernel in both
    assert all(
        k.startswith("kalman_kernels.") or k.startswith("hypothesiser_kernels.") for k in kalman
    )
    assert _added(steps["kalman"], steps["warm"]) == {}  # nothing left to compile
