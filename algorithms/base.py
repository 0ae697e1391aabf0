"""What every ground-filter algorithm shares: the INPUT/OUTPUT/DTM/GROUND_POINTS
parameters, the adaptation of QGIS feedback to the core's plain callables, and the
translation of core errors into QgsProcessingException."""
import math
import os
import re

from qgis.core import (Qgis, QgsCoordinateReferenceSystem, QgsFeature, QgsFeatureSink, QgsField, QgsFields,
                       QgsGeometry, QgsPoint, QgsProcessing, QgsProcessingAlgorithm, QgsProcessingException,
                       QgsProcessingOutputNumber,
                       QgsProcessingParameterBoolean, QgsProcessingParameterDefinition,
                       QgsProcessingParameterEnum, QgsProcessingParameterExtent, QgsProcessingParameterFeatureSink,
                       QgsProcessingParameterFile, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterDestination,
                       QgsProcessingParameterString,
                       QgsWkbTypes)
from qgis.PyQt.QtCore import QVariant
from qgis.PyQt.QtGui import QIcon

from ..core.engine.kernels import COMPILING  # (the standard library only: the plugin loads without numpy)
from .discovery import Discoverable
from .presets import PRESET_HELP

_ICONS = os.path.join(os.path.dirname(os.path.dirname(__file__)), "icons")

COMMON_HELP = """
<h3>Input and outputs</h3>
<p><b>Input point cloud</b>: LAS 1.0-1.4 or LAZ (point formats 0-10), or an ISPRS filter-test text
file <code>x y z label</code> (.txt); or, for a survey, a folder of LAS/LAZ files (the folder button beside
"...", or type its path) or a QGIS virtual point cloud (.vpc, as "Build virtual point cloud" writes it). The files are
only read, never changed. Lengths given in metres
are read in the unit of the cloud's CRS (a warning says so when that unit is not the metre).</p>
<p><b>Classified point cloud</b>: LAS or LAZ (by extension) with every dimension, extra bytes, VLRs,
scales, offsets and the CRS of the input kept (an ISPRS text input gets a scale that keeps its
decimals, 0.001 m for millimetres). Ground points get ASPRS class 2, the other filtered points class 1
(with <i>Keep existing classes other than 0, 1, 2</i>, every point of another class, e.g. building 6,
water 9, bridge deck 17 or a class of your own, keeps it exactly and is never made ground, so it stays
out of the DTM unless its class is one of the <i>DTM classes</i>).</p>
<p><b>Withheld points</b> (the LAS flag meaning, in the ASPRS LAS specification, "if set, this point should
not be included in processing (synonymous with Deleted)"; bit 7 of the classification byte in point formats 0-5) are never
given to the filter, never become ground, never enter the DTM, and keep their class and flags.</p>
<p><b>Ignored classes</b> (default <code>7,18</code>: low and high noise; a list or ranges such as
<code>7,18,20-25</code>, as PDAL's <code>ignore</code> and LAStools' <code>-ignore_class</code>;
empty = none): points of these classes are treated as withheld: not filtered, not ground, not in
the DTM (whose grid spans only the other points), their class kept.</p>
<p>Where this QGIS opens point clouds (a point-cloud provider for LAS/LAZ, COPC or .vpc: PDAL in the
Windows and macOS builds), <i>or a loaded point-cloud layer</i> takes a layer of the project instead
of a path, and the classified cloud is loaded as a point-cloud layer when the run ends; where it cannot
(Debian's builds have no PDAL), the log says where the classified cloud was written, with a warning when it
is a temporary file ("[Save to temporary file]"), which QGIS deletes when it closes: give it a file name to keep it.</p>
<p><b>DTM</b> (on by default; untick or leave empty in qgis_process to skip it): a GeoTIFF of the ground points interpolated linearly on their Delaunay
triangulation, cell size <i>DTM cell size</i>, the cloud's CRS, nodata -9999 outside the hull of
the ground points unless <i>DTM: fill cells outside the ground hull</i> is ticked (nearest value).
<i>DTM classes</i> (e.g. <code>9</code>): points of these classes in the input enter the DTM with the
ground, whatever the filter made of them; for a flood model, with <i>Keep existing classes</i>, the
DTM then holds the vendor's water surface while bridge decks (17) stay out of it. <i>DTM: leave cells
farther than this from any ground point empty</i> (advanced, 0 = no limit): data gaps are otherwise
bridged by the triangulation. <i>DTM extent</i> (advanced): the DTM covers it, widened to whole cells on multiples of the cell size, nodata
beyond the points' own DTM: two epochs' DTMs or a model's domain on one grid of one size. QGIS writes an
extent xmin,xmax,ymin,ymax (an extent in another CRS is reprojected to the cloud's); one that misses the
points, or is thousands of times their area where its numbers in the other order fit them, is refused. On a survey,
a DTM with an extent and no classified point cloud (skipped) filters only the tiles making the extent's cells and
reads only the files within their reach: a model domain's DTM takes the domain's time. Heights of 32,768 or more (a geocentric export) make a
Float64 DTM, others Float32.</p>
<p><b>Ground points as a vector layer</b> (advanced, off by default): the ground points as a PointZ layer with return
number and intensity; meant for small clouds.</p>
<p>Outputs are written under a temporary name (<code>.NAME.gs&lt;process id&gt;-&lt;random&gt;.part</code> and the
extension, hidden, beside the output) and renamed when complete: a failed or cancelled run leaves
nothing half-written, and the next run to the same output deletes what a killed run left. Two
outputs on one file are refused before any work.</p>
<p><b>Memory</b>: before a grid (the filter's or the DTM's) is allocated, its peak memory is estimated
and the run is refused above 60 % of the memory available, with the estimate, the extent and the
likely cause (e.g. one point kilometres away from the others: class it as noise or remove it).</p>
""" + PRESET_HELP + """
<h3>Surveys: buffered tiles</h3>
<p>A folder, a .vpc, a set <i>Tile size</i>, or a cloud larger than the <i>Memory budget</i> runs in
square tiles, each read with a buffer around it (the filter's own reach unless <i>Tile buffer</i> is set)
so that no seam shows at tile or file edges: only the tile's own points keep their class. Tiles exist
only where points are; they run <i>Tiles at the same time</i> at once (worker processes under
qgis_process for 10 million points or more, threads below that and in the desktop), sharing the
<i>Memory budget</i> for their points and grids (a worker process also holds Python and its libraries,
130-250 MB, measured, outside it); their temporary files (the tiles, and each input's points uncompressed, about
75 bytes a point at most) go to the <i>Working folder</i> and are removed at the end. A COPC input is not
copied there: each tile reads its points from it by bounds. A run killed or failed midway resumes when started again with the same inputs and
parameters, skipping the tiles done (after a failure only when you chose the working folder). With several input files the output names a .vpc and
the classified files (same names as the inputs) go into a folder of the same name beside it. The DTM is
one seamless cloud-optimised GeoTIFF over the whole survey. <i>Dask scheduler address</i> (advanced; needs the Python
package dask[distributed]): the tiles run on a Dask cluster (tcp://host:port) or on N local worker processes
(local:N); the workers must see the input and the working folder at the same paths (a shared file system). The ground points layer and the filter's
intermediate grids are not written in a tiled run.</p>
<p><i>One file of the survey</i> (advanced; for a job array, one batch job per file): its number from 0 (a
.vpc's files in its order, a folder's by name; e.g. <code>--ONLY=$SLURM_ARRAY_TASK_ID</code> in qgis_process),
its name or its path. Only that file's points are classified, on the tiles of a run of the whole survey,
each reading its buffer from the neighbouring files: with one <i>Tile size</i> set in every job, the files'
classes and DTM cells are those of one run of the whole survey with that tile size (left at 0, each job fits
its tiles to the files, and its log names their size). The outputs are that file's: in their
paths <code>{name}</code> is its name without extension (<code>--OUTPUT=out/{name}.laz
--DTM=dtm/{name}.tif</code>), so that every job writes its own.</p>
"""


