"""The Processing dialogs and `python -m groundsieve` share one definition of each filter's
parameters (core/engine/parameters.py); every filter takes a Dask scheduler address."""
import pytest

from groundsieve.core.engine import parameters as table


@pytest.mark.parametrize("name", list(table.FILTERS))
def test_the_dialog_is_the_table_and_its_defaults_the_filter_s(groundsieve_provider, name):
    from qgis.core import QgsApplication, QgsProcessingContext, QgsProcessingParameterDefinition
    algorithm = QgsApplication.processingRegistry().createAlgorithmById(f"groundsieve:{name}")
    for p in table.params(name):
        d = algorithm.parameterDefinition(p.name)
        assert d is not None and d.description() == p.title()
        assert bool(d.flags() & QgsProcessingParameterDefinition.Flag.FlagAdvanced) == p.advanced
    assert algorithm.buildFilter({}, QgsProcessingContext()) == table.filter_class(name)()
    scheduler = algorithm.parameterDefinition("SCHEDULER")
    assert scheduler is not None and scheduler.flags() & QgsProcessingParameterDefinition.Flag.FlagAdvanced
    assert algorithm.tileOptions({"SCHEDULER": " tcp://10.0.0.5:8786 "}, QgsProcessingContext()).scheduler == \
        "tcp://10.0.0.5:8786"
    assert algorithm.tileOptions({}, QgsProcessingContext()).scheduler == ""


def test_a_bad_scheduler_address_is_a_processing_error(groundsieve_provider, tmp_path):
    import processing
    from qgis.core import QgsProcessingException
    from groundsieve.core.io import new_las, write_las
    src = tmp_path / "in.laz"
    write_las(new_las([0.0, 10.0, 0.0], [0.0, 0.0, 10.0], [0.0, 0.0, 0.0]), str(src))
    with pytest.raises(QgsProcessingException, match="tcp://host:port"):
        processing.run("groundsieve:pmf", {"INPUT": str(src), "OUTPUT": str(tmp_path / "o.laz"),
                                           "SCHEDULER": "somewhere"})
