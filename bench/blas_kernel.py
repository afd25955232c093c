"""Which BLAS kernel this benchmark runs (printed beside its figures).

Some machines here set OPENBLAS_CORETYPE (and OPENBLAS_L2_SIZE) because older OpenBLAS builds
compute wrong results or crash on their processors; a current numpy then runs older kernels
(Haswell's AVX2 instead of its AVX-512 ones on this machine's AMD EPYC). A benchmark of the
CPU's own kernel unsets both in that command alone:

    env -u OPENBLAS_CORETYPE -u OPENBLAS_L2_SIZE .venv/bin/python bench/sweep.py

(tests and CI keep the machine's setting). Worker processes inherit the command's environment.
"""

from __future__ import annotations

import os

from threadpoolctl import threadpool_info


def describe() -> str:
    """'openblas 0.3.31 (SkylakeX kernel; OPENBLAS_CORETYPE unset)' for the BLAS numpy loaded."""
    import numpy  # noqa: F401 - loads the BLAS that threadpoolctl reports

    libs = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    setting = os.environ.get("OPENBLAS_CORETYPE")
    override = f"OPENBLAS_CORETYPE={setting}" if setting else "OPENBLAS_CORETYPE unset"
    return "; ".join(f"{i.get('internal_api')} {i.get('version')} ({i.get('architecture') or 'kernel not reported'} kernel; {override})" for i in libs) or "no BLAS reported"