#: "All files (*)" last: it lets a folder through (QGIS checks a File parameter's value against the
#: filter's extensions unless one pattern is a bare *), so one INPUT takes a file, a folder or a .vpc.
INPUT_FILTER = ("Point clouds (*.las *.laz *.vpc *.LAS *.LAZ *.VPC);;ISPRS text (*.txt);;"
                "All files and folders (*)")


def attribute_field(name, kind="Int"):
    """An attribute field of ``kind`` "Int", "Double" or "String": QgsField takes a QMetaType from QGIS
    3.38 on (the QVariant form is deprecated there and warns on every run), a QVariant type before."""
    if Qgis.QGIS_VERSION_INT >= 33800:
        from qgis.PyQt.QtCore import QMetaType
        return QgsField(name, getattr(QMetaType.Type, "QString" if kind == "String" else kind))
    return QgsField(name, getattr(QVariant, kind))


def dialog_help(html):
    """``html`` as the algorithm dialog wants it: QGIS's dialog makes each line of
    shortHelpString a paragraph of its own (QgsProcessingAlgorithmDialogBase::formatHelp), so
    the source's wrapped lines are joined; the paragraphs come from the HTML tags. Under
    ``qgis_process`` (``qgis_process help``, which prints it as it is, and R's qgisprocess), the same
    help as plain text (:func:`plain_help`): it was one line of HTML thousands of characters long."""
    text = re.sub(r"\s*\n\s*", " ", html).strip()
    from qgis.core import QgsApplication
    return plain_help(text) if QgsApplication.platform() == "qgis_process" else text


def plain_help(text, width=100):
    """The dialog's HTML help ``text`` as plain text for a terminal: each paragraph, heading, list item
    and parameter (a bold label after a sentence) on lines of their own, wrapped at ``width``, a blank
    line between them, links as "text (address)", the other tags dropped and the entities decoded."""
    import html
    import textwrap
    text = re.sub(r"\s+", " ", text)
    # a link keeps its address (a code reviewer: "the benchmarks" without where); a parameter's bold label
    # after a sentence starts a paragraph of its own (a power user: they ran together without the bold)
    text = re.sub(r'(?i)<a\s[^>]*href="([^"]+)"[^>]*>(.*?)</a>', r"\2 (\1)", text)
    text = re.sub(r"(?i)(?<=[.)]) (<b>)", r"\n\n\1", text)
    text = re.sub(r"(?i)</?h\d\b[^>]*>|</?p\b[^>]*>|<br\s*/?>|</?[uo]l\b[^>]*>", "\n\n", text)
    text = re.sub(r"(?i)<li[^>]*>", "\n\n- ", text)
    text = html.unescape(re.sub(r"<[^>]+>", "", text))
    paragraphs = [p.strip() for p in re.split(r"\n\s*\n", text) if p.strip()]
    return "\n\n".join(textwrap.fill(p, width=width, break_long_words=False, break_on_hyphens=False,
                                     subsequent_indent="  " if p.startswith("- ") else "") for p in paragraphs)


def core_modules(extra=None, feedback=None, kernels_of=None):
    """Import the core, turning a missing dependency into a clear Processing error. With
    ``feedback``, the first run of the algorithm ``kernels_of`` (a filter's name; None: any) in the
    session says so when its kernels are to be compiled (``say_if_compiling``)."""
    from ..dependencies import require_dependencies
    try:
        require_dependencies(extra)
        from ..core import errors
        from ..core.engine import workflow
    except ImportError as err:
        raise QgsProcessingException(str(err)) from err
    if feedback is not None:
        say_if_compiling(feedback, kernels_of)
    return errors, workflow


#: the algorithms whose kernels were checked this QGIS session (one check each)
_SESSION = {"kernels_checked": set()}


def kernels_compiled(name):
    """After a run of algorithm ``name`` finished: its kernels are in numba's cache, and its next runs,
    in this session or another, say nothing of compiling (core/engine/kernels.py ``remember_run``)."""
    from ..core.engine.kernels import remember_run
    remember_run(name)


def say_if_compiling(feedback, name=None):
    """At the first run of algorithm ``name`` (None: any) in a session, say that its kernels are
    compiled now when numba's cache holds fewer than half of them or of the grids' (a new install, an
    upgrade that replaced the plugin's folder, or an algorithm run for the first time: PTD compiled
    for 30 s with nothing said after SMRF had filled the cache, a release engineer;
    core/engine/kernels.py ``about_to_compile``)."""
    from ..core.engine.kernels import about_to_compile
    if name in _SESSION["kernels_checked"]:
        return False
    _SESSION["kernels_checked"].add(name)
    if not about_to_compile(name):
        return False
    feedback.pushInfo(COMPILING)
    return True


def dtm_cell_set(algorithm, parameters, context, name) -> bool:
    """Whether the user set the DTM cell (presets.set_by_user): then it is in the CRS's unit; otherwise
    the default 1 m, converted for a cloud in feet (core/engine/workflow.py defaults_in_crs_unit)."""
    from .presets import set_by_user
    if parameters.get(name) in (None, ""):
        return False
    return set_by_user(algorithm, parameters, name, algorithm.parameterAsDouble(parameters, name, context),
                       float(algorithm.parameterDefinition(name).defaultValue()))


def feedback_callables(feedback):
    """The core's plain callables for a Processing feedback: progress, is_cancelled, log."""
    from ..core.progress import warning_of

    def log(line):  # the core's warnings (e.g. the CRS's unit, said before the work) as warnings
        warning = warning_of(line)
        if warning is not None:
            feedback.pushWarning(warning)
        else:
            feedback.pushInfo(line)
    return dict(progress=lambda f: feedback.setProgress(100.0 * f), is_cancelled=feedback.isCanceled, log=log)


def _file_extensions(file_filter):
    """The extensions a file parameter's filter names ("Point clouds (*.las *.laz)" -> {".las",
    ".laz"}); None when it takes any file."""
    found = {m.lower() for m in re.findall(r"\*(\.[A-Za-z0-9]+)", file_filter or "")}
    return None if not found or re.search(r"\*\.\*", file_filter or "") else found


