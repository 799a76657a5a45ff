"""Build the two-link arm of ``arm2.c`` into a co-simulation FMU.

A plain C compiler call against the FMI headers that FMPy ships
(``fmpy/c-code``), then the model description written from :data:`VARIABLES`
and both zipped into ``arm2.fmu`` (FMI 2.0 or 3.0, with or without
``canGetAndSetFMUstate``).  The FMI functions the arm does not implement
(model exchange, integers, strings, ...) are compiled as stubs that return an
error, so that FMPy finds every symbol it loads.

Usage: ``python examples/fmu/build.py OUT_DIR [--fmi 3] [--no-state]``.
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "arm2.c"
MODEL_IDENTIFIER = "arm2"

#: (name, causality, start or None, unit, description); the value reference
#: is the index, as in arm2.c's enum
VARIABLES = [
    ("l1", "parameter", 0.2, "m", "length of link 1"),
    ("l2", "parameter", 0.15, "m", "length of link 2 (joint 2 to the tip)"),
    ("m1", "parameter", 1.0, "kg", "mass of link 1"),
    ("m2", "parameter", 0.5, "kg", "mass of link 2"),
    ("I1", "parameter", 1.0 * 0.2 ** 2 / 12, "kg.m2", "inertia of link 1 about its mass centre"),
    ("I2", "parameter", 0.5 * 0.15 ** 2 / 12, "kg.m2", "inertia of link 2 about its mass centre"),
    ("lc1", "parameter", 0.1, "m", "joint 1 to link 1's mass centre"),
    ("lc2", "parameter", 0.075, "m", "joint 2 to link 2's mass centre"),
    ("base_x", "parameter", 0.2, "m", "joint 1, x"),
    ("base_y", "parameter", 0.06, "m", "joint 1, y"),
    ("g", "parameter", 9.81, "m/s2", "gravity along -y"),
    ("q1_start", "parameter", 0.0, "rad", "initial q1"),
    ("q2_start", "parameter", -0.3, "rad", "initial q2"),
    ("dq1_start", "parameter", -3.0, "rad/s", "initial dq1"),
    ("dq2_start", "parameter", 0.0, "rad/s", "initial dq2"),
    ("max_step", "parameter", 1e-5, "s", "largest RK4 sub-step inside doStep"),
    ("fx", "input", 0.0, "N", "force on the tip, x"),
    ("fy", "input", 0.0, "N", "force on the tip, y"),
    ("x", "output", None, "m", "tip position, x"),
    ("y", "output", None, "m", "tip position, y"),
    ("vx", "output", None, "m/s", "tip velocity, x"),
    ("vy", "output", None, "m/s", "tip velocity, y"),
    ("q1", "output", None, "rad", "joint 1 angle"),
    ("q2", "output", None, "rad", "joint 2 angle"),
    ("dq1", "output", None, "rad/s", "joint 1 rate"),
    ("dq2", "output", None, "rad/s", "joint 2 rate"),
    ("energy", "output", None, "J", "kinetic plus gravitational energy"),
    ("mass_y", "output", None, "kg", "effective mass of the tip along y"),
]

_STATE_FUNCTIONS = {2: ("fmi2GetFMUstate", "fmi2SetFMUstate", "fmi2FreeFMUstate"),
                    3: ("fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState")}


def headers() -> Path:
    """FMPy's folder of FMI C headers."""
    import fmpy
    return Path(fmpy.__file__).resolve().parent / "c-code"


