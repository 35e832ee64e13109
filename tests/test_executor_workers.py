"""Pool workers end with their parent, even when it is killed outright."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

psutil = pytest.importorskip("psutil")

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


def _alive(proc) -> bool:
    try:
        return proc.is_running() and proc.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(signal, "SIGKILL"), reason="kill -9 is a POSIX signal")
def test_workers_and_the_resource_tracker_end_when_the_parent_is_killed(tmp_path):
    script = tmp_path / "run.py"
    script.write_text(SCRIPT)
    # The workbench under test, not another installed copy: the script lies elsewhere.
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")])}
    parent = subprocess.Popen([sys.executable, str(script)], env=env)
    try:
        # The two workers and the resource tracker, once they have all started.
        assert _wait_for(lambda: len(psutil.Process(parent.pid).children()) >= 3, 120)
        children = psutil.Process(parent.pid).children(recursive=True)
        time.sleep(1.0)  # the workers are inside their tasks, past the initializer
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait()
        # The watch looks every 0.5 s; ten seconds leaves room for a loaded machine.
        assert _wait_for(lambda: not any(_alive(c) for c in children), 10), [
            c.pid for c in children if _alive(c)
        ]
    finally:
        for child in psutil.Process(os.getpid()).children(recursive=True):
            if child.pid != parent.pid and _alive(child):
                child.kill()
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
    try:
        # The two workers and the resource tracker, once they have all started.
        assert _wait_for(lambda: len(psutil.Process(parent.pid).children()) >= 3, 120)
        children = psutil.Process(parent.pid).children(recursive=True)
        os.kill(parent.pid, signal.SIGKILL)
        parent.wait()
        assert _wait_for(lambda: not any(_alive(c) for c in children), 10), [
            c.pid for c in children if _alive(c)
        ]
    finally:
        for child in psutil.Process(os.getpid()).children(recursive=True):
            if child.pid != parent.pid and _alive(child):
                child.kill()
        if parent.poll() is None:
            parent.kill()