def explain_parameter(param, value, strictly_positive=(), largest=None):
    """What is wrong with ``value`` for ``param``, in the dialog's words (its label), or None.
    QGIS's own check only says "An error was encountered while checking parameter values"."""
    from .pointclouds import EITHER_INPUT
    label = param.description().replace(EITHER_INPUT, "")  # (what the value is, not that one of two is needed)
    if value is None or (isinstance(value, str) and value == ""):
        return None
    if isinstance(param, QgsProcessingParameterNumber):
        if not isinstance(value, (int, float, str)) or isinstance(value, bool):
            return None  # an expression or a property: QGIS evaluates it
        try:
            number = float(value)
        except ValueError:
            return f"{label}: '{value}' is not a number"
        if not math.isfinite(number):
            return f"{label} must be a finite number (got {value})"
        name = param.name()
        if name in strictly_positive and number <= 0:
            return f"{label} must be > 0 (got {number:g})"
        if number < param.minimum():
            return f"{label} must be at least {param.minimum():g} (got {number:g})"
        if number > param.maximum():
            return f"{label} must be at most {param.maximum():g} (got {number:g})"
        if largest and name in largest and number > largest[name]:
            return f"{label}: {number:g} is larger than any map (at most {largest[name]:g})"
        return None
    if isinstance(param, QgsProcessingParameterFile) and isinstance(value, str):
        if param.behavior() != QgsProcessingParameterFile.Behavior.File:
            return None
        from .pointclouds import takes_folders
        if os.path.isdir(value) and takes_folders(param):
            return None  # the survey inputs take a folder of LAS/LAZ files too
        if param.name() in ("PRESET", "START_PRESET") and not os.path.isfile(value):
            from .presets import shipped_preset_problem
            return shipped_preset_problem(label, value)
        if not os.path.isfile(value):
            return f"{label}: {value} does not exist or is not a file"
        extensions = _file_extensions(param.fileFilter())
        ext = os.path.splitext(value)[1].lower()
        if extensions and ext not in extensions:
            text = f"{label}: {value} is not a {' or '.join(sorted(extensions))} file (it ends in '{ext or '(none)'}')"
            if ext == ".txt" and ".las" in extensions:
                text += ("; ISPRS text files are read by the ground filters only: convert it to LAS/LAZ with "
                         "its label as the class (ground 2, object 1), e.g. with PDAL or LAStools' txt2las")
            return text
    return None


def check_parameter_values(algorithm, parameters, context, ok, message, *, strictly_positive=(), largest=None):
    """``checkParameterValues`` with QGIS's verdict ``ok, message`` made specific: the first
    parameter whose value is wrong, named by its label, and why."""
    for param in algorithm.parameterDefinitions():
        if param.isDestination():
            continue
        why = explain_parameter(param, parameters.get(param.name()), strictly_positive, largest)
        if why:
            return False, why
    return ok, message


def sink_folder_problem(algorithm, parameters, name, context):
    """destination_folder_problem of the feature sink ``name``, its destination read from the parameter's
    value: parameterAsOutputLayer registered a layer to load for a temporary output ("memory:<label>") that
    no run made, and the dialog ended every successful run in red with "The following layers were not
    correctly generated" (a QGIS plugin reviewer). Temporary outputs (memory layers) pass."""
    from qgis.core import QgsProcessingOutputLayerDefinition
    value = parameters.get(name)
    if isinstance(value, QgsProcessingOutputLayerDefinition):
        text = value.sink.valueAsString(context.expressionContext(), "")
        value = text[0] if isinstance(text, tuple) else text
    if not isinstance(value, str) or not value or value == QgsProcessing.TEMPORARY_OUTPUT:
        return None
    return destination_folder_problem(algorithm.parameterDefinition(name).description(), value)


def staged_sink(parameters, name, context):
    """(the final path, the parameters with the feature sink ``name`` sent to a file of the same name in a hidden
    folder beside it: core.io.outputs.temporary_folder_beside) for a destination that is a plain file with an
    extension (the driver follows it); (None, the parameters as they are) for a temporary output, a database, a
    layer of a GeoPackage named with options, a path without an extension (QGIS completes it), and an append to
    an existing layer (the dialog's "Append to Layer...": its features are kept, QGIS adds to them in place)."""
    from qgis.core import QgsProcessingOutputLayerDefinition, QgsProperty
    value = parameters.get(name)
    definition = value if isinstance(value, QgsProcessingOutputLayerDefinition) else None
    if definition is not None:
        if hasattr(definition, "useRemapping") and definition.useRemapping():
            return None, parameters
        text = definition.sink.valueAsString(context.expressionContext(), "")
        value = text[0] if isinstance(text, tuple) else text
    if (not isinstance(value, str) or not value or value == QgsProcessing.TEMPORARY_OUTPUT or "|" in value
            or _not_a_plain_file(value) or not os.path.splitext(value)[1]):
        return None, parameters
    from ..core.io.outputs import remove_stale_sink_folders, temporary_folder_beside
    remove_stale_sink_folders(value)
    tmp = os.path.join(temporary_folder_beside(value), os.path.basename(value))
    if definition is not None:
        staged = QgsProcessingOutputLayerDefinition(QgsProperty.fromValue(tmp), definition.destinationProject)
        staged.destinationName = definition.destinationName
        staged.createOptions = definition.createOptions
    else:
        staged = tmp
    return value, dict(parameters, **{name: staged})


def _not_a_plain_file(destination: str) -> bool:
    path = destination.split("|")[0]
    return path.startswith(("memory:", "ogr:", "postgres:", "spatialite:")) or "://" in path or "dbname=" in path


def _staged_path(staged) -> str:
    from qgis.core import QgsProcessingOutputLayerDefinition
    if isinstance(staged, QgsProcessingOutputLayerDefinition):
        return staged.sink.staticValue()
    return staged


#: layer files that hold no geometry: the ground points get their coordinates as columns there
TABLE_EXTENSIONS = (".csv", ".xlsx", ".ods", ".dbf")

#: a shapefile's sidecars besides its .shp (its style and metadata, .qml and .qmd, are the user's: kept)
SHAPEFILE_SIDECARS = (".shx", ".dbf", ".prj", ".cpg", ".qix", ".sbn", ".sbx", ".fbn", ".fbx", ".ain", ".aih", ".atx",
                      ".idm", ".ind", ".qpj")


