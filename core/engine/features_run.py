"""groundsieve:features from file to file: read a cloud, compute its features
(core.learn.features) and write them into a copy of the cloud as LAS extra bytes."""
from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Callable, Dict, Optional, Tuple

import numpy as np

from ..errors import InputError, InvalidParameterError, OutputError
from ..io import PointCloud, check_output_path, new_las, read_cloud, write_las
from ..learn.features import (_NAME_RE, COLUMN_FEATURES, EIGEN_FEATURES, MAX_NAME_LENGTH, MIN_POINTS, FeatureSpec,
                             compute_features, parse_feature_name)
from ..progress import Steps


# --------------------------------------------------------------------------- files

def _description(name: str) -> str:
    """The extra-bytes description of a feature (at most 32 characters)."""
    try:
        feature, radius = parse_feature_name(name)
    except InvalidParameterError:
        return ""
    shape = "column" if feature in COLUMN_FEATURES else "sphere"
    return f"{feature} {shape} r={radius:g}"[:32]


def _check_feature_arrays(features: Mapping, n: int, path: str) -> Dict[str, np.ndarray]:
    arrays: Dict[str, np.ndarray] = {}
    lowered = {}
    for name, values in features.items():
        if not isinstance(name, str) or not _NAME_RE.match(name) or len(name) > MAX_NAME_LENGTH:
            raise OutputError(f"{path}: {name!r} cannot name a LAS extra dimension: use at most "
                              f"{MAX_NAME_LENGTH} letters, digits or underscores, starting with a letter")
        if name.lower() in lowered:
            raise OutputError(f"{path}: feature names {lowered[name.lower()]!r} and {name!r} differ only by case")
        lowered[name.lower()] = name
        values = np.asarray(values)
        if values.shape != (n,):
            raise OutputError(f"{path}: feature {name} has {values.shape} values for {n} points")
        arrays[name] = values.astype(np.float32, copy=False)
    if not arrays:
        raise OutputError(f"{path}: no feature to write")
    return arrays


def check_names_free(cloud: PointCloud, names, path: str) -> None:
    """Refuse (OutputError) feature names already taken by a dimension of ``cloud`` (case ignored,
    as PDAL does), e.g. when the input is the output of an earlier run."""
    if cloud.las is not None:
        taken = list(cloud.las.point_format.dimension_names)
    else:
        taken = ["X", "Y", "Z", "classification"] + (["reference_label"] if cloud.reference_label is not None else [])
    existing = {d.lower(): d for d in taken}
    for name in names:
        if name.lower() in existing:
            raise OutputError(
                f"{path}: the input {cloud.path} already has a dimension named '{existing[name.lower()]}' "
                f"(from an earlier run?); the feature {name} cannot be added beside it. Compute the "
                "features on the original cloud, or at other radii.")


def write_features(cloud: PointCloud, features: Mapping, path: str, *, atomic: bool = True) -> None:
    """Write ``cloud`` (LAS/LAZ by the extension of ``path``) with every dimension, extra bytes,
    VLR and the CRS of a LAS/LAZ input kept, plus one float32 extra-bytes dimension per entry of
    ``features`` ({name: array}); NaN marks points without a value. An ISPRS text input becomes
    LAS 1.2 point format 0 (its label column kept as ``reference_label``, as
    :func:`~groundsieve.core.io.write_classified` does). A name already used by a dimension of
    the input (case ignored, as PDAL does) is refused with an :class:`OutputError`."""
    import laspy
    path = check_output_path(path, inputs=[cloud.path])
    arrays = _check_feature_arrays(features, len(cloud), path)
    check_names_free(cloud, arrays, path)
    if cloud.las is not None:
        # A copy: the cloud in memory stays as read.
        las = laspy.LasData(copy.deepcopy(cloud.las.header), points=cloud.las.points.copy())
    else:
        extra = {"reference_label": cloud.reference_label} if cloud.reference_label is not None else None
        las = new_las(cloud.x, cloud.y, cloud.z, point_format=0, crs_wkt=cloud.crs_wkt, extra=extra,
                      classification=cloud.classification)
    las.add_extra_dims([laspy.ExtraBytesParams(name=name, type=np.float32, description=_description(name))
                        for name in arrays])
    for name, values in arrays.items():
        las[name] = values
    write_las(las, path, atomic=atomic, source=cloud.path if cloud.las is not None else None)


@dataclass
class FeaturesRun:
    cloud: PointCloud
    features: Dict[str, np.ndarray]   #: {name: float32 per point}

    @property
    def names(self) -> Tuple[str, ...]:
        return tuple(self.features)


def run_features(input_path: str, output_path: str, spec: FeatureSpec = FeatureSpec(), *,
                 ignore_classes=(7, 18),
                 progress: Optional[Callable[[float], None]] = None,
                 is_cancelled: Optional[Callable[[], bool]] = None,
                 log: Optional[Callable[[str], None]] = None) -> FeaturesRun:
    """Read ``input_path``, compute the features of ``spec`` for every point and write
    ``output_path`` (LAS/LAZ) with them as extra bytes. The output is written under a temporary
    name and renamed when complete; the input is never modified.

    As in groundsieve:rfclassify and the ground filters, withheld points and points of
    ``ignore_classes`` (noise 7 and 18 by default; a list or text such as "7,18,20-25") stay out
    of every neighbourhood and get no value (NaN): the features written are those the classifier
    computes on the same cloud."""
    from .tiles import refuse_in_a_workers_import
    from .workflow import FilterOptions, processable
    refuse_in_a_workers_import()
    steps = Steps(progress, is_cancelled)
    log = log or (lambda _msg: None)
    check_output_path(output_path, inputs=[input_path])
    steps.check()
    cloud = read_cloud(input_path)
    log(f"Read {len(cloud):,} points from {input_path}.")
    check_names_free(cloud, spec.names, output_path)
    options = FilterOptions(ignore_classes=ignore_classes if ignore_classes is not None else ())
    may = processable(cloud, options)
    n_may = int(may.sum())
    if n_may == 0:
        raise InputError(f"{input_path}: every point is withheld or of an ignored class "
                         f"({', '.join(map(str, options.ignored)) or 'none'}): no feature to compute")
    if n_may < len(cloud):
        log(f"{int(cloud.withheld_mask.sum()):,} withheld point(s) and {int((~may & ~cloud.withheld_mask).sum()):,} "
            f"of an ignored class ({', '.join(map(str, options.ignored)) or 'none'}) are left out of the "
            "neighbourhoods and get no value (NaN).")
    steps.report(0.05)
    if n_may == len(cloud):
        features = compute_features(cloud.xyz, spec, steps=steps.sub(0.05, 0.85))
    else:
        part = compute_features(cloud.xyz[may], spec, steps=steps.sub(0.05, 0.85))
        features = {}
        for name, values in part.items():
            full = np.full(len(cloud), np.nan, dtype=np.float32)
            full[may] = values
            features[name] = full
    for radius, wanted in spec.sphere_passes().items():
        eigen = [name for feature, name in wanted if feature in EIGEN_FEATURES]
        missing = int(np.isnan(features[eigen[0]][may]).sum()) if eigen else 0
        if missing:
            log(f"{missing:,} point(s) ({100.0 * missing / len(cloud):.1f} %) have fewer than {MIN_POINTS} points "
                f"(or only coincident ones) within {radius:g} m: no value (NaN) for {', '.join(eigen)}.")
    steps.check()
    write_features(cloud, features, output_path)
    steps.report(1.0)
    return FeaturesRun(cloud, features)
