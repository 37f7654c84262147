"""The C source of a kronlag FMU, its compilation for this platform and the ``.fmu`` archive.

The source is the numeric model's generated C (:attr:`NumericModel.c_source` with the
``potential_energy`` and ``Phi_q`` kernels), the compiled integrators' declarations and C of
:mod:`kronlag.simulation` up to ``cvode.c`` (as :func:`kronlag.simulation.drivers.driver` builds
them), the FMU header generated here (value references, start values, the parameter definitions,
the joint reactions), ``c/fmu_core.c`` (the model instance) and ``c/fmu2.c`` or ``c/fmu3.c``, the
FMI 2.0 or 3.0 functions.  It compiles against the FMI headers that FMPy ships (``fmpy/c-code``)
and links the SUNDIALS libraries of the scikit-sundae wheel, which go into ``binaries/<platform>/``
next to the FMU's library (found there through the run path ``$ORIGIN``).
"""

from __future__ import annotations

import importlib.util
import re
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import sympy as sp

from ...core.errors import CompilerError, InputError
from ...numeric import codegen
from ...numeric.tolerances import CVODE_TIGHTEST
from ...simulation import drivers
from ...simulation.solvers.compiled import CompiledSolver

__all__ = ["Standard", "STANDARDS", "header_directory", "reactions", "c_source", "compile_fmu",
           "build_description"]

@dataclass(frozen=True)
class Standard:
    """What differs between the FMI versions kronlag writes: the headers the source includes (taken
    from FMPy's package data), the platform folder of the binary and the C of the FMI functions."""

    version: str
    headers: tuple[str, ...]
    platform: str
    functions: str


#: The FMI versions by ``fmi_version`` (64-bit Linux binaries only).
STANDARDS = {"2.0": Standard("2.0", ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h"), "linux64",
                             "fmu2.c"),
             "3.0": Standard("3.0", ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h"),
                             "x86_64-linux", "fmu3.c")}

#: Co-simulation's absolute tolerance over its relative one (that of kronlag.simulate's defaults,
#: rtol 1e-8 and atol 1e-10).
ATOL_RATIO = 1e-2

_CFLAGS = ("-O2", "-fPIC", "-fno-math-errno", "-fvisibility=hidden", "-std=gnu99")


def _check_platform() -> None:
    if not (sys.platform.startswith("linux") and sys.maxsize > 2**32):
        raise InputError(f"FMU export builds binaries for 64-bit Linux only (this is {sys.platform}); the FMU's "
                         "sources could be compiled elsewhere, but kronlag does not do it yet")


def header_directory(standard: Standard) -> Path:
    """The directory of the FMI headers that FMPy ships; InputError if FMPy is not installed."""
    spec = importlib.util.find_spec("fmpy")
    if spec is None or spec.origin is None:
        raise InputError(f"FMU export needs the FMI {standard.version} headers that FMPy ships: "
                         "pip install kronlag[fmu]")
    directory = Path(spec.origin).parent / "c-code"
    missing = [name for name in standard.headers if not (directory / name).is_file()]
    if missing:
        raise InputError(f"FMU export: the FMPy installed lacks the FMI {standard.version} header(s) "
                         f"{', '.join(missing)} in {directory}")
    return directory


def _c_array(values: Sequence[float] | np.ndarray) -> str:
    return "{" + ", ".join(repr(float(value)) for value in values) + (", 0.0}" if not len(values) else "}")


def _definitions(parameter_names: Sequence[str], definitions: Mapping[str, sp.Expr]) -> str:
    """``kl_fmu_definitions(p)``: the defined parameters computed from the others, in the order of
    their dependencies (:meth:`NumericModel.parameter_definitions`)."""
    index = {name: i for i, name in enumerate(parameter_names)}
    lines = ["static void kl_fmu_definitions(double *p)", "{", "    (void)p;"]
    for name, expression in definitions.items():
        renamed = expression.xreplace({symbol: sp.Symbol(f"p[{index[symbol.name]}]")
                                       for symbol in expression.free_symbols})
        lines.append(f"    p[{index[name]}] = {sp.ccode(sp.N(renamed, 17), standard='C99')};  /* {name} */")
    return "\n".join(lines + ["}"]) + "\n"


def reactions(model) -> tuple[str, list[str], dict[str, str]]:
    """The C of ``kl_fmu_reactions(t, q, qd, p, lam, out)``, the world-frame wrench of every joint
    ``W_J(q) lambda_J`` (:mod:`kronlag.numeric.reactions`), the output names and their units."""
    from ...numeric.reactions import REACTION_UNITS

    lam = [sp.Dummy(f"lambda{j}") for j in range(model.r)]
    system = model.equations.system
    row = {constraint.name: j for j, constraint in enumerate(system.constraints)}
    expressions: dict[str, sp.Matrix] = {}
    names: list[str] = []
    units: dict[str, str] = {}
    for joint in system.joints:
        multipliers = sp.Matrix([lam[row[name]] for name in joint.constraint_names])
        expressions[f"J{len(expressions)}"] = sp.Matrix(joint.wrench) * multipliers
        d = joint.dimension
        force = [f"{joint.name}.F{axis}" for axis in "xyz"[:d]]
        torque = [f"{joint.name}.M{axis}" for axis in ("z" if d == 2 else "xyz")]
        names += force + torque
        units |= dict.fromkeys(force, REACTION_UNITS["force"]) | dict.fromkeys(torque, REACTION_UNITS["couple"])
    P = len(model.parameter_names)
    call = "static void kl_fmu_reactions(double t, const double *q, const double *qd, const double *p, " \
           "const double *lam, double *out)"
    if not expressions:
        return f"{call}\n{{\n    (void)t, (void)q, (void)qd, (void)p, (void)lam, (void)out;\n}}\n", names, units
    kernel = codegen.KernelSource(model.equations).expression_kernel("fmu_reactions", expressions, extra=lam)
    code, _ = codegen.c_kernel(kernel, 1)
    body = (f"{call}\n{{\n    double inputs[{P + len(lam)} + 1];\n"
            f"    memcpy(inputs, p, {P} * sizeof(double));\n    memcpy(inputs + {P}, lam, {len(lam)} * sizeof(double));\n"
            "    kronlag_fmu_reactions(t, q, qd, inputs, out);\n}\n")
    return code + body, names, units


