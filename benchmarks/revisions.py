"""This checkout's core against an earlier revision's, in interleaved processes.

A benchmark script that defines `measure(core_root)` (returning something JSON can carry, with
the core found at core_root imported) calls `interleaved(script, before, rounds)`: the revision
is checked out in a temporary git worktree, and the two cores are measured in turn (A B A B ...),
each in a fresh process, so that a drifting machine affects both alike.
"""

import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def measure_in_process(script, core_root):
    """`measure(core_root)` of the benchmark file `script`, run in a fresh process whose working
    directory is core_root (so that its core, alone, is imported there)."""
    code = (
        "import importlib.util, json; "
        f"spec = importlib.util.spec_from_file_location('measured', {str(script)!r}); "
        "m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m); "
        f"print(json.dumps(m.measure({str(core_root)!r})))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=core_root
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def interleaved(script, before, rounds):
    """(now, earlier, commit): `rounds` measurements each of this checkout and of git revision
    `before`, taken in turn, and this checkout's short commit."""
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    with tempfile.TemporaryDirectory() as tmp:
        old = Path(tmp) / "before"
        subprocess.run(["git", "worktree", "add", "-q", "--detach", str(old), before], cwd=ROOT, check=True)
        try:
            now, earlier = [], []
            for _ in range(rounds):
                now.append(measure_in_process(script, ROOT))
                earlier.append(measure_in_process(script, old))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=ROOT, check=False)
    return now, earlier, commit.stdout.strip()
