"""One BLAS / OpenMP thread per process, for the benchmarks that spread seeds over processes
or time solves: imported before numpy by those benchmarks (``import benchmarks._single_thread``
as their first import; the variables only take effect before numpy is loaded). A value set
in the environment beforehand wins."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