def commit_staged_sink(staged, final: str, sink_id: str, context) -> str:
    """Move the complete files of :func:`staged_sink`'s folder (the layer and its sidecars, the main file last)
    into place and remove the folder; the layer QGIS is to load when the run ends is the final one. Returns the
    sink id of the final path."""
    import shutil
    tmp = _staged_path(staged)
    holder, target = os.path.dirname(tmp), os.path.dirname(os.path.abspath(final))
    names = sorted(os.listdir(holder), key=lambda n: n == os.path.basename(tmp))
    stem, ext = os.path.splitext(os.path.abspath(final))
    if ext.lower() == ".shp":  # an old shapefile's sidecars the new one has not (its spatial index answered
        # extent queries on the new layer with none of its features: a dense-UAV reviewer), as QGIS's writer does
        for side in SHAPEFILE_SIDECARS:
            for old in (stem + side, stem + side.upper()):
                if os.path.basename(old) not in names and os.path.isfile(old):
                    os.remove(old)
    for name in names:
        if name.endswith(("-journal", "-wal", "-shm")):  # (a database's open journal: nothing to keep)
            continue
        os.replace(os.path.join(holder, name), os.path.join(target, name))
    shutil.rmtree(holder, ignore_errors=True)
    loads = context.layersToLoadOnCompletion()
    moved = {key.replace(tmp, final) if isinstance(key, str) else key: details for key, details in loads.items()}
    if moved.keys() != loads.keys():
        context.setLayersToLoadOnCompletion(moved)
    return sink_id.replace(tmp, final) if isinstance(sink_id, str) else sink_id


def discard_staged_sink(staged) -> None:
    """Remove :func:`staged_sink`'s folder and what it holds (a failed or cancelled run)."""
    import shutil
    shutil.rmtree(os.path.dirname(_staged_path(staged)), ignore_errors=True)


def destination_folder_problem(label, destination):
    """Why the file destination ``destination`` of the output ``label`` cannot be written (missing or
    read-only folder), or None; data sources that are not plain files (memory:, databases) pass."""
    if not destination or not isinstance(destination, str):
        return None
    path = destination.split("|")[0]
    if _not_a_plain_file(path):
        return None
    from ..core.errors import OutputError
    from ..core.io.outputs import check_folder_writable
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        return f"{path}: the folder {folder} of the output '{label}' does not exist"
    try:
        check_folder_writable(path, folder)
    except OutputError as err:
        return str(err)
    return None


def warn_about_crs(feedback, input_path, crs_wkt, lengths="every length parameter"):
    """Warn when the cloud has no CRS, or one whose unit is not the metre (lengths are read in it):
    the command line's words (core/raster/crs.py)."""
    from ..core.raster.crs import unit_warning
    warning = unit_warning(input_path, crs_wkt, lengths)
    if warning:
        feedback.pushWarning(warning)


def dtm_classes_parameter(name):
    """The DTM's classes added to the ground (ground filters and rfclassify)."""
    param = QgsProcessingParameterString(
        name, "DTM classes: classes of the input added to the ground (e.g. 9 = water)", defaultValue="",
        optional=True)
    param.setHelp("Points of these classes in the input enter the DTM with the ground, whatever the filter "
                  "made of them (withheld and ignored points never do): e.g. 9, so that a flood model's DTM "
                  "holds the water surface. Empty: the ground only.")
    return param


def _advanced(param, text):
    """``param`` among the advanced parameters, with the tooltip ``text``."""
    param.setFlags(param.flags() | QgsProcessingParameterDefinition.Flag.FlagAdvanced)
    param.setHelp(text)
    return param


def dtm_max_distance_parameter(name):
    """The DTM's gap limit (ground filters and rfclassify), advanced."""
    return _advanced(QgsProcessingParameterNumber(
        name, "DTM: leave cells farther than this from any ground point empty (m, 0 = no limit)",
        type=QgsProcessingParameterNumber.Type.Double, defaultValue=0.0, minValue=0.0),
        "A data gap (a missing tile, water without returns) is otherwise bridged by the triangulation: cells whose "
        "centre is farther than this from the centre of every cell holding a ground point stay nodata. In a survey, "
        "keep it at most the tile buffer.")


def dtm_extent_parameter(name):
    """The DTM's extent (ground filters, the DTM from classes, rfclassify), advanced."""
    return _advanced(QgsProcessingParameterExtent(name, "DTM extent (empty = the points')", optional=True),
                     "The DTM covers this extent, widened to whole cells on multiples of the cell size: two epochs' "
                     "DTMs, or a hydraulic model's domain, on one grid of one size; cells beyond the points' own DTM "
                     "are nodata (the fill stops there too). An extent in another CRS is reprojected to the cloud's.")


def dtm_extent_value(algorithm, parameters, name, context, input_path, feedback=None):
    """The DTM extent asked for as (xmin, ymin, xmax, ymax) in the cloud's CRS (the first file's of a
    survey), reprojected from the extent's own CRS when it has one (said to ``feedback``: the log then
    calls it "the extent given", a flood modeller's 300 m square came out 302 cells wide); None when none
    is given."""
    from qgis.core import QgsCoordinateReferenceSystem
    if not parameters.get(name):
        return None
    crs = QgsCoordinateReferenceSystem()
    try:
        from ..core.io.lasfiles import expand_inputs, scan_header
        files = expand_inputs(input_path) if input_path else []
        wkt = scan_header(files[0]).crs_wkt if files and files[0].lower().endswith((".las", ".laz")) else None
        if wkt:
            crs = QgsCoordinateReferenceSystem.fromWkt(wkt)
    except Exception:  # noqa: BLE001 - an input the run will name; the extent is then taken as it is
        pass
    label = algorithm.parameterDefinition(name).description().split(" (")[0]
    given_crs = algorithm.parameterAsExtentCrs(parameters, name, context)
    if not crs.isValid() and given_crs.isValid() and given_crs.isGeographic():
        # (a canvas in EPSG:4326 over a cloud without a CRS: its degrees were taken as the cloud's metres)
        raise QgsProcessingException(f"{label}: given in {given_crs.authid() or given_crs.description()} (degrees), "
                                     "but the cloud has no CRS to reproject it to: give the extent in the cloud's "
                                     "own coordinates, or assign the cloud its CRS")
    rect = algorithm.parameterAsExtent(parameters, name, context, crs) if crs.isValid() else \
        algorithm.parameterAsExtent(parameters, name, context)
    if rect.isNull():
        return None
    if rect.isEmpty():  # (a zero width or height fell back to the points' extent without a word)
        raise QgsProcessingException(f"{label}: x {rect.xMinimum():,.2f} to {rect.xMaximum():,.2f}, y "
                                     f"{rect.yMinimum():,.2f} to {rect.yMaximum():,.2f} is empty (zero width or "
                                     "height)")
    if feedback is not None and crs.isValid() and given_crs.isValid() and given_crs != crs:
        feedback.pushInfo(f"{label}: given in {given_crs.authid() or given_crs.description()}, reprojected to the "
                          f"cloud's {crs.authid() or crs.description()}: the box around it, x {rect.xMinimum():,.2f} to "
                          f"{rect.xMaximum():,.2f}, y {rect.yMinimum():,.2f} to {rect.yMaximum():,.2f}.")
    return rect.xMinimum(), rect.yMinimum(), rect.xMaximum(), rect.yMaximum()


#: the GeoPackage's "Undefined Cartesian SRS" (srs_id -1), for outputs of a cloud without a CRS
UNDEFINED_CARTESIAN_WKT = ('LOCAL_CS["Undefined cartesian SRS",LOCAL_DATUM["Unknown engineering datum",32767],'
                           'UNIT["metre",1],AXIS["Easting",EAST],AXIS["Northing",NORTH]]')


