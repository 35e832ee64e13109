"""Pool workers end with their parent, even when it is killed outright."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

PROC = Path("/proc")
pytestmark = pytest.mark.skipif(
    not (PROC / "self" / "stat").exists(), reason="reads the process table from /proc (Linux)"
)


def _stat(pid: int) -> list[str] | None:
    """Fields of /proc/PID/stat after the command name (state first), None once it is gone."""
    try:
        text = (PROC / str(pid) / "stat").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2 :].split()


def _children(pid: int) -> list[int]:
    found = []
    for entry in PROC.iterdir():
        if entry.name.isdigit() and (fields := _stat(int(entry.name))) and fields[1] == str(pid):
            found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    fields = _stat(pid)
    return fields is not None and fields[0] not in ("Z", "X")  # a zombie has ended


# Two workers that would each sleep for ten minutes: alive long after the test's deadline
# unless something ends them.
SCRIPT = textwrap.dedent(
    """
    import time
    from workbench.executor import run_tasks

    if __name__ == "__main__":
        for _ in run_tasks(time.sleep, [600.0, 600.0], workers=2):
            pass
    """
)


def _wait_for(condition, seconds: float, step: float = 0.1) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(step)
    return condition()


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="kill -9 is a POSIX signal")
def test_workers_and_the_resource_tracker_end_when_the_parent_is_killed(tmp_path):
    script = tmp_path / "run.py"
    script.write_text(SCRIPT)
    # The workbench under test, not another installed copy: the script lies elsewhere.
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    parent = subprocess.Popen([sys.executable, str(script)], env=env)
    children: list[int] = []
    try:
        # The two workers and the resource tracker, once they have all started.
        assert _wait_for(lambda: len(_children(parent.pid)) >= 3, 120)
        children = _children(parent.pid)
        time.sleep(1.0)  # the workers are inside their tasks, past the initializer
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait()
        # The watch looks every 0.5 s; ten seconds leaves room for a loaded machine.
        assert _wait_for(lambda: not any(_alive(c) for c in children), 10), [
            c for c in children if _alive(c)
        ]
    finally:
        for child in children:
            if _alive(child):
                os.kill(child, signal.SIGKILL)
        if parent.poll() is None:
            parent.kill()


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="kill -9 is a POSIX signal")
def test_a_batch_killed_outright_leaves_no_worker_running(tmp_path):
    from workbench.population.study import StudyDesign, study_plan, write_study

    design = StudyDesign(n_male=1, n_female=1, n_records=None, duration_s=3.0)
    manifest = write_study(study_plan(design, seed=11).iloc[:4], tmp_path / "study", design)
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    cmd = [sys.executable, "-m", "workbench", "batch", str(manifest), "--out"]
    cmd += [str(tmp_path / "out"), "--workers", "2", "--method", "rbpf", "--json"]
    parent = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    children: list[int] = []
    try:
        # The two workers and the resource tracker, once they have all started.
        assert _wait_for(lambda: len(_children(parent.pid)) >= 3, 120)
        children = _children(parent.pid)
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait()
        assert _wait_for(lambda: not any(_alive(c) for c in children), 10), [
            c for c in children if _alive(c)
        ]
    finally:
        for child in children:
            if _alive(child):
                os.kill(child, signal.SIGKILL)
        if parent.poll() is None:
            parent.kill()
