"""A pinned revision of the repository, checked out beside the working tree for a benchmark.

A benchmark's named reference is often the code of an earlier revision, timed in the same
run as the working tree so that both meet the same machine and load.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

#: The repository this benchmark folder belongs to.
REPO = Path(__file__).resolve().parents[2]


class Revision:
    """A detached git worktree of a revision, removed on exit."""

    def __init__(self, revision: str) -> None:
        self.revision = revision
        self.path = Path(tempfile.mkdtemp(prefix="workbench-ref-")) / "tree"

    def __enter__(self) -> Revision:
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "add", "--detach", str(self.path), self.revision],
            check=True,
            capture_output=True,
        )
        return self

    def __exit__(self, *exc: object) -> None:
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "remove", "--force", str(self.path)],
            check=False,
            capture_output=True,
        )
        shutil.rmtree(self.path.parent, ignore_errors=True)
        subprocess.run(["git", "-C", str(REPO), "worktree", "prune"], check=False)
