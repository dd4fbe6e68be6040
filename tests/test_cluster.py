"""Tuning on a real Dask cluster: a scheduler and two workers started here as processes.

The command line reaches the cluster with ``--scheduler ADDRESS``; the result must be the one
local processes give under the same seeds, and a cluster that is not there must be refused
with one line before any work.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from racing_lib.face.cli import main
from racing_lib.tracks import CircuitSpec, generate

pytest.importorskip("distributed")

pytestmark = pytest.mark.slow


def _start(args: list[str], log: Path) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    with open(log, "w") as out:
        return subprocess.Popen(
            [sys.executable, "-m", *args], stdout=out, stderr=subprocess.STDOUT, env=env
        )


@contextlib.contextmanager
def _cluster(folder: Path, workers: int = 2):
    """A scheduler and ``workers`` single-threaded workers on localhost: (address, processes).

    Workers run without a nanny, so that a killed worker stays dead (a lost machine).
    """
    info = folder / "scheduler.json"
    procs = [
        _start(
            ["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
             "--no-dashboard", "--scheduler-file", str(info)],
            folder / "scheduler.log",
        )
    ]  # fmt: skip
    try:
        for _ in range(300):
            if info.exists() and info.stat().st_size > 0:
                break
            time.sleep(0.1)
        else:
            pytest.fail(
                "the Dask scheduler did not start: " + (folder / "scheduler.log").read_text()
            )
        for k in range(workers):
            procs.append(
                _start(
                    ["distributed.cli.dask_worker", "--scheduler-file", str(info), "--nthreads",
                     "1", "--no-dashboard", "--no-nanny", "--name", f"worker-{k}"],
                    folder / f"worker-{k}.log",
                )
            )  # fmt: skip
        yield json.loads(info.read_text())["address"], procs
    finally:
        for proc in reversed(procs):
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()


@pytest.fixture(scope="module")
def scheduler(tmp_path_factory):
    """The address of a scheduler with two single-threaded workers, on localhost."""
    with _cluster(tmp_path_factory.mktemp("dask")) as (address, _):
        yield address


@pytest.fixture(scope="module")
def circuits(tmp_path_factory) -> Path:
    """Two short generated circuits, so that a lap takes a fraction of a second."""
    folder = tmp_path_factory.mktemp("circuits")
    spec = CircuitSpec(length=(900.0, 1100.0))
    for seed in (1, 2):
        generate(seed, spec, name=f"short-{seed}").to_csv(folder / f"short-{seed}.csv")
    return folder


def _tune(where: list[str], circuits: Path, out: Path, capsys) -> dict:
    argv = ["tune", "--tracks", str(circuits), "--seeds", "2", "--budget", "2", "--popsize", "4"]
    assert main([*argv, *where, "--out", str(out)]) == 0
    capsys.readouterr()
    return json.loads(out.read_text())


def test_tuning_on_the_cluster_equals_tuning_in_local_processes(
    scheduler, circuits, tmp_path, capsys
):
    on_cluster = _tune(["--scheduler", scheduler], circuits, tmp_path / "cluster.json", capsys)
    local = _tune(["--workers", "2"], circuits, tmp_path / "local.json", capsys)
    assert on_cluster["tracks"] == ["short-1", "short-2"] and on_cluster["seeds"] == [0, 1]
    assert on_cluster["laps"] == 2 * 4 * 2 * 2  # generations x candidates x circuits x seeds
    assert on_cluster["weights"] == local["weights"]
    assert on_cluster["best_objective"] == local["best_objective"]
    # The run resumes from its checkpoints: asked again, it drives nothing and answers the same.
    again = _tune(["--scheduler", scheduler], circuits, tmp_path / "cluster.json", capsys)
    assert again["weights"] == on_cluster["weights"]


def test_an_unreachable_scheduler_is_refused_before_any_work(tmp_path, capsys):
    out = tmp_path / "w.json"
    code = main(["tune", "--scheduler", "tcp://127.0.0.1:9", "--budget", "1", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "no Dask scheduler answered" in err and "dask scheduler" in err
    assert "planning" not in err and not out.exists()


def test_a_folder_without_circuits_is_refused(tmp_path, capsys):
    assert main(["tune", "--tracks", str(tmp_path), "--out", str(tmp_path / "w.json")]) == 2
    assert "no track CSV files" in capsys.readouterr().err


@pytest.mark.parametrize("address", ["", "foo", "tcp://127.0.0.1:notaport"])
def test_a_malformed_address_is_refused_at_once(tmp_path, capsys, address):
    out = tmp_path / "w.json"
    assert main(["tune", "--scheduler", address, "--out", str(out)]) == 2
    assert "is not a scheduler address" in capsys.readouterr().err
    assert not out.exists() and not (tmp_path / "w_checkpoints").exists()


def test_ablation_refuses_a_scheduler_with_nothing_to_recompute(capsys):
    assert main(["ablation", "--scheduler", "tcp://127.0.0.1:8786"]) == 2
    assert "without --recompute" in capsys.readouterr().err


def test_checkpoints_of_other_circuits_or_seeds_are_not_resumed(circuits, tmp_path, capsys):
    out = tmp_path / "w.json"
    argv = ["tune", "--budget", "1", "--popsize", "2", "--workers", "1", "--out", str(out)]
    assert main([*argv, "--tracks", str(circuits / "short-1.csv")]) == 0
    for other in (["--tracks", str(circuits)], ["--tracks", str(circuits / "short-1.csv"),
                                                 "--seeds", "2"]):  # fmt: skip
        capsys.readouterr()
        assert main([*argv, *other]) == 2
        assert "tune other circuits or seeds" in capsys.readouterr().err


def test_a_worker_lost_mid_run_loses_no_finished_generation(circuits, tmp_path, capsys):
    """Kill one of two workers after the first generation: the run finishes on the other, with the
    weights a local run gives, and the checkpoints kept every generation."""
    out = tmp_path / "w.json"
    argv = ["tune", "--tracks", str(circuits), "--seeds", "2", "--budget", "3", "--popsize", "4",
            "--out", str(out)]  # fmt: skip
    history = tmp_path / "w_checkpoints" / "history.json"
    with _cluster(tmp_path) as (address, procs):
        run = subprocess.Popen(
            [sys.executable, "-m", "racing_lib.face.cli", *argv, "--scheduler", address],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        for _ in range(600):
            if history.is_file() and json.loads(history.read_text())["generations"] >= 1:
                break
            time.sleep(0.1)
        else:
            run.kill()
            pytest.fail("no generation finished: " + run.communicate()[1][-2000:])
        procs[1].kill()  # a worker lost, without a goodbye
        _, err = run.communicate(timeout=600)
        assert run.returncode == 0, err[-2000:]
    on_cluster = json.loads(out.read_text())
    assert json.loads(history.read_text())["generations"] == 3  # every generation kept
    local = _tune(["--workers", "2", "--budget", "3"], circuits, tmp_path / "local.json", capsys)
    assert on_cluster["weights"] == local["weights"]
