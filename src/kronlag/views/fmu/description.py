"""The variables of a kronlag FMU and its ``modelDescription.xml`` (FMI 2.0 or 3.0).

Value references, one block after the other (:class:`Layout`): the states ``q`` and ``qd``
(outputs), their derivatives, every model parameter (in the order of the parameter vector ``p``:
tunable parameters, the defined ones as calculated parameters, the input parameters as inputs),
the three settings of the integration (Baumgarte's ``alpha`` and ``beta``, the drift tolerance),
then the outputs: the multipliers ``lambda[<constraint>]``, the joint reactions
``<joint>.F<axis>`` and ``<joint>.M<axis>`` and the energies.  The C side reads the same blocks
from the macros :meth:`Layout.c_macros` prints (``kronlag/views/fmu/c/fmu_core.c``); FMI 3.0 adds the
independent variable ``time`` after the last.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import cast
from xml.sax.saxutils import quoteattr

import numpy as np

from ...model.modelfile.units import si_unit

__all__ = ["Variable", "Layout", "KINDS", "SETTINGS", "ENERGIES", "model_description", "base_unit"]

#: The settings of the integration exported as parameters: name, start value, description.
SETTINGS = (("kronlag.alpha", "Baumgarte alpha of the index-1 ODE (1/s)"),
            ("kronlag.beta", "Baumgarte beta of the index-1 ODE (1/s)"),
            ("kronlag.drift_tolerance", "largest constraint residual before a step event projects the states "
                                        "(model exchange)"))

#: The FMI interfaces an FMU can provide, in the order of the model description.
KINDS = ("model-exchange", "co-simulation")

#: The energy outputs, in the order of the C outputs.
ENERGIES = ("kinetic_energy", "potential_energy", "energy")

#: The FMI base units by pint's dimension.
_BASE_UNITS = {"[mass]": "kg", "[length]": "m", "[time]": "s", "[current]": "A", "[temperature]": "K",
               "[substance]": "mol", "[luminosity]": "cd"}


def base_unit(text: str) -> dict[str, float] | None:
    """The attributes of FMI's ``BaseUnit`` for the unit ``text`` (SI exponents, ``rad`` for an angle,
    ``factor``), or None when pint does not know it."""
    try:
        one, _ = si_unit(text)
    except ValueError:
        return None
    # pint types an exponent as any scalar; a unit's are real numbers
    exponents = {_BASE_UNITS[dimension]: cast(float, power) for dimension, power in one.dimensionality.items()
                 if dimension in _BASE_UNITS}
    if len(exponents) < len(one.dimensionality):
        return None
    if "rad" in text.replace(" ", "").split("/")[0].split("*"):
        exponents["rad"] = 1
    factor = float(one.magnitude)
    return exponents | ({"factor": factor} if factor != 1.0 else {})


@dataclass(frozen=True)
class Variable:
    """One FMI ``ScalarVariable`` (all are Real)."""

    name: str
    reference: int
    causality: str
    variability: str
    initial: str | None = None
    start: float | None = None
    description: str = ""
    unit: str | None = None
    derivative: int | None = None  # the value reference of the state this is the derivative of


@dataclass(frozen=True)
class Layout:
    """The value references of an FMU's variables, block by block (see the module docstring)."""

    coordinates: tuple[str, ...]
    speeds: tuple[str, ...]
    parameters: tuple[str, ...]
    multipliers: tuple[str, ...]
    reactions: tuple[str, ...]

    @property
    def m(self) -> int:
        return len(self.coordinates)

    @property
    def offsets(self) -> dict[str, int]:
        """First value reference of each block, and ``count``, one past the last."""
        sizes = {"states": 2 * self.m, "derivatives": 2 * self.m, "parameters": len(self.parameters),
                 "settings": len(SETTINGS), "outputs": len(self.multipliers) + len(self.reactions) + len(ENERGIES)}
        offsets, start = {}, 0
        for block, size in sizes.items():
            offsets[block], start = start, start + size
        return offsets | {"count": start}

    def c_macros(self) -> str:
        """The ``KL_VR_*`` and ``KL_OUT_*`` macros of ``fmu2.c``."""
        offsets = self.offsets
        settings = offsets["settings"]
        lines = [f"#define KL_VR_DERIVATIVES {offsets['derivatives']}",
                 f"#define KL_VR_PARAMETERS {offsets['parameters']}",
                 f"#define KL_VR_ALPHA {settings}", f"#define KL_VR_BETA {settings + 1}",
                 f"#define KL_VR_DRIFT_TOLERANCE {settings + 2}",
                 f"#define KL_VR_OUTPUTS {offsets['outputs']}", f"#define KL_VR_COUNT {offsets['count']}",
                 f"#define KL_VR_TIME {offsets['count']}",
                 f"#define KL_VR_OUTPUTS_COUNT {offsets['count'] - offsets['outputs']}",
                 "#define KL_OUT_LAMBDA 0", f"#define KL_OUT_REACTIONS {len(self.multipliers)}",
                 f"#define KL_OUT_ENERGY {len(self.multipliers) + len(self.reactions)}"]
        return "\n".join(lines) + "\n"

    def variables(self, *, start_state: Sequence[float] | np.ndarray, parameter_values: Sequence[float] | np.ndarray,
                  calculated: Sequence[str], inputs: Sequence[str], settings: Sequence[float],
                  units: Mapping[str, str], reaction_units: Mapping[str, str],
                  independent_time: bool = False) -> list[Variable]:
        """Every variable, in value-reference order (with ``independent_time``, FMI 3.0's ``time`` last)."""
        offsets, m = self.offsets, self.m
        unit_of = [units.get(name) for name in self.coordinates]
        state_units = unit_of + [f"{unit}/s" if unit else None for unit in unit_of]
        rate_units = state_units[m:] + [f"{unit}/s^2" if unit else None for unit in unit_of]
        variables = [Variable(name, k, "output", "continuous", "approx", float(start_state[k]),
                              "coordinate (start: projected onto the constraints)" if k < m else "speed", unit)
                     for k, (name, unit) in enumerate(zip(self.coordinates + self.speeds, state_units))]
        variables += [Variable(f"der({name})", offsets["derivatives"] + k, "local", "continuous", "calculated",
                               unit=unit, derivative=k)
                      for k, (name, unit) in enumerate(zip(self.coordinates + self.speeds, rate_units))]
        for k, (name, value) in enumerate(zip(self.parameters, parameter_values)):
            reference = offsets["parameters"] + k
            if name in calculated:
                variables.append(Variable(name, reference, "calculatedParameter", "tunable", "calculated",
                                          description="defined by an expression of other parameters",
                                          unit=units.get(name)))
            elif name in inputs:
                variables.append(Variable(name, reference, "input", "continuous", None, float(value),
                                          "input parameter (enters the generalized forces only)", units.get(name)))
            else:
                variables.append(Variable(name, reference, "parameter", "tunable", "exact", float(value),
                                          unit=units.get(name)))
        variables += [Variable(name, offsets["settings"] + k, "parameter", "fixed", "exact", float(value), text)
                      for k, ((name, text), value) in enumerate(zip(SETTINGS, settings))]
        outputs = self.multipliers + self.reactions + ENERGIES
        output_units = {**reaction_units, **dict.fromkeys(ENERGIES, units.get("energy", "J"))}
        variables += [Variable(name, offsets["outputs"] + k, "output", "continuous", "calculated",
                               unit=output_units.get(name)) for k, name in enumerate(outputs)]
        if independent_time:
            variables.append(Variable("time", offsets["count"], "independent", "continuous",
                                      description="simulation time", unit=units.get("t")))
        return variables


