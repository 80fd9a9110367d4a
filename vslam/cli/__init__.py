"""Command-line interface; see `vslam.cli.main`.

Our matrix products are small ((N, 2) @ (2, 2) and the like): multi-threaded OpenBLAS only adds overhead, and on a
busy 2-core machine it made them up to 100x slower. The CLI therefore defaults BLAS to one thread; this runs before
numpy is first imported, and an explicit setting in the environment wins.
"""
import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