#: the tooltips of the parameters every ground filter shares (Discoverable.PARAMETER_HELP)
FILTER_PARAMETER_HELP = {
    "INPUT": "A LAS/LAZ file (1.0-1.4, point formats 0-10), an ISPRS text file (x y z label), a folder of LAS/LAZ "
             "files or a virtual point cloud (.vpc): a folder or .vpc runs in buffered tiles. Only read, never changed.",
    "PRESET": "A parameters file of this filter written by Tune, or a shipped preset's file name (each is for "
              "one filter, e.g. forest-smrf.json for SMRF): its values replace the filter's defaults; a value you "
              "change in the dialog wins.",
    "LAST_RETURNS": "Only each pulse's last return is filtered; the other returns become non-ground (class 1): "
                    "canopy hits stay out of the ground. A cloud without return information (photogrammetry) "
                    "loses no point by it.",
    "IGNORE_CLASSES": "Points of these classes are not filtered, keep their class and stay out of the DTM and its "
                      "extent: 7 and 18 (low and high noise) by default. Codes and ranges, e.g. 7,18,20-25.",
    "KEEP_CLASSES": "Points already of a class other than 0, 1 and 2 (a building 6, water 9) keep it and are never "
                    "made ground, so they stay out of the DTM unless named in the DTM classes.",
    "TILE_SIZE": "The side of the square tiles a survey (a folder, a .vpc, a cloud beyond the memory budget) runs "
                 "in; 0 = planned from the memory budget. Set, it tiles even a cloud that fits: two epochs run with "
                 "one tile size share their tiles.",
    "TILE_BUFFER": "The margin read around each tile so that no seam shows; -1 = the filter's own reach (e.g. "
                   "SMRF's window).",
    "MEMORY_BUDGET": "The memory the tiles' points and grids may take, shared by the tiles that run at once; 0 = a "
                     "quarter of the job's memory (the RAM, or its control group's limit), at most 2048 MB. Each "
                     "worker process's Python and libraries (130-250 MB, measured) come on top.",
    "WORKERS": "How many tiles run at once; 0 = one per core this process may use. With no tile size set, the "
               "tiles are planned from the memory budget shared by the workers: set the tile size for the same "
               "results with other workers.",
    "WORK_FOLDER": "Where the temporary tiles go (each input's points uncompressed, about 75 bytes a point at "
                   "most), removed at the end; a run killed midway resumes from them.",
    "SCHEDULER": "Run the tiles on a Dask cluster (tcp://host:port) or on N local worker processes (local:N); "
                 "needs the Python package dask[distributed].",
    "ONLY": "For a job array, one batch job per file: the one file of the survey to classify (its number from 0, "
            "its name or its path), its tiles buffered by the neighbouring files; {name} in the outputs' paths is "
            "its name.",
    "DTM_CELL": "The DTM's cell size in the CRS's unit; its cells lie on multiples of it, so DTMs of one cell size "
                "share their cells. The default 1 m is 3 ft in a CRS in feet.",
    "DTM_FILL": "Fill the cells outside the convex hull of the ground points with the nearest value, instead of "
                "leaving them nodata.",
    "OUTPUT": "The classified LAS/LAZ (ground 2, other filtered points 1), every dimension, VLR and the CRS of the "
              "input kept; a .vpc and a folder of files for several input files. Skip it for the DTM alone (on a survey "
              "with a DTM extent, only the extent's tiles are then filtered).",
    "DTM": "A cloud-optimised GeoTIFF of the ground points' triangulation; skip it to classify only.",
    "GROUND_POINTS": "The ground points as a point layer, for small clouds (a point layer of millions of points "
                     "is slow in QGIS).",
}


class SurveyTiles:
    """The advanced parameters of tiled runs (folders, .vpc, clouds beyond the memory budget), for
    the ground filters and rfclassify alike: the same labels, the same TileOptions."""
    TILE_SIZE = "TILE_SIZE"
    TILE_BUFFER = "TILE_BUFFER"
    MEMORY_BUDGET = "MEMORY_BUDGET"
    WORKERS = "WORKERS"
    WORK_FOLDER = "WORK_FOLDER"
    SCHEDULER = "SCHEDULER"
    ONLY = "ONLY"

    def addTileParameters(self, reach="the filter's own reach"):  # noqa: N802
        """Advanced parameters of tiled runs (folders, .vpc, clouds beyond the memory budget);
        ``reach``: what the buffer's -1 stands for."""
        advanced = [
            QgsProcessingParameterNumber(self.TILE_SIZE, "Tile size (m; 0 = from the memory budget)",
                                         type=QgsProcessingParameterNumber.Type.Double, defaultValue=0.0,
                                         minValue=0.0),
            QgsProcessingParameterNumber(self.TILE_BUFFER, f"Tile buffer (m; -1 = {reach})",
                                         type=QgsProcessingParameterNumber.Type.Double, defaultValue=-1.0,
                                         minValue=-1.0),
            QgsProcessingParameterNumber(self.MEMORY_BUDGET, "Memory budget (MB; 0 = a quarter of the memory, "
                                         "at most 2048)", type=QgsProcessingParameterNumber.Type.Integer,
                                         defaultValue=0, minValue=0),
            QgsProcessingParameterNumber(self.WORKERS, "Tiles at the same time (0 = every core it may use)",
                                         type=QgsProcessingParameterNumber.Type.Integer, defaultValue=0, minValue=0),
            QgsProcessingParameterFile(self.WORK_FOLDER, "Working folder for temporary tiles (default: beside "
                                       "the output)", behavior=QgsProcessingParameterFile.Behavior.Folder,
                                       optional=True),
            QgsProcessingParameterString(self.SCHEDULER, "Dask scheduler address (empty = this machine; "
                                         "tcp://host:port, or local:N for N local worker processes)",
                                         defaultValue="", optional=True),
            QgsProcessingParameterString(self.ONLY, "One file of the survey only (job arrays: number from 0, name "
                                         "or path)", defaultValue="", optional=True)]
        for param in advanced:
            param.setFlags(param.flags() | QgsProcessingParameterDefinition.Flag.FlagAdvanced)
            self.addParameter(param)

    def tileOptions(self, parameters, context):  # noqa: N802
        from ..core.engine.tiles import TileOptions
        buffer = self.parameterAsDouble(parameters, self.TILE_BUFFER, context)
        return TileOptions(tile_size_m=self.parameterAsDouble(parameters, self.TILE_SIZE, context),
                           buffer_m=None if buffer < 0 else buffer,
                           memory_budget_mb=self.parameterAsInt(parameters, self.MEMORY_BUDGET, context),
                           workers=self.parameterAsInt(parameters, self.WORKERS, context),
                           work_dir=self.parameterAsFile(parameters, self.WORK_FOLDER, context) or None,
                           scheduler=(self.parameterAsString(parameters, self.SCHEDULER, context) or "").strip(),
                           only=(self.parameterAsString(parameters, self.ONLY, context) or "").strip())

    def tiledOutputs(self, options, run, output_path, dtm_path):  # noqa: N802
        """The outputs' paths a run wrote: one file of a survey (ONLY) names its own ({name}, or
        under a folder); else those the dialog gave."""
        from ..core.engine.tiles import TiledRun
        if isinstance(run, TiledRun) and options.only != "":
            return (run.outputs or [None])[0], run.dtm_path
        return output_path, dtm_path