def _common_attributes(variable: Variable) -> list[str]:
    """The attributes FMI 2.0's ``ScalarVariable`` and FMI 3.0's ``Float64`` share."""
    attributes = [f"name={quoteattr(variable.name)}", f'valueReference="{variable.reference}"',
                  f'causality="{variable.causality}"', f'variability="{variable.variability}"']
    if variable.initial:
        attributes.append(f'initial="{variable.initial}"')
    if variable.description:
        attributes.append(f"description={quoteattr(variable.description)}")
    return attributes


def _scalar_variable(variable: Variable) -> str:
    attributes = _common_attributes(variable)
    real = []
    if variable.unit and base_unit(variable.unit) is not None:
        real.append(f"unit={quoteattr(variable.unit)}")
    if variable.start is not None:
        real.append(f'start="{variable.start!r}"')
    if variable.derivative is not None:
        real.append(f'derivative="{variable.derivative + 1}"')  # 1-based index of ModelVariables
    return f"    <ScalarVariable {' '.join(attributes)}>\n      <Real {' '.join(real)}/>\n    </ScalarVariable>"


def _unit_definitions(variables: Sequence[Variable]) -> str:
    """``UnitDefinitions`` of the units the variables use (none: the element left out)."""
    used = sorted({variable.unit for variable in variables if variable.unit})
    bases = {name: found for name in used if (found := base_unit(name))}
    lines = []
    for name, attributes in bases.items():
        base = " ".join(f'{key}="{value!r}"' if key == "factor" else f'{key}="{round(value)}"'
                        for key, value in attributes.items())
        lines.append(f"    <Unit name={quoteattr(name)}><BaseUnit {base}/></Unit>\n")
    return f"  <UnitDefinitions>\n{''.join(lines)}  </UnitDefinitions>\n" if lines else ""


def _structure(variables: Sequence[Variable]) -> tuple[list[Variable], list[Variable], list[Variable]]:
    """The outputs, the state derivatives and the initial unknowns (outputs and states computed at
    initialization, the calculated parameters, the derivatives), each in the order of the variables."""
    outputs = [v for v in variables if v.causality == "output"]
    derivatives = [v for v in variables if v.derivative is not None]
    initial = [v for v in variables if (v.causality == "output" and v.initial in ("approx", "calculated"))
               or v.causality == "calculatedParameter" or v.derivative is not None]
    return outputs, derivatives, initial