def c_source(model, standard: Standard, *, layout_macros: str, reactions_code: str, guid: str,
             start_state: np.ndarray, calculated: Sequence[str], settings: Sequence[float], rtol: float,
             max_steps: int) -> str:
    """The FMU's C source (see the module docstring); ``reactions_code`` from :func:`reactions`."""
    names = model.parameter_names
    alpha, beta, drift = settings
    header = [
        "/* Generated by kronlag.views.fmu: the FMU's variables and their start values. */",
        f'#define KL_FMU_GUID "{guid}"', f"#define KL_FMU_PARAMETERS {len(names)}",
        f"#define KL_FMU_START_PARAMETERS {_c_array(model.parameter_vector(0.0))}",
        f"#define KL_FMU_START_STATE {_c_array(start_state)}",
        f"#define KL_FMU_CALCULATED {{{', '.join('1' if name in calculated else '0' for name in names) or '0'}}}",
        f"#define KL_FMU_ALPHA {alpha!r}", f"#define KL_FMU_BETA {beta!r}", f"#define KL_FMU_DRIFT_TOLERANCE {drift!r}",
        f"#define KL_FMU_RTOL {rtol!r}", f"#define KL_FMU_MAX_STEPS {int(max_steps)}L",
        f"#define KL_FMU_ATOL_RATIO {ATOL_RATIO!r}",
        f"#define KL_FMU_TOLERANCE_SCALE {CompiledSolver.TOLERANCE_SCALE!r}",
        f"#define KL_FMU_TIGHTEST_RTOL {CVODE_TIGHTEST[0]!r}", f"#define KL_FMU_TIGHTEST_ATOL {CVODE_TIGHTEST[1]!r}",
    ]
    source = (drivers.driver_source(model, "cvode") + "\n".join(header) + "\n" + layout_macros + _definitions(names, model.parameter_definitions())
              + reactions_code + _c_file("fmu_core.c") + _c_file(standard.functions))
    return source


def _c_file(name: str) -> str:
    return (Path(__file__).with_name("c") / name).read_text()


def _compiler() -> list[str]:
    compiler = codegen.c_compiler()
    if compiler is None:
        raise CompilerError("FMU export needs a C compiler (gcc or cc on PATH, or $CC)")
    return [*compiler.command, *compiler.flags]


def compile_fmu(source: str, standard: Standard, identifier: str, binaries: Path, sources: Path) -> None:
    """Write ``source`` and the FMI headers to ``sources``, compile ``binaries/<identifier>.so`` with
    the SUNDIALS libraries copied next to it (run path ``$ORIGIN``)."""
    _check_platform()
    headers = header_directory(standard)
    compiler = _compiler()
    sources.mkdir(parents=True, exist_ok=True)
    binaries.mkdir(parents=True, exist_ok=True)
    (sources / f"{identifier}.c").write_text(source)
    for name in standard.headers:
        shutil.copyfile(headers / name, sources / name)
    libraries = []
    for library in drivers.sundials_libraries():
        shutil.copyfile(library, binaries / library.name)
        libraries.append(binaries / library.name)
    command = [*compiler, *_CFLAGS, "-shared", f"-I{sources}", "-o", str(binaries / f"{identifier}.so"),
               str(sources / f"{identifier}.c"), *map(str, libraries), "-Wl,-rpath,$ORIGIN", "-lm"]
    try:
        result = subprocess.run(command, capture_output=True, text=True)
    except OSError as error:
        raise CompilerError(f"cannot run the C compiler {compiler[0]}: {error}") from None
    if result.returncode:
        raise CompilerError(f"compiling the FMU with {compiler[0]} failed: exit status {result.returncode}\n"
                            f"{result.stderr[-4000:]}".rstrip())


def build_description(identifier: str, libraries: Sequence[str], standard: Standard) -> str:
    """``sources/buildDescription.xml`` (the FMI 3.0 format, which FMI 2.0.4 allows for source FMUs):
    the source file and the SUNDIALS libraries (file names ``lib<name>[-<hash>].so.<version>``)."""
    links: list[str] = []
    for file in libraries:
        match = re.fullmatch(r"lib(\w+?)(?:-[0-9a-f]+)?\.so\.([\d.]+)", file)
        name, release = match.groups() if match else (file, "")
        links.append(f'    <Library name="{name}"{f" version={quoteattr(release)}" if release else ""} '
                     f'description={quoteattr(f"binaries/{standard.platform}/{file}")}/>\n')
    text = "".join(links)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier="{identifier}" description="links the SUNDIALS 7 libraries '
            f'shipped in binaries/{standard.platform}/ (or any SUNDIALS 7 build)">\n'
            '    <SourceFileSet language="C99">\n'
            f'      <SourceFile name="{identifier}.c"/>\n'
            '    </SourceFileSet>\n'
            f'{text}'
            '  </BuildConfiguration>\n'
            '</fmiBuildDescription>\n')


def temporary_directory() -> tempfile.TemporaryDirectory:
    """A scratch directory for the FMU's tree before it is zipped."""
    return tempfile.TemporaryDirectory(prefix="kronlag-fmu-")
