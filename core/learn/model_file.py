"""The Random Forest model file: a NumPy ``.npz`` archive of plain arrays (read with
``allow_pickle=False``, so loading cannot run code) and a JSON header with a SHA-256 over both.
A file whose format, version or checksum does not match is refused."""
from __future__ import annotations

import hashlib
import json
import os
from typing import Dict

import numpy as np

from ..errors import InputError, InvalidParameterError
from ..io import atomic_path
from .rf import Model, Scaler


FORMAT = "groundsieve-rf"
FORMAT_VERSION = 1
MODEL_EXTENSION = ".npz"


# -- the model file -------------------------------------------------------------------------------

_ARRAYS = ("classes", "roots", "left", "right", "feature", "threshold", "missing_left", "value")


def _digest(arrays: Dict[str, np.ndarray], header: dict) -> str:
    """SHA-256 over every array and the header (less its own checksum)."""
    h = hashlib.sha256()
    h.update(json.dumps({k: v for k, v in header.items() if k != "sha256"}, sort_keys=True).encode("utf-8"))
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(name.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def save_model(model: Model, path: str) -> None:
    """Write ``model`` to ``path`` (.npz) atomically."""
    path = os.fspath(path)
    if not path.lower().endswith(MODEL_EXTENSION):
        raise InvalidParameterError(f"{path}: a model file must end in {MODEL_EXTENSION}")
    arrays = {name: getattr(model, name) for name in _ARRAYS}
    if model.scaler.kind != "none":
        arrays["scaler_center"] = model.scaler.center
        arrays["scaler_scale"] = model.scaler.scale
    header = dict(model.meta, format=FORMAT, format_version=FORMAT_VERSION, features=list(model.features),
                  scaler=model.scaler.kind)
    header["sha256"] = _digest(arrays, header)
    arrays["header"] = np.frombuffer(json.dumps(header, sort_keys=True).encode("utf-8"), dtype=np.uint8)
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as handle:
            np.savez_compressed(handle, **arrays)


def load_model(path: str) -> Model:
    """Read a model file, refusing anything that is not an intact GroundSieve model."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such model file")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except Exception as err:  # zip errors, pickled objects refused, ...
        raise InputError(f"{path}: not a GroundSieve model file ({err})") from err
    try:
        header = json.loads(bytes(arrays.pop("header")).decode("utf-8"))
    except Exception as err:
        raise InputError(f"{path}: not a GroundSieve model file (no readable header)") from err
    if header.get("format") != FORMAT:
        raise InputError(f"{path}: not a GroundSieve model file")
    if header.get("format_version") != FORMAT_VERSION:
        raise InputError(f"{path}: model format version {header.get('format_version')} is not supported by "
                         f"this GroundSieve (it reads version {FORMAT_VERSION}); train the model again")
    missing = [name for name in _ARRAYS if name not in arrays]
    if missing or _digest(arrays, header) != header.get("sha256"):
        raise InputError(f"{path}: the model file has been changed or damaged (checksum mismatch); "
                         "it is refused")
    n_nodes = arrays["left"].shape[0]
    for name in ("right", "feature", "threshold", "missing_left"):
        if arrays[name].shape != (n_nodes,):
            raise InputError(f"{path}: inconsistent model arrays")
    features = header["features"]
    if (arrays["feature"].min(initial=0) < 0 or arrays["feature"].max(initial=0) >= len(features)
            or arrays["left"].max(initial=-1) >= n_nodes or arrays["right"].max(initial=-1) >= n_nodes):
        raise InputError(f"{path}: inconsistent model arrays")
    scaler = Scaler(header.get("scaler", "none"), arrays.get("scaler_center"), arrays.get("scaler_scale"))
    meta = {k: v for k, v in header.items() if k not in ("format", "format_version", "features", "scaler", "sha256")}
    return Model(features, arrays["classes"], arrays["roots"], arrays["left"], arrays["right"],
                 arrays["feature"], arrays["threshold"], arrays["missing_left"], arrays["value"], scaler, meta)
