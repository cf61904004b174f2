"""Outputs that never destroy data (tangraph.outputs): a set of files written as one, SIGTERM as a
clean stop, and the partial folders of killed runs (removed by the next demo)."""

from __future__ import annotations

import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

import tangraph.navigation
from tangraph.demo import run_demo
from tangraph.outputs import (
    OutputSet,
    Terminated,
    deferred_signals,
    remove_stale_partials,
    sigterm_exits,
)

REPO = Path(__file__).resolve().parents[1]


def _dead_pid() -> int:
    """The PID of a process that has ended (and been reaped)."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    return child.pid


# -- OutputSet ---------------------------------------------------------------------------------
def test_all_files_appear_together_with_the_usual_mode(tmp_path):
    a, b = tmp_path / "track.csv", tmp_path / "sub" / "track.tum"
    with OutputSet() as outputs:
        tmp_a, tmp_b = outputs.path(a), outputs.path(b)
        assert tmp_a.parent == a.parent and tmp_a.suffix == ".csv" and tmp_a.name.startswith(".")
        assert tmp_b.parent == b.parent and tmp_b.suffix == ".tum"
        tmp_a.write_text("a")
        tmp_b.write_text("b")
        assert not a.exists() and not b.exists()  # nothing in place before the end
    assert a.read_text() == "a" and b.read_text() == "b"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(a.stat().st_mode) == 0o666 & ~umask
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["sub", "track.csv", "track.tum"]


@pytest.mark.parametrize("error", [RuntimeError("disk full"), KeyboardInterrupt(), Terminated()])
def test_an_error_while_writing_the_second_file_leaves_neither(tmp_path, error):
    first, second, figure = tmp_path / "track.csv", tmp_path / "track.tum", tmp_path / "track.png"
    figure.write_text("the old figure")  # existing: replaced only on success, kept on failure
    with pytest.raises(type(error)), OutputSet(overwrite=True) as outputs:
        outputs.path(first).write_text("first")
        outputs.path(figure).write_text("new figure")
        outputs.path(second).write_text("half of the sec")
        raise error
    assert not first.exists() and not second.exists()
    assert figure.read_text() == "the old figure"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["track.png"]


def test_existing_targets_are_refused_unless_overwrite(tmp_path):
    kept, new = tmp_path / "kept.csv", tmp_path / "new.csv"
    kept.write_text("precious")
    with pytest.raises(FileExistsError, match="--force"), OutputSet() as outputs:
        outputs.path(new).write_text("new")
        outputs.path(kept)
    assert kept.read_text() == "precious" and not new.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.csv"]
    with OutputSet(overwrite=True) as outputs:
        outputs.path(kept).write_text("replaced")
    assert kept.read_text() == "replaced"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.csv"]


def test_a_target_that_appears_meanwhile_is_not_clobbered(tmp_path):
    late, other = tmp_path / "late.csv", tmp_path / "other.csv"
    with pytest.raises(FileExistsError), OutputSet() as outputs:
        outputs.path(other).write_text("other")
        outputs.path(late).write_text("mine")
        late.write_text("someone else's")
    assert late.read_text() == "someone else's" and not other.exists()


def test_the_same_target_twice_is_refused(tmp_path):
    with pytest.raises(ValueError, match="already an output"), OutputSet() as outputs:
        outputs.path(tmp_path / "a.csv")
        outputs.path(tmp_path / "." / "a.csv")
    assert list(tmp_path.iterdir()) == []


def test_a_rename_failing_part_way_puts_the_old_files_back(tmp_path, monkeypatch):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text("old a")
    b.write_text("old b")
    real = os.replace
    calls = []

    def failing(src, dst):
        calls.append(dst)
        if Path(dst) == b and ".partial-" in Path(src).name:  # a is already replaced by then
            raise OSError("no space left on device")
        return real(src, dst)

    monkeypatch.setattr(os, "replace", failing)
    with pytest.raises(OSError, match="no space"), OutputSet(overwrite=True) as outputs:
        outputs.path(a).write_text("new a")
        outputs.path(b).write_text("new b")
    monkeypatch.undo()
    assert a in [Path(c) for c in calls]
    assert a.read_text() == "old a" and b.read_text() == "old b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "b.csv"]


# -- stale partial folders ---------------------------------------------------------------------
def test_a_stale_partial_folder_goes_and_a_live_one_stays(tmp_path):
    dead, alive = _dead_pid(), os.getppid()
    stale = tmp_path / f".demo.partial-{dead}"
    (stale / "tracks").mkdir(parents=True)
    (stale / "report.md").write_text("half")
    running = tmp_path / f".demo.partial-{alive}"
    running.mkdir()
    own = tmp_path / f".demo.partial-{os.getpid()}"
    own.mkdir()
    unrelated = [tmp_path / f".other.partial-{dead}", tmp_path / "demo.partial-1",
                 tmp_path / ".demo.partial-x"]
    for path in unrelated:
        path.mkdir()
    old = tmp_path / f".demo.old-{dead}"
    old.mkdir()
    assert remove_stale_partials(tmp_path / "demo") == [stale]
    assert running.is_dir() and own.is_dir() and all(p.is_dir() for p in unrelated)
    assert old.is_dir()  # with no demo/ beside it, the old report may be the only copy left
    (tmp_path / "demo").mkdir()
    assert remove_stale_partials(tmp_path / "demo") == [old]
    assert remove_stale_partials(tmp_path / "nowhere" / "demo") == []


def test_an_output_set_removes_the_stale_temporary_files_of_its_targets(tmp_path):
    dead, alive = _dead_pid(), os.getppid()
    stale = tmp_path / f".track.partial-{dead}-k3x_9q.csv"
    running = tmp_path / f".track.partial-{alive}-abc123.csv"
    backup = tmp_path / f".track.old-{dead}-zz9.csv"  # the only copy while track.csv is missing
    other = tmp_path / f".track.partial-{dead}-k3x_9q.tum"  # another target's
    for path in (stale, running, backup, other):
        path.write_text("left over")
    with OutputSet() as outputs:
        outputs.path(tmp_path / "track.csv").write_text("new")
    assert not stale.exists() and running.exists() and backup.exists() and other.exists()
    with OutputSet(overwrite=True) as outputs:  # now track.csv exists: the backup is stale
        outputs.path(tmp_path / "track.csv").write_text("newer")
    assert not backup.exists() and running.exists() and other.exists()
    assert (tmp_path / "track.csv").read_text() == "newer"


def test_the_next_demo_removes_a_stale_partial_folder(tmp_path, monkeypatch):
    stale = tmp_path / f".demo.partial-{_dead_pid()}"
    (stale / "tracks").mkdir(parents=True)
    running = tmp_path / f".demo.partial-{os.getppid()}"
    running.mkdir()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(tangraph.navigation, "navigate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_demo(tmp_path / "demo", quick=True, progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == [running.name]


# -- SIGTERM -----------------------------------------------------------------------------------
needs_default_sigterm = pytest.mark.skipif(
    os.name != "posix" or signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL,
    reason="needs POSIX signals and the default SIGTERM handler",
)


@needs_default_sigterm
def test_sigterm_raises_terminated_and_the_handler_comes_back():
    with pytest.raises(Terminated) as caught, sigterm_exits():
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):  # the handler runs at the next bytecode
            time.sleep(0.001)
    assert caught.value.code == 143
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


@needs_default_sigterm
def test_signals_wait_for_the_renames():
    done = []
    with pytest.raises(Terminated), sigterm_exits():
        with deferred_signals():
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.05)
            done.append("renamed")
        time.sleep(1.0)
    assert done == ["renamed"]


@pytest.mark.skipif(not hasattr(signal, "SIGTERM") or os.name != "posix", reason="POSIX signals")
def test_sigterm_stops_the_demo_and_leaves_no_partial_folder(tmp_path):
    out = tmp_path / "demo"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    demo = subprocess.Popen(
        [sys.executable, "-m", "tangraph.cli", "demo", "--quick", "-q", "--out", str(out)],
        cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".demo.partial-*")) and demo.poll() is None:
        assert time.monotonic() < deadline, "the demo made no partial folder"
        time.sleep(0.02)
    assert demo.poll() is None, demo.communicate()
    demo.send_signal(signal.SIGTERM)
    _, err = demo.communicate(timeout=60)
    assert demo.returncode == 143, err
    assert "Traceback" not in err and "stopped by SIGTERM" in err
    assert list(tmp_path.iterdir()) == []
