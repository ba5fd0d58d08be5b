"""Dask runs give the local run's content hash: 2 workers, 4 shuffled, a worker killed."""

from __future__ import annotations

import json

import pytest

pytestmark = pytest.mark.timeout(300)


def test_local_run_is_deterministic(
    site12_dir, small_archive, local_manifest, run_reprocess, tmp_path
):
    again = run_reprocess(site12_dir, small_archive, tmp_path / "again")
    assert again["content_hash"] == local_manifest["content_hash"]
    assert local_manifest["n_tracks"] > 0
    assert local_manifest["n_detections"] >= 3000
    assert len(local_manifest["groups"]) == 4
    # the manifest on disk is the one returned, with the hash of the files beside it
    on_disk = json.loads((tmp_path / "again" / "manifest.json").read_text())
    assert on_disk["files"] == again["files"]


def test_dask_two_workers_same_hash(
    site12_dir, small_archive, local_manifest, run_reprocess, tmp_path
):
    # a running cluster, reached as --scheduler reaches one (the others start their own)
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster:
        got = run_reprocess(
            site12_dir, small_archive, tmp_path / "d2", engine="dask",
            scheduler=cluster.scheduler_address,
        )  # fmt: skip
    assert got["run"]["workers"] == 2
    assert got["run"]["scheduler"].startswith("tcp://")
    assert got["content_hash"] == local_manifest["content_hash"]


def test_dask_four_workers_shuffled_same_hash(
    site12_dir, small_archive, local_manifest, run_reprocess, tmp_path
):
    # 20 s windows: the tracker's state crosses from task to task (and worker to worker)
    got = run_reprocess(
        site12_dir, small_archive, tmp_path / "d4", engine="dask", workers=4, shuffle_seed=7,
        window_s=20.0,
    )  # fmt: skip
    assert got["run"]["workers"] == 4
    assert got["n_jobs"] > local_manifest["n_jobs"]
    assert got["content_hash"] == local_manifest["content_hash"]


def test_dask_worker_killed_mid_run_same_hash(
    site12_dir, small_archive, local_manifest, run_reprocess, tmp_path
):
    n_tasks = local_manifest["n_jobs"]  # on Dask, a job is one task (its geolocation too)
    assert n_tasks >= 3
    got = run_reprocess(
        site12_dir, small_archive, tmp_path / "dk", engine="dask", workers=2, shuffle_seed=3,
        kill_after=n_tasks // 3,
    )  # fmt: skip
    assert got["run"]["killed_worker_gone"]  # it did die mid-run (a new one took its place)
    assert got["content_hash"] == local_manifest["content_hash"]


def test_outputs_differ_when_the_method_does(
    site12_dir, small_archive, local_manifest, run_reprocess, tmp_path
):
    # the hash is not blind: another method, another hash
    got = run_reprocess(site12_dir, small_archive, tmp_path / "k", method="kalman")
    assert got["content_hash"] != local_manifest["content_hash"]
    assert got["files"]["tracks.geojson"] != local_manifest["files"]["tracks.geojson"]
    # geolocation does not depend on the tracking method
    assert got["files"]["fixes.parquet"] == local_manifest["files"]["fixes.parquet"]