def find_compiler() -> str | None:
    """The machine's C compiler (``$CC``, ``gcc`` or ``cc``), or None."""
    for name in (os.environ.get("CC"), "gcc", "cc"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def _stubs(version: int, state: bool) -> str:
    """C source defining, as functions that return an error, every FMI
    function of the header that arm2.c does not define."""
    header = (headers() / f"fmi{version}Functions.h").read_text()
    declared = re.findall(rf"FMI{version}_Export\s+fmi{version}\w+TYPE\s+(fmi{version}\w+)\s*;",
                          header)
    source = SOURCE.read_text()
    defined = set(re.findall(rf"^[A-Za-z][\w ]*?\**\s*\b(fmi{version}[A-Z]\w*)\(", source,
                             re.MULTILINE))
    if not state:
        defined -= set(_STATE_FUNCTIONS[version])
    return "".join(f"int {name}(void) {{ return 3; }}\n" for name in declared
                   if name not in defined)


def _description(version: int, state: bool) -> str:
    token = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"cosim-arm2-fmi{version}")) + "}"
    flag = "true" if state else "false"
    outputs = [i for i, v in enumerate(VARIABLES) if v[1] == "output"]
    lines = ['<?xml version="1.0" encoding="UTF-8"?>']
    if version == 2:
        lines += [f'<fmiModelDescription fmiVersion="2.0" modelName="arm2" guid="{token}" '
                  f'generationTool="cosim examples/fmu/build.py" '
                  f'variableNamingConvention="flat" numberOfEventIndicators="0">',
                  f'  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}" '
                  f'canHandleVariableCommunicationStepSize="true" canInterpolateInputs="true" '
                  f'canGetAndSetFMUstate="{flag}"/>', "  <ModelVariables>"]
        for vr, (name, causality, start, unit, text) in enumerate(VARIABLES):
            kind = "fixed" if causality == "parameter" else "continuous"
            init = (' initial="exact"' if causality == "parameter" else
                    ' initial="calculated"' if causality == "output" else "")
            real = f'<Real start="{start!r}"/>' if start is not None else "<Real/>"
            lines.append(f"    <ScalarVariable name={quoteattr(name)} valueReference=\"{vr}\" "
                         f"description={quoteattr(text + ' [' + unit + ']')} "
                         f"causality=\"{causality}\" variability=\"{kind}\"{init}>{real}"
                         f"</ScalarVariable>")
        lines += ["  </ModelVariables>", "  <ModelStructure>", "    <Outputs>"]
        lines += [f'      <Unknown index="{i + 1}"/>' for i in outputs]
        lines += ["    </Outputs>", "    <InitialUnknowns>"]
        lines += [f'      <Unknown index="{i + 1}"/>' for i in outputs]
        lines += ["    </InitialUnknowns>", "  </ModelStructure>", "</fmiModelDescription>"]
    else:
        lines += [f'<fmiModelDescription fmiVersion="3.0" modelName="arm2" '
                  f'instantiationToken="{token}" generationTool="cosim examples/fmu/build.py">',
                  f'  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}" '
                  f'canHandleVariableCommunicationStepSize="true" '
                  f'canGetAndSetFMUState="{flag}"/>', "  <ModelVariables>",
                  f'    <Float64 name="time" valueReference="{len(VARIABLES)}" '
                  f'causality="independent" variability="continuous"/>']
        for vr, (name, causality, start, unit, text) in enumerate(VARIABLES):
            kind = "fixed" if causality == "parameter" else "continuous"
            extra = f' start="{start!r}"' if start is not None else ""
            lines.append(f"    <Float64 name={quoteattr(name)} valueReference=\"{vr}\" "
                         f"description={quoteattr(text + ' [' + unit + ']')} "
                         f"causality=\"{causality}\" variability=\"{kind}\"{extra}/>")
        lines += ["  </ModelVariables>", "  <ModelStructure>"]
        lines += [f'    <Output valueReference="{i}"/>' for i in outputs]
        lines += [f'    <InitialUnknown valueReference="{i}"/>' for i in outputs]
        lines += ["  </ModelStructure>", "</fmiModelDescription>"]
    return "\n".join(lines) + "\n"


def build_fmu(out_dir, fmi_version: int = 2, state: bool = True, compiler: str | None = None,
              name: str | None = None, extra_sources=()) -> Path:
    """Compile ``arm2.c`` and zip it into ``OUT_DIR/NAME.fmu``.

    Parameters
    ----------
    out_dir : path
        Folder that receives the ``.fmu``.
    fmi_version : 2 or 3
    state : bool
        Whether the FMU can get and set its state (``canGetAndSetFMUstate``).
    compiler : str, optional
        The C compiler; :func:`find_compiler` by default.
    name : str, optional
        File name without ``.fmu``; ``arm2_fmi{2,3}[_nostate]`` by default.
    extra_sources : sequence of path, optional
        More C files compiled into the FMU's library (the tests add one whose
        constructor leaves a mark when the library is loaded).

    Raises
    ------
    RuntimeError
        If no C compiler is found or it fails (its output in the message).
    """
    from fmpy import platform, platform_tuple, sharedLibraryExtension

    if fmi_version not in (2, 3):
        raise ValueError(f"`fmi_version` must be 2 or 3, got {fmi_version!r}")
    cc = compiler or find_compiler()
    if cc is None:
        raise RuntimeError("no C compiler found (tried $CC, gcc and cc)")
    name = name or f"arm2_fmi{fmi_version}{'' if state else '_nostate'}"
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "stubs.c").write_text(_stubs(fmi_version, state))
        folder = platform if fmi_version == 2 else platform_tuple     # FMI 3.0: x86_64-linux ...
        library = tmp / "binaries" / folder / (MODEL_IDENTIFIER + sharedLibraryExtension)
        library.parent.mkdir(parents=True)
        flags = [f"-I{headers()}"] + (["-DFMI3"] if fmi_version == 3 else []) \
            + ([] if state else ["-DNO_STATE"])
        cmd = [cc, "-shared", "-fPIC", "-O2", *flags, str(SOURCE), str(tmp / "stubs.c"),
               *map(str, extra_sources), "-o", str(library), "-lm"]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"`{' '.join(cmd)}` failed:\n{done.stderr}")
        (tmp / "modelDescription.xml").write_text(_description(fmi_version, state))
        (tmp / "sources").mkdir()
        shutil.copy(SOURCE, tmp / "sources" / SOURCE.name)
        fmu = out_dir / f"{name}.fmu"
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            for f in ("modelDescription.xml", f"sources/{SOURCE.name}",
                      library.relative_to(tmp).as_posix()):
                z.write(tmp / f, f)
    return fmu


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out_dir")
    p.add_argument("--fmi", type=int, default=2, choices=(2, 3))
    p.add_argument("--no-state", action="store_true")
    a = p.parse_args()
    print(build_fmu(a.out_dir, a.fmi, not a.no_state))
