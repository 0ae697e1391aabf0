"""The dialogs' limits agree with the core's checks: a value the form accepts is not refused at
run time (a size of 0 passed the form and failed after Run)."""
import pytest

from groundsieve.core.errors import InvalidParameterError

#: Limits that depend on another parameter, which a form's fixed minimum cannot express; the core's
#: message names both values.
RELATIVE = {("evc", "LARGE_SCALE"), ("evcrasters", "LARGE_SCALE"), ("pmf", "MAX_WINDOW"), ("pmf", "MAX_DISTANCE"),
            ("smrf", "WINDOW")}


def _number_parameters(provider):
    from qgis.core import QgsProcessingParameterNumber
    for algorithm in provider.algorithms():
        if not hasattr(algorithm, "buildFilter"):
            continue
        for parameter in algorithm.parameterDefinitions():
            if isinstance(parameter, QgsProcessingParameterNumber) and parameter.name() != "DTM_CELL":
                yield algorithm, parameter


def test_every_limit_of_the_form_is_accepted_by_the_core(groundsieve_provider):
    from qgis.core import QgsProcessingContext
    context = QgsProcessingContext()
    refused, checked = [], 0
    for algorithm, parameter in _number_parameters(groundsieve_provider):
        defaults = {p.name(): p.defaultValue() for p in algorithm.parameterDefinitions()}
        algorithm.buildFilter(defaults, context)  # the defaults themselves are valid
        for limit in (parameter.minimum(), parameter.maximum()):
            if abs(limit) > 1e12 or (algorithm.name(), parameter.name()) in RELATIVE:
                continue
            checked += 1
            try:
                algorithm.buildFilter(dict(defaults, **{parameter.name(): limit}), context)
            except InvalidParameterError as err:
                refused.append(f"{algorithm.name()} {parameter.description()!r} = {limit}: {err}")
    assert checked > 20
    assert not refused, "\n".join(refused)


@pytest.mark.parametrize("name, parameter", sorted(RELATIVE))
def test_relative_limits_are_really_relative(groundsieve_provider, name, parameter):
    """Each exception above is refused at the form's minimum only because of another parameter."""
    from qgis.core import QgsProcessingContext
    algorithm = groundsieve_provider.algorithm(name)
    definition = algorithm.parameterDefinition(parameter)
    defaults = {p.name(): p.defaultValue() for p in algorithm.parameterDefinitions()}
    with pytest.raises(InvalidParameterError):
        algorithm.buildFilter(dict(defaults, **{parameter: definition.minimum()}), QgsProcessingContext())