def _float64(variable: Variable) -> str:
    """An FMI 3.0 ``Float64`` variable."""
    attributes = _common_attributes(variable)
    if variable.unit and base_unit(variable.unit) is not None:
        attributes.append(f"unit={quoteattr(variable.unit)}")
    if variable.start is not None:
        attributes.append(f'start="{variable.start!r}"')
    if variable.derivative is not None:
        attributes.append(f'derivative="{variable.derivative}"')  # the state's value reference
    return f"    <Float64 {' '.join(attributes)}/>"


def model_description(version: str, *, model_name: str, identifier: str, guid: str, description: str, tool: str,
                      date: str, variables: Sequence[Variable], source_file: str, stop_time: float,
                      tolerance: float, kinds: Sequence[str]) -> str:
    """The ``modelDescription.xml`` (FMI ``version`` "2.0" or "3.0") of an FMU with the interfaces
    ``kinds`` ("model-exchange", "co-simulation") in one binary."""
    outputs, derivatives, initial = _structure(variables)
    experiment = (f'  <DefaultExperiment startTime="0.0" stopTime="{float(stop_time)!r}" '
                  f'tolerance="{float(tolerance)!r}"/>\n')
    categories = '  <LogCategories>\n    <Category name="logStatusError"/>\n  </LogCategories>\n'
    header = (f'<?xml version="1.0" encoding="UTF-8"?>\n<fmiModelDescription fmiVersion="{version}" '
              f'modelName={quoteattr(model_name)} {"guid" if version == "2.0" else "instantiationToken"}="{guid}" '
              f'description={quoteattr(description)} generationTool={quoteattr(tool)} '
              f'generationDateAndTime="{date}" variableNamingConvention="flat"')
    if version == "3.0":
        interfaces = {
            "model-exchange": f'  <ModelExchange modelIdentifier="{identifier}" canGetAndSetFMUState="false" '
                              'canSerializeFMUState="false" providesDirectionalDerivatives="false" '
                              'needsCompletedIntegratorStep="true"/>\n',
            "co-simulation": f'  <CoSimulation modelIdentifier="{identifier}" canGetAndSetFMUState="false" '
                             'canSerializeFMUState="false" providesDirectionalDerivatives="false" '
                             'canHandleVariableCommunicationStepSize="true" maxOutputDerivativeOrder="0" '
                             'hasEventMode="false" providesIntermediateUpdate="false"/>\n'}
        structure = "".join(f'    <{element} valueReference="{v.reference}"/>\n'
                            for element, chosen in (("Output", outputs), ("ContinuousStateDerivative", derivatives),
                                                    ("InitialUnknown", initial)) for v in chosen)
        return (header + '>\n' + "".join(interfaces[kind] for kind in KINDS if kind in kinds)
                + _unit_definitions(variables) + categories + experiment
                + '  <ModelVariables>\n' + "\n".join(map(_float64, variables)) + '\n  </ModelVariables>\n'
                + f'  <ModelStructure>\n{structure}  </ModelStructure>\n</fmiModelDescription>\n')
    sources = f'\n    <SourceFiles>\n      <File name={quoteattr(source_file)}/>\n    </SourceFiles>\n  '
    common = ('canNotUseMemoryManagementFunctions="true" canGetAndSetFMUstate="false" '
              'canSerializeFMUstate="false" providesDirectionalDerivative="false"')
    index = {variable.reference: k + 1 for k, variable in enumerate(variables)}  # 1-based

    def unknowns(chosen: Sequence[Variable]) -> str:
        return "".join(f'      <Unknown index="{index[v.reference]}"/>\n' for v in chosen)

    interfaces = {
        "model-exchange": f'  <ModelExchange modelIdentifier="{identifier}" {common} '
                          f'completedIntegratorStepNotNeeded="false">{sources}</ModelExchange>\n',
        "co-simulation": f'  <CoSimulation modelIdentifier="{identifier}" {common} '
                         'canHandleVariableCommunicationStepSize="true" canInterpolateInputs="false" '
                         f'maxOutputDerivativeOrder="0" canRunAsynchronuously="false">{sources}</CoSimulation>\n'}
    return (
        header + ' numberOfEventIndicators="0">\n'
        + "".join(interfaces[kind] for kind in KINDS if kind in kinds)
        + _unit_definitions(variables) + categories + experiment
        + '  <ModelVariables>\n' + "\n".join(map(_scalar_variable, variables)) + '\n  </ModelVariables>\n'
        '  <ModelStructure>\n'
        f'    <Outputs>\n{unknowns(outputs)}    </Outputs>\n'
        f'    <Derivatives>\n{unknowns(derivatives)}    </Derivatives>\n'
        f'    <InitialUnknowns>\n{unknowns(initial)}    </InitialUnknowns>\n'
        '  </ModelStructure>\n'
        '</fmiModelDescription>\n')
