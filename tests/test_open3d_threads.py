"""open3d honours OMP_NUM_THREADS (scrapcut_cli/_open3d.py): its TBB pool does not read the
variable itself, so a Dask worker whose nanny set it to 1 ran open3d's outlier removal on every
core. In fresh interpreters: the limit is process-wide."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CODE = (
    "import os, numpy as np\n"
    "from scrapcut_cli._open3d import o3d\n"
    "from scrapcut_cli.perception.cloud import statistical_inliers\n"
    "pts = np.random.default_rng(0).random((3000, 3))\n"
    "kept = statistical_inliers(pts, neighbors=20, std_ratio=2.0)\n"
    "print(len(os.listdir('/proc/self/task')), o3d().utility.get_max_threads(), len(kept))\n"
)


def _run(threads: str | None) -> list[int]:
    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    env["PYTHONPATH"] = str(ROOT)
    if threads is not None:
        env["OMP_NUM_THREADS"] = threads
    result = subprocess.run(
        [sys.executable, "-c", CODE], capture_output=True, text=True, env=env, timeout=120
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return [int(v) for v in result.stdout.split()]


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="counts threads in /proc")
def test_one_thread_when_omp_num_threads_says_one() -> None:
    from scrapcut_cli._open3d import o3d

    if not hasattr(o3d().utility, "set_max_threads"):
        pytest.skip("this open3d has no thread limit to set")
    os_threads, limit, kept = _run("1")
    assert (os_threads, limit) == (1, 1)
    # Unset, or not a count of threads: open3d's own default; the same points kept either way.
    _, default, same = _run(None)
    assert same == kept
    assert _run("abc")[1:] == [default, kept]
