"""Build of cosim's compiled step kernels (Cython); everything else is in pyproject.toml.

Each side's step runs in compiled code built here by ``pip install .`` with the
machine's C compiler; the numpy modules beside them stay the readable reference
(``COSIM_KERNEL=numpy`` selects it, see ``cosim.sides.kernel``).
"""
from Cython.Build import cythonize
from setuptools import Extension, setup

KERNELS = [
    Extension("cosim.sides._multibody_step", ["src/cosim/sides/_multibody_step.pyx"]),
    Extension("cosim.sides._structure_step", ["src/cosim/sides/_structure_step.pyx"]),
]

setup(ext_modules=cythonize(KERNELS, language_level=3,
                            compiler_directives={"embedsignature": True}))
