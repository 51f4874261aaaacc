"""One BLAS thread per process (common/blas_threads.py): set on import of the package, before
numpy loads its BLAS, and never over a user's own setting."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from haptic.common.blas_threads import BLAS_THREAD_VARIABLES

PACKAGES = ("haptic.common", "haptic.master", "haptic.slave_sim", "haptic.lockstep",
            "haptic.view")


def _python(code: str, **env: str) -> str:
    """Run ``code`` in a fresh interpreter without the BLAS variables (plus ``env``)."""
    clean = {k: v for k, v in os.environ.items() if k not in BLAS_THREAD_VARIABLES}
    clean.update(env)
    done = subprocess.run([sys.executable, "-c", code], env=clean, capture_output=True,
                          text=True, timeout=120, check=True)
    return done.stdout.strip()


@pytest.mark.parametrize("package", PACKAGES)
def test_each_top_level_package_sets_one_blas_thread(package: str) -> None:
    code = (f"import os, {package}\n"
            f"print(' '.join(os.environ.get(n, '-') for n in {BLAS_THREAD_VARIABLES!r}))")
    assert _python(code) == " ".join("1" for _ in BLAS_THREAD_VARIABLES)


def test_a_users_own_setting_wins() -> None:
    code = "import os, haptic.lockstep; print(os.environ['OPENBLAS_NUM_THREADS'])"
    assert _python(code, OPENBLAS_NUM_THREADS="3") == "3"


@pytest.mark.skipif(not os.path.isdir("/proc/self/task") or (os.cpu_count() or 1) < 2,
                    reason="counts threads in /proc on a machine with 2 CPUs or more")
def test_numpy_loaded_after_the_package_starts_no_blas_worker() -> None:
    """Without the setting OpenBLAS starts one worker per further CPU when numpy loads."""
    count = ("import os, numpy as np\n"
             "np.linalg.eigvals(np.random.default_rng(0).random((300, 300)))\n"
             "print(len(os.listdir('/proc/self/task')))")
    assert _python("import haptic.common\n" + count) == "1"
    if "openblas" in _python("import numpy; numpy.show_config()").lower():
        assert int(_python(count)) > 1  # the check above can fail: the pool is there without
