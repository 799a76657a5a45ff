"""Build of cosim's compiled step kernels (Cython); everything else is in pyproject.toml.

Each side's step runs in compiled code built here by ``pip install .`` with the
machine's C compiler; the numpy modules beside them stay the readable reference
(``COSIM_KERNEL=numpy`` selects it, see ``cosim.sides.kernel``).
"""
from Cython.Build import cythonize
from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

#: the face every side's compiled model-exchange face derives from (cimported)
FACE = "src/cosim/core/_stacked.pxd"

KERNELS = [
    Extension("cosim.sides._multibody_step", ["src/cosim/sides/_multibody_step.pyx"],
              depends=[FACE]),
    # the implicit scheme's iterations, which call the sides' kernels through
    # the C face they fill in (cosim/core/_side_face.pxd, declarations only)
    Extension("cosim.core.schemes._implicit_step", ["src/cosim/core/schemes/_implicit_step.pyx"]),
    Extension("cosim.sides._structure_step", ["src/cosim/sides/_structure_step.pyx"]),
    Extension("cosim.core.schemes._driver", ["src/cosim/core/schemes/_driver.pyx"]),
    # the monolithic reference's right-hand side, and the structure's face it calls
    Extension("cosim.core._stacked", ["src/cosim/core/_stacked.pyx"], depends=[FACE]),
    Extension("cosim.sides._modal_face", ["src/cosim/sides/_modal_face.pyx"], depends=[FACE]),
]

#: Every a * b + c in the kernels is rounded twice, as written and as Python and
#: numpy round it.  GCC contracts it into one fused multiply-add (rounded once)
#: wherever the target has FMA -- by default on arm64, ppc64le and s390x, and on
#: x86-64 under -march=haswell or later -- and Clang within an expression; the
#: compiled steps would then round otherwise on each architecture.  Contraction
#: off, they give the same bits on every target (given the same C library
#: functions: sin, cos, pow): built here with -march=native
#: they match the baseline x86-64 build bit for bit, while contracted they do
#: not, and a result that round-off decides (the stalled step of
#: tests/test_kernel_structure.py) changes.
NO_CONTRACTION = "-ffp-contract=off"


class BuildKernels(build_ext):
    """``build_ext`` that turns contraction off where the compiler takes GCC's
    options (MSVC since 2022 does not contract under its default /fp:precise,
    and does not know the option)."""

    def build_extensions(self):
        if self.compiler.compiler_type in ("unix", "mingw32", "cygwin"):
            for ext in self.extensions:
                if NO_CONTRACTION not in ext.extra_compile_args:
                    ext.extra_compile_args.append(NO_CONTRACTION)
        super().build_extensions()


# include_path: the kernels cimport cosim.core._side_face from the sources
setup(ext_modules=cythonize(KERNELS, language_level=3, include_path=["src"],
                            compiler_directives={"embedsignature": True}),
      cmdclass={"build_ext": BuildKernels})