class GroundFilterAlgorithm(SurveyTiles, Discoverable, QgsProcessingAlgorithm):
    """Base class of the ground filters. Subclasses declare their own parameters in
    ``initFilterParameters`` and build the core filter object in ``buildFilter``."""

    PARAMETER_HELP = FILTER_PARAMETER_HELP

    INPUT = "INPUT"
    OUTPUT = "OUTPUT"
    LAST_RETURNS = "LAST_RETURNS"
    IGNORE_NOISE = "IGNORE_NOISE"  # before IGNORE_CLASSES; hidden, kept for saved models and scripts
    IGNORE_CLASSES = "IGNORE_CLASSES"
    KEEP_CLASSES = "KEEP_CLASSES"
    DTM = "DTM"
    DTM_CELL = "DTM_CELL"
    DTM_FILL = "DTM_FILL"
    DTM_CLASSES = "DTM_CLASSES"
    DTM_MAX_DISTANCE = "DTM_MAX_DISTANCE"
    DTM_EXTENT = "DTM_EXTENT"
    GROUND_POINTS = "GROUND_POINTS"
    GROUND_COUNT = "GROUND_COUNT"
    POINT_COUNT = "POINT_COUNT"

    #: the filter's name in core/engine/parameters.py (its parameters, labels, units; defaults
    #: from the filter dataclass): the dialog and `python -m groundsieve` share that one definition
    FILTER = None

    # -- to override (or set FILTER) ------------------------------------------------------
    def initFilterParameters(self):  # noqa: N802
        """The filter's parameters from the one table (core/engine/parameters.py)."""
        from ..core.engine import parameters as table
        defaults = table.source_defaults(self.FILTER)
        for p in table.params(self.FILTER):
            value = defaults[p.field]
            if p.choices:
                param = QgsProcessingParameterEnum(p.name, p.title(), options=list(p.choice_labels),
                                                   defaultValue=list(p.choices).index(value))
            elif isinstance(value, bool):
                param = QgsProcessingParameterBoolean(p.name, p.title(), defaultValue=value)
            else:
                kind = QgsProcessingParameterNumber.Type.Integer if isinstance(value, int) else \
                    QgsProcessingParameterNumber.Type.Double
                extra = {} if p.maximum is None else dict(maxValue=p.maximum)
                param = QgsProcessingParameterNumber(p.name, p.title(), type=kind, defaultValue=value,
                                                     minValue=p.minimum, **extra)
            if p.advanced:
                param.setFlags(param.flags() | QgsProcessingParameterDefinition.Flag.FlagAdvanced)
            if p.help:  # (else addParameter takes the help panel's paragraph on it)
                param.setHelp(f"{p.help[0].upper()}{p.help[1:]}.")
            self.addParameter(param)

    def filterArguments(self, parameters, context):  # noqa: N802
        """The filter dataclass's keyword arguments from the dialog's values (the one table)."""
        from ..core.engine import parameters as table
        defaults = table.source_defaults(self.FILTER)
        kwargs = {}
        for p in table.params(self.FILTER):
            value = defaults[p.field]
            if p.choices:
                kwargs[p.field] = p.choices[self.parameterAsEnum(parameters, p.name, context)]
            elif isinstance(value, bool):
                kwargs[p.field] = self.parameterAsBoolean(parameters, p.name, context)
            elif isinstance(value, int):
                kwargs[p.field] = self.parameterAsInt(parameters, p.name, context)
            else:
                kwargs[p.field] = self.parameterAsDouble(parameters, p.name, context)
        return kwargs

    def buildFilter(self, parameters, context, log=None):  # noqa: N802
        """The filter from the dialog's values over the PRESET's (algorithms/presets.py); ``log``
        (a callable) gets the parameters the run uses and which came from the preset."""
        from .presets import build_filter
        return build_filter(self, parameters, context, log)

    def completeFilterArguments(self, kwargs):  # noqa: N802
        """The filter's keyword arguments once the dialog's and the preset's are merged; a filter
        whose parameters depend on each other completes them here."""
        return kwargs

    def rasterOutputs(self, parameters, context):  # noqa: N802
        """More GeoTIFF outputs: {output name: (path, f(run) -> (values, grid))}; none by default."""
        return {}

    def iconName(self):  # noqa: N802
        return "groundsieve.svg"

    # -- QgsProcessingAlgorithm --------------------------------------------------------
    def group(self):
        return "Ground filters"

    def groupId(self):  # noqa: N802
        return "groundfilters"

    def icon(self):
        return QIcon(os.path.join(_ICONS, self.iconName()))

    def createInstance(self):  # noqa: N802
        return type(self)()

    def initAlgorithm(self, config=None):  # noqa: N802
        """Every ground filter's parameters, in one place and one order: the input, the filter's
        own, the point selection, the tiles (advanced), then the outputs with the DTM's options
        beside the DTM (see addOutputParameters)."""
        self.addInputParameters()
        self.initFilterParameters()
        if self.FILTER:  # a filter of the one table: its parameters may come from a preset file
            from .presets import add_preset_parameter
            add_preset_parameter(self)
        self.addSelectionParameters()
        self.addTileParameters()
        self.addOutputParameters()

    INPUT_LAYER = "INPUT_LAYER"

    def addInputParameters(self):  # noqa: N802
        """INPUT, a file parameter on every QGIS (a path, a folder, a .vpc, an ISPRS .txt); and,
        where this QGIS opens point clouds the filters read (algorithms/pointclouds.py decides),
        INPUT_LAYER, a loaded point-cloud layer that replaces it. In the modeler both offer only
        what can be a point cloud (pointclouds.offer_point_clouds_in_modeler)."""
        from . import pointclouds
        param = QgsProcessingParameterFile(
            self.INPUT, "Input point cloud (LAS/LAZ, a folder of them, a .vpc, or ISPRS .txt)",
            behavior=QgsProcessingParameterFile.Behavior.File, fileFilter=INPUT_FILTER)
        self.addParameter(pointclouds.offer_point_clouds_in_modeler(param, folders=True))
        if pointclouds.add_input_layer_parameter(self, self.INPUT_LAYER, "…or a loaded point-cloud layer"):
            pointclouds.make_input_optional(param)

    def addSelectionParameters(self):  # noqa: N802
        """Which points are filtered and which classes are kept."""
        self.addParameter(QgsProcessingParameterBoolean(
            self.LAST_RETURNS, "Filter only last returns (others become non-ground)", defaultValue=False))
        self.addParameter(QgsProcessingParameterString(
            self.IGNORE_CLASSES, "Ignored classes: not filtered, kept, out of the DTM (e.g. 7,18,20-25)",
            defaultValue="7,18", optional=True))
        ignore_noise = QgsProcessingParameterBoolean(
            self.IGNORE_NOISE, "Ignore noise (7, 18) [replaced by Ignored classes]", defaultValue=True)
        ignore_noise.setFlags(ignore_noise.flags() | QgsProcessingParameterDefinition.Flag.FlagHidden)
        self.addParameter(ignore_noise)
        self.addParameter(QgsProcessingParameterBoolean(
            self.KEEP_CLASSES, "Keep existing classes other than 0, 1, 2 (never made ground)", defaultValue=False))

    def addOutputParameters(self):  # noqa: N802
        """The one rule of outputs, for every filter and evcrasters: the classified cloud (loaded
        where QGIS can show it, else logged); the DTM offered by default, its cell size and fill
        option last among the inputs, right above the outputs (QGIS's dialog lists every output
        after every input); the ground-point layer off by default and advanced; the filter's
        intermediate rasters (rasterOutputs) off by default."""
        self.addDtmParameters()
        # optional, made by default: skipped, a run makes its DTM alone (a flood modeller's domains from a
        # county's survey had each classified and written the whole survey)
        self.addParameter(QgsProcessingParameterFileDestination(
            self.OUTPUT, "Classified point cloud (a .vpc for several input files)",
            fileFilter="LAZ (*.laz);;LAS (*.las);;Virtual point cloud (*.vpc)", optional=True, createByDefault=True))
        self.addParameter(QgsProcessingParameterRasterDestination(
            self.DTM, "DTM (ground surface)", optional=True, createByDefault=True))
        self.addExtraOutputParameters()
        ground_points = QgsProcessingParameterFeatureSink(
            self.GROUND_POINTS, "Ground points as a vector layer (small clouds only)",
            type=QgsProcessing.SourceType.TypeVectorPoint, optional=True, createByDefault=False)
        ground_points.setFlags(ground_points.flags() | QgsProcessingParameterDefinition.Flag.FlagAdvanced)
        self.addParameter(ground_points)
        # the counts every run returns, declared as native algorithms declare theirs: a model's next
        # step can take them, and the dialog and qgis_process help list them
        self.addOutput(QgsProcessingOutputNumber(self.GROUND_COUNT, "Ground points"))
        self.addOutput(QgsProcessingOutputNumber(self.POINT_COUNT, "Points classified"))

    def addDtmParameters(self, dtm_classes=True):  # noqa: N802
        """The DTM's options, the filters' and the DTM from classes' (``dtm_classes``: the filters' DTM classes,
        added to their ground; the DTM from classes names its own ground classes)."""
        self.addParameter(QgsProcessingParameterNumber(
            self.DTM_CELL, "DTM cell size (m)", type=QgsProcessingParameterNumber.Type.Double,
            defaultValue=1.0, minValue=0.0))
        self.addParameter(QgsProcessingParameterBoolean(
            self.DTM_FILL, "DTM: fill cells outside the ground hull (nearest value)", defaultValue=False))
        if dtm_classes:
            self.addParameter(dtm_classes_parameter(self.DTM_CLASSES))
        self.addParameter(dtm_max_distance_parameter(self.DTM_MAX_DISTANCE))
        self.addParameter(dtm_extent_parameter(self.DTM_EXTENT))

    def addExtraOutputParameters(self):  # noqa: N802
        """The filter's intermediate rasters (evcrasters): optional, not created by default."""

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        errors, workflow = core_modules(feedback=feedback, kernels_of=self.name())
        self.checkGroundPointsDestination(parameters, context)
        from . import pointclouds, styles
        input_path = pointclouds.input_path(self, parameters, context, self.INPUT, self.INPUT_LAYER)
        output_path = pointclouds.classified_output_path(self, parameters, context, self.OUTPUT, input_path) or None
        dtm_path = self.parameterAsOutputLayer(parameters, self.DTM, context) or None
        # the ground points layer alone (a dense-UAV reviewer's run was refused as writing nothing): from a cloud
        # run whole, the only run that writes it
        ground_only = not output_path and not dtm_path and bool(parameters.get(self.GROUND_POINTS))
        if not output_path and not dtm_path and not ground_only:
            raise QgsProcessingException(pointclouds.nothing_to_write(self))
        try:
            algorithm = self.buildFilter(parameters, context, feedback.pushInfo)
            rasters = {name: (path, make) for name, (path, make) in self.rasterOutputs(parameters, context).items()
                       if path}
            self.checkDistinctOutputs([(self.OUTPUT, output_path), (self.DTM, dtm_path),
                                       *((name, path) for name, (path, _make) in rasters.items())])
            options = workflow.FilterOptions(
                last_returns_only=self.parameterAsBoolean(parameters, self.LAST_RETURNS, context),
                ignore_classes=self.ignoredClasses(parameters, context, errors),
                keep_existing_classes=self.parameterAsBoolean(parameters, self.KEEP_CLASSES, context),
                tiling=self.tileOptions(parameters, context))
            dtm = workflow.DTMOptions(
                cell_size_m=self.parameterAsDouble(parameters, self.DTM_CELL, context),
                cell_set=dtm_cell_set(self, parameters, context, self.DTM_CELL),
                fill_outside_hull=self.parameterAsBoolean(parameters, self.DTM_FILL, context),
                classes=self.parameterAsString(parameters, self.DTM_CLASSES, context) or "",
                max_distance_m=self.parameterAsDouble(parameters, self.DTM_MAX_DISTANCE, context),
                extent=dtm_extent_value(self, parameters, self.DTM_EXTENT, context, input_path, feedback))
            if ground_only:
                from ..core.engine.tiles import needs_tiling
                if needs_tiling(input_path, options.tiling, algorithm):
                    raise QgsProcessingException(
                        f"{self.parameterDefinition(self.GROUND_POINTS).description().split(' (')[0]} alone: "
                        f"{input_path} runs in tiles (a survey, a tile size set, or a cloud beyond the memory "
                        "budget), which write no such layer; give the classified point cloud or the DTM")
            run = workflow.run_ground_filter(
                input_path, output_path, algorithm, options=options, dtm_path=dtm_path, dtm=dtm,
                rasters={path: make for path, make in rasters.values()}, **feedback_callables(feedback))
        except errors.GroundSieveError as err:
            raise QgsProcessingException(str(err)) from err
        tiled = run.cloud is None  # a tiled run (survey scale) holds no cloud in memory
        output_path, dtm_path = self.tiledOutputs(options.tiling, run, output_path, dtm_path)
        # (the CRS's unit was said before the work, by the core's log: see feedback_callables)
        results = {self.GROUND_COUNT: run.ground_count, self.POINT_COUNT: run.point_count if tiled else len(run.cloud)}
        if output_path:
            results[self.OUTPUT] = output_path
        if dtm_path:
            results[self.DTM] = dtm_path
        for name, (path, _make) in rasters.items():
            results[name] = path
        sink_id = None
        if tiled and parameters.get(self.GROUND_POINTS):
            feedback.pushWarning("Ground points layer: not written in a tiled run (survey scale); "
                                 "use the classified point cloud.")
        elif not tiled:
            sink_id = self.writeGroundPointsOrUndo(parameters, context, feedback, run,
                                                   [output_path, dtm_path, *(p for p, _m in rasters.values())])
        if sink_id is not None:
            results[self.GROUND_POINTS] = sink_id
        if output_path:
            pointclouds.load_or_log(context, feedback, output_path,
                                    self.parameterDefinition(self.OUTPUT).description().split(" (")[0], self.OUTPUT,
                                    parameters.get(self.OUTPUT))
        styles.style_when_loaded(context, dtm_path, styles.DTM_STYLE)
        for name, (path, _make) in rasters.items():
            styles.style_when_loaded(context, path, self.rasterStyles(run).get(name))
        kernels_compiled(self.name())
        return results

    def rasterStyles(self, run=None):  # noqa: N802
        """{output name: layer post-processor} of the rasters styled when loaded (algorithms/styles);
        ``run`` the filter's run (e.g. its threshold)."""
        return {}

    def checkDistinctOutputs(self, outputs):  # noqa: N802
        """Refuse two outputs on one file before any work, naming them as the dialog does."""
        from ..core.io.outputs import check_distinct_outputs
        check_distinct_outputs([(self.parameterDefinition(name).description(), path) for name, path in outputs])

    #: Number parameters that must be > 0 although their minimum is 0 (and the largest values accepted)
    STRICTLY_POSITIVE = ("DTM_CELL",)

    def checkParameterValues(self, parameters, context):  # noqa: N802
        """QGIS's check, with what is wrong said in the dialog's words (a cell size of -1, inf or text)."""
        from ..core.grids.spec import MAX_CELL_M
        ok, message = super().checkParameterValues(parameters, context)
        layer_input = self.parameterDefinition(self.INPUT_LAYER)
        if layer_input is not None and not parameters.get(self.INPUT) and not parameters.get(self.INPUT_LAYER):
            return False, (f"{self.parameterDefinition(self.INPUT).description()}: give a file, a folder or a "
                           f".vpc, or a layer in '{layer_input.description()}'")
        return check_parameter_values(self, parameters, context, ok, message,
                                      strictly_positive=self.STRICTLY_POSITIVE, largest={self.DTM_CELL: MAX_CELL_M})

    def checkGroundPointsDestination(self, parameters, context):  # noqa: N802
        """The ground-point layer is written after the core run: its folder is checked before the
        work starts, so that a run that cannot write it writes nothing at all."""
        if not parameters.get(self.GROUND_POINTS):
            return
        why = sink_folder_problem(self, parameters, self.GROUND_POINTS, context)
        if why:
            raise QgsProcessingException(why)

    def ignoredClasses(self, parameters, context, errors):  # noqa: N802
        """IGNORE_CLASSES as codes; IGNORE_NOISE=false (older models and scripts) drops 7 and 18."""
        from ..core.io.clouds import NOISE_CLASSES, parse_classes
        codes = parse_classes(self.parameterAsString(parameters, self.IGNORE_CLASSES, context) or "",
                              what="Ignored classes")
        if not self.parameterAsBoolean(parameters, self.IGNORE_NOISE, context):
            codes = tuple(c for c in codes if c not in NOISE_CLASSES)
        return codes

    def writeGroundPointsOrUndo(self, parameters, context, feedback, run, written):  # noqa: N802
        """The ground-point layer, written by QGIS after the core has committed the other outputs:
        should it fail all the same (its folder was checked before the work), or the run be cancelled
        meanwhile, the outputs this run wrote (``written``) are removed, so that the run leaves all its
        outputs or none."""
        from ..core.errors import Cancelled
        try:
            return self._write_ground_points(parameters, context, feedback, run)
        except (Exception, Cancelled) as err:
            for path in written:
                if path and os.path.isfile(path):
                    os.remove(path)
            if isinstance(err, Cancelled):
                raise QgsProcessingException(f"{err}; the run's outputs were removed") from err
            raise QgsProcessingException(f"{err}; the ground points could not be written, so the run's other "
                                         "outputs were removed") from err

    def _write_ground_points(self, parameters, context, feedback, run):
        """The ground-point layer. A file destination is written under its own name in a hidden folder beside
        it and moved into place once complete (:func:`staged_sink`), as the core writes its outputs (QGIS writes a sink straight to
        its destination: a cancelled run left a GeoPackage of 201,278 of its 2,496,477 points under the
        final name, and the run said it was done; a killed one left a broken one: a modeller reviewer).
        A cancel stops it with the run's other outputs removed (:meth:`writeGroundPointsOrUndo`)."""
        final, staged = staged_sink(parameters, self.GROUND_POINTS, context)
        # a table without geometry (CSV, a spreadsheet) gets the coordinates as columns: a CSV had the return
        # number and intensity alone, and the run said it was done (a dense-UAV reviewer)
        table = final is not None and os.path.splitext(final)[1].lower() in TABLE_EXTENSIONS
        fields = QgsFields()
        for name in ("x", "y", "z") if table else ():
            fields.append(attribute_field(name, "Double"))
        fields.append(attribute_field("return_number"))
        fields.append(attribute_field("intensity"))
        # A cloud without a CRS: an undefined *Cartesian* CRS (a GeoPackage's srs_id -1), not QGIS's invalid
        # CRS, which OGR writes as "Undefined geographic SRS" (srs_id 0): metres taken for degrees
        crs = QgsCoordinateReferenceSystem.fromWkt(run.cloud.crs_wkt or UNDEFINED_CARTESIAN_WKT)
        try:
            sink, sink_id = self.parameterAsSink(staged, self.GROUND_POINTS, context, fields,
                                                 QgsWkbTypes.Type.PointZ, crs)
            if sink is None:
                return None
            cloud = run.cloud
            idx = run.ground.nonzero()[0]
            intensity = cloud.intensity if cloud.intensity is not None else None
            feedback.setProgressText(f"Writing the ground points layer ({idx.size:,} points)…")
            step = max(1, idx.size // 100)
            for k, i in enumerate(idx):
                if k % step == 0:
                    if feedback.isCanceled():
                        from ..core.errors import Cancelled
                        raise Cancelled("cancelled by the user while the ground points layer was written")
                    feedback.setProgress(100.0 * k / idx.size)
                feature = QgsFeature(fields)
                feature.setGeometry(QgsGeometry(QgsPoint(float(cloud.x[i]), float(cloud.y[i]), float(cloud.z[i]))))
                feature.setAttributes(([float(cloud.x[i]), float(cloud.y[i]), float(cloud.z[i])] if table else [])
                                      + [int(cloud.return_number[i]),
                                         int(intensity[i]) if intensity is not None else None])
                sink.addFeature(feature, QgsFeatureSink.Flag.FastInsert)
            del sink  # (closes the file)
            if final is None:
                return sink_id
            return commit_staged_sink(staged[self.GROUND_POINTS], final, sink_id, context)
        except BaseException:
            if final is not None:
                discard_staged_sink(staged[self.GROUND_POINTS])
            raise
