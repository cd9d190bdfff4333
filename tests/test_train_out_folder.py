"""`splatbench train --out DIR` never trains into a folder holding another run without being told
(splatbench.train.out_folder): refused untouched, --force clears that run's files only,
--resume of the folder's own checkpoint and a fresh folder still work."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from splatbench.cli import main
from splatbench.errors import InputError
from splatbench.train.out_folder import claim_out

#: A few steps on a tiny scene, random init: the run's files, not its quality, are under test.
FAST = ["--set", "iterations=3", "--set", "strategy=none", "--set", "init=random", "--set", "init.random_points=200",
        "--quiet"]


@pytest.fixture(scope="module")
def dataset_dir(tmp_path_factory) -> Path:
    """The `diffuse` scene, 32x32, 8 views (7 train + 1 test), 4 spp."""
    from splatbench.scenes.render import render_dataset

    out = tmp_path_factory.mktemp("scenes") / "diffuse-32"
    render_dataset("diffuse", out, resolution=32, views=8, spp=4, progress=False)
    return out


def train(dataset: Path, out: Path, *extra) -> tuple[int, str, str]:
    res = CliRunner().invoke(main, ["train", str(dataset), "--out", str(out), *FAST, *map(str, extra)])
    return res.exit_code, res.stdout, res.stderr


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_folder_holding_a_run_is_refused_untouched_and_force_clears_only_that_run(tmp_path, dataset_dir):
    out = tmp_path / "d64"
    code, stdout, stderr = train(dataset_dir, out, "--set", "checkpoint_every=2")  # a fresh folder works
    assert code == 0, stderr
    assert {"config.toml", "point_cloud.ply", "result.json", "checkpoints/iteration_2.ply",
            "checkpoints/iteration_2.pt"} <= set(snapshot(out))
    (out / "point_cloud.png").write_bytes(b"a render of the old model")  # `splatbench render` of its PLY
    (out / "notes.txt").write_text("mine")                               # not the trainer's: never removed
    before = snapshot(out)

    code, stdout, stderr = train(dataset_dir, out, "--set", "seed=1")
    assert code == 2 and stdout == ""
    assert stderr.strip() == (f"splatbench: error: {out}: already holds a training run (result.json, point_cloud.ply, "
                              f"checkpoints/); pass --force to replace it (removes that run's files), or choose "
                              f"another --out")
    assert snapshot(out) == before

    code, stdout, stderr = train(dataset_dir, out, "--set", "seed=1", "--force")
    assert code == 0, stderr
    after = snapshot(out)
    assert set(after) == {"config.toml", "point_cloud.ply", "result.json", "notes.txt"}  # no old png, no checkpoints
    assert after["notes.txt"] == b"mine" and after["point_cloud.ply"] != before["point_cloud.ply"]
    assert "seed = 1" in after["config.toml"].decode()


def test_resume_of_the_folders_own_checkpoint_is_allowed_and_of_another_is_not(tmp_path, dataset_dir):
    out = tmp_path / "c"
    assert train(dataset_dir, out, "--set", "checkpoint_every=2")[0] == 0
    straight = (out / "point_cloud.ply").read_bytes()
    checkpoint = out / "checkpoints" / "iteration_2.pt"
    code, _, stderr = train(dataset_dir, out, "--set", "checkpoint_every=2", "--resume", checkpoint)
    assert code == 0, stderr
    assert (out / "point_cloud.ply").read_bytes() == straight  # resuming is exact (tests/test_train.py)

    other = tmp_path / "other"
    assert train(dataset_dir, other)[0] == 0
    before = snapshot(other)
    code, _, stderr = train(dataset_dir, other, "--set", "checkpoint_every=2", "--resume", checkpoint)
    assert code == 2 and f"{other}: already holds a training run" in stderr and snapshot(other) == before


def test_claim_out_names_resume_for_an_unfinished_run_and_removes_only_trainer_files(tmp_path):
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    for name in ("iteration_5.ply", "iteration_5.pt", ".tmp-abc.pt", ".iteration_6.pt.4242.0badcafe.tmp", "keep.txt"):
        (run / "checkpoints" / name).write_text(name)
    (run / "config.toml").write_text("")
    with pytest.raises(InputError) as err:  # interrupted: checkpoints but no result.json
        claim_out(run)
    assert str(err.value) == (f"{run}: already holds a training run (checkpoints/); pass --resume "
                              f"{run / 'checkpoints'}/iteration_<step>.pt to continue it, pass --force to replace "
                              f"it (removes that run's files), or choose another --out")
    assert claim_out(run, resume=run / "checkpoints" / "iteration_5.pt") == []  # its own checkpoint: untouched
    removed = claim_out(run, force=True)
    # the temporaries a killed checkpoint write leaves (fsutil.atomic_write's; an older version's .tmp-*.pt) go too
    assert sorted(p.name for p in removed) == [".iteration_6.pt.4242.0badcafe.tmp", ".tmp-abc.pt", "config.toml",
                                               "iteration_5.ply", "iteration_5.pt"]
    assert snapshot(run) == {"checkpoints/keep.txt": b"keep.txt"}
    assert claim_out(tmp_path / "missing") == [] and claim_out(tmp_path) == []  # no run there: nothing to do
