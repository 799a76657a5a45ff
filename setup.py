"""Build of cosim's compiled step kernels (Cython); everything else is in pyproject.toml.

Each side's step runs in compiled code built here by ``pip install .`` with the
machine's C compiler; the numpy modules beside them stay the readable reference
(``COSIM_KERNEL=numpy`` selects it, see ``cosim.sides.kernel``).
"""
from pathlib import Path

from Cython.Build import cythonize
from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.command.build_py import build_py

#: the face every side's compiled model-exchange face derives from (cimported)
FACE = "src/cosim/core/_stacked.pxd"
#: the C face a side's compiled step offers the schemes' compiled loops (cimported)
SIDE_FACE = "src/cosim/core/_side_face.pxd"
#: the sub-step's cubic Hermite and peaks, inline (a .pxd alone)
HERMITE = "src/cosim/sides/_hermite.pxd"

KERNELS = [
    # the multibody step (the integrator) extends the tree's model (its .pxd)
    Extension("cosim.sides._multibody_tree", ["src/cosim/sides/_multibody_tree.pyx"]),
    Extension("cosim.sides._multibody_step", ["src/cosim/sides/_multibody_step.pyx"],
              depends=[SIDE_FACE, "src/cosim/sides/_multibody_tree.pxd", HERMITE]),
    # the tree's model-exchange face, for the monolithic reference
    Extension("cosim.sides._tree_face", ["src/cosim/sides/_tree_face.pyx"],
              depends=[FACE, "src/cosim/sides/_multibody_tree.pxd"]),
    # the embedded Runge-Kutta pairs (DOP853, RK45) over the tree's right-hand side (its .pxd)
    Extension("cosim.sides._embedded_rk", ["src/cosim/sides/_embedded_rk.pyx"],
              depends=["src/cosim/sides/_multibody_tree.pxd"]),
    # the implicit scheme's iterations, which call the sides' kernels through
    # the C face they fill in (cosim/core/_side_face.pxd, declarations only)
    Extension("cosim.core.schemes._implicit_step", ["src/cosim/core/schemes/_implicit_step.pyx"],
              depends=["src/cosim/core/schemes/_implicit_step.pxd", SIDE_FACE]),
    # the implicit scheme's macro loop, which calls the iterations through their .pxd
    Extension("cosim.core.schemes._implicit_block", ["src/cosim/core/schemes/_implicit_block.pyx"],
              depends=["src/cosim/core/schemes/_implicit_step.pxd", SIDE_FACE]),
    # the structure's step (its Python face) extends the contact phases, which
    # extend the modal response, which calls the rank-one update (their .pxd)
    Extension("cosim.sides._rank_one", ["src/cosim/sides/_rank_one.pyx"]),
    Extension("cosim.sides._structure_modes", ["src/cosim/sides/_structure_modes.pyx"],
              depends=["src/cosim/sides/_rank_one.pxd"]),
    Extension("cosim.sides._structure_contacts", ["src/cosim/sides/_structure_contacts.pyx"],
              depends=["src/cosim/sides/_structure_modes.pxd", SIDE_FACE]),
    # the structure's RK4 with hosted penalty contacts, over the tree's laws (its .pxd)
    Extension("cosim.sides._structure_rk", ["src/cosim/sides/_structure_rk.pyx"],
              depends=["src/cosim/sides/_multibody_tree.pxd", HERMITE]),
    Extension("cosim.sides._structure_step", ["src/cosim/sides/_structure_step.pyx"],
              depends=["src/cosim/sides/_structure_modes.pxd",
                       "src/cosim/sides/_structure_contacts.pxd", SIDE_FACE]),
    # the compiled loop, and its following contacts (which call the structure's
    # face through cosim/core/_stacked.pxd, declarations only)
    Extension("cosim.core.schemes._driver", ["src/cosim/core/schemes/_driver.pyx"],
              depends=["src/cosim/core/schemes/_follow.pxd", "src/cosim/core/schemes/_driver.pxd",
                       "src/cosim/core/schemes/_driver_faces.pxd", SIDE_FACE]),
    # the sides as the compiled loop holds them, stepped through their C faces
    Extension("cosim.core.schemes._driver_faces", ["src/cosim/core/schemes/_driver_faces.pyx"],
              depends=["src/cosim/core/schemes/_driver_faces.pxd", SIDE_FACE]),
    # the compiled loop's samples in blocks (calls the loop's steps in C)
    Extension("cosim.core.schemes._driver_block", ["src/cosim/core/schemes/_driver_block.pyx"],
              depends=["src/cosim/core/schemes/_driver.pxd",
                       "src/cosim/core/schemes/_driver_faces.pxd", SIDE_FACE]),
    Extension("cosim.core.schemes._follow", ["src/cosim/core/schemes/_follow.pyx"],
              depends=[FACE]),
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


#: The kernels' generated C is about 2 MB each; Python's own flags build it at -O3
#: with debug information (-g), which takes twice the compiler's time of -O2 without
#: it (15 s against 7.7 s of CPU for the structure step), for no faster step: the
#: kernels are loops over small arrays.  The last -O and -g on the command line win,
#: and neither changes a result (no flag here lets the compiler reorder floating-point
#: arithmetic).  `pip install -v .` shows each compiler command as it starts.
QUICK = ["-O2", "-g0"]


class BuildKernels(build_ext):
    """``build_ext`` that turns contraction off where the compiler takes GCC's
    options (MSVC since 2022 does not contract under its default /fp:precise,
    and does not know the option), compiles at -O2 without debug information
    there, and builds the kernels side by side, one compiler per CPU (``pip
    install`` passes no ``--parallel`` of its own)."""

    def finalize_options(self):
        super().finalize_options()
        if not self.parallel:
            self.parallel = True           # as many compilers as CPUs

    def run(self):
        # Cython's translation when the kernels are built, not at every setup.py
        # command: `egg_info` and `build_py` (a wheel's pure-Python step, and
        # the shipped files' test) need no C.  include_path: the kernels
        # cimport cosim.core._side_face from the sources
        # (the C sources replace the .pyx in the extensions setuptools has
        # finalised: cythonize returns copies without setuptools' own fields)
        translated = {ext.name: ext for ext in cythonize(
            self.extensions, language_level=3, include_path=["src"],
            compiler_directives={"embedsignature": True})}
        for ext in self.extensions:
            ext.sources = translated[ext.name].sources
        super().run()

    def build_extensions(self):
        if self.compiler.compiler_type in ("unix", "mingw32", "cygwin"):
            for ext in self.extensions:
                for flag in (NO_CONTRACTION, *QUICK):
                    if flag not in ext.extra_compile_args:
                        ext.extra_compile_args.append(flag)
        super().build_extensions()


#: folders of the repository shipped inside the package, as ``cosim/_shipped/NAME``:
#: the verification cases and the studies, so that `cosim run spring_drop`,
#: `cosim verify` and `cosim sweep --study NAME` work from any folder.  The
#: repository keeps the one copy at its root (the paths the docs use);
#: ``cosim.scene.shipped`` finds them in either place.
#: A plane body's scene ships its mesh (``.msh``) and the Gmsh script that made it (``.geo``).
SHIPPED = {"cases": ("*.toml", "*.msh", "*.geo"), "studies": ("*.toml",)}


def shipped_files(root="."):
    """``(source, path inside the package)`` of each shipped file."""
    root = Path(root)
    for folder, patterns in SHIPPED.items():
        for src in sorted(p for pattern in patterns for p in (root / folder).glob(pattern)):
            yield src, Path("cosim", "_shipped", folder, src.name)


class BuildWithShipped(build_py):
    """``build_py`` that also copies :data:`SHIPPED` into the built package."""

    def run(self):
        super().run()
        for src, rel in shipped_files(Path(__file__).resolve().parent):
            target = Path(self.build_lib) / rel
            self.mkpath(str(target.parent))
            self.copy_file(str(src), str(target))


if __name__ == "__main__":
    setup(ext_modules=KERNELS,
          cmdclass={"build_ext": BuildKernels, "build_py": BuildWithShipped})
