"""The package's one compiled module, optional: without a C compiler scrapcut still installs
and runs, on open3d's and scipy's code instead (slower; ``scrapcut_cli/_kernels.py``)."""

import sys

from setuptools import Extension, setup

# No fused multiply-add: a contracted a*b + c rounds differently and a point on the outlier
# threshold could change sides between machines.
ARGS = [] if sys.platform == "win32" else ["-O2", "-ffp-contract=off"]

setup(
    ext_modules=[
        Extension(
            "scrapcut_cli._native",
            ["scrapcut_cli/_native.c"],
            extra_compile_args=ARGS,
            optional=True,
        )
    ]
)
