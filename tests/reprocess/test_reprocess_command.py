"""``demtrack reprocess`` and ``demtrack archive`` from the command line."""

from __future__ import annotations

import json
import re

import pytest

from demtrack.cli import main

pytestmark = pytest.mark.timeout(300)


def test_reprocess_prints_the_manifest_hash(
    site12_dir, small_archive, local_manifest, tmp_path, capsys
):
    out = tmp_path / "o"
    argv = ["reprocess", "--site", str(site12_dir), "--archive", str(small_archive)]
    assert main([*argv, "--method", "multi-hypothesis-road", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    got = re.search(r"content hash: sha256:([0-9a-f]{64})", text).group(1)
    assert got == json.loads((out / "manifest.json").read_text())["content_hash"]
    assert got == local_manifest["content_hash"]  # the CLI runs what the API runs


def test_archive_convert_then_reprocess_same_hash(
    site12_dir, small_archive, local_manifest, tmp_path
):
    # the archive folder -> a JSON Lines file is not a route here; folder -> folder is
    assert main(["archive", "convert", str(small_archive), "--site", str(site12_dir),
                 "-o", str(tmp_path / "copy")]) == 0  # fmt: skip
    out = tmp_path / "o"
    assert main(["reprocess", "--site", str(site12_dir), "--archive", str(tmp_path / "copy"),
                 "--method", "multi-hypothesis-road", "-o", str(out)]) == 0  # fmt: skip
    assert (
        json.loads((out / "manifest.json").read_text())["content_hash"]
        == (local_manifest["content_hash"])
    )


@pytest.mark.parametrize(
    ("extra", "expect"),
    [
        (["--archive", "{tmp}/missing.parquet"], "missing.parquet does not exist"),
        (["--archive", "{tmp}/notes.txt"], "unknown archive kind"),
        (
            ["--archive", "{archive}", "--engine", "dask", "--scheduler", "tcp://127.0.0.1:9"],
            "cannot reach the Dask scheduler",
        ),  # fmt: skip
    ],
)
def test_reprocess_mistakes_one_line_exit_2(
    site12_dir, small_archive, tmp_path, capsys, extra, expect
):
    (tmp_path / "notes.txt").write_text("x")
    extra = [e.format(tmp=tmp_path, archive=small_archive) for e in extra]
    code = main(["reprocess", "--site", str(site12_dir), *extra, "-o", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("demtrack reprocess: error:") and expect in err[0]


def test_unknown_method_exit_2(site12_dir, small_archive, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["reprocess", "--site", str(site12_dir), "--archive", str(small_archive),
              "--method", "nope", "-o", str(tmp_path / "o")])  # fmt: skip
    assert exc.value.code == 2
    assert "invalid choice: 'nope'" in capsys.readouterr().err


def test_archive_export_mistakes(tmp_path, capsys):
    assert main(["archive", "export", "-o", str(tmp_path / "a")]) == 2
    assert "give --db" in capsys.readouterr().err
    assert (
        main(["archive", "export", "--db", str(tmp_path / "no.sqlite3"), "-o", str(tmp_path / "a")])
        == 2
    )
    assert "does not exist" in capsys.readouterr().err
    url = "postgresql://demtrack:secret@127.0.0.1:9/none"
    assert main(["archive", "export", "--database-url", url, "-o", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot be used" in err[0] and "secret" not in err[0]
