"""Loads and applies model files in a process of its own, for tests/robustness/test_model_fuzz.py:
a crash or a hang here must not take pytest down with it.

    python _model_worker.py LIST      (LIST: one model file path a line)

Prints, per file, ``START<TAB>name`` before touching it, then one of
``OK``, ``REFUSED`` (an InputError from load_model naming the file), ``UNNAMED`` (an InputError
that does not name the file), ``PREDICT_REFUSED`` (the model loaded but the predictor found it
malformed: a gap in load_model's checks), ``WRONG`` (predictions not valid) or ``ERROR`` (any
other exception), each followed by a tab, the name and a detail."""
import os
import sys

import numpy as np


def _status(path):
    from groundsieve.core.errors import InputError
    from groundsieve.core.learn.model_file import load_model
    name = os.path.basename(path)
    try:
        model = load_model(path)
    except InputError as err:
        return ("REFUSED" if name in str(err) else "UNNAMED"), str(err)
    except Exception as err:  # noqa: BLE001 - what the test is looking for
        return "ERROR", f"load: {type(err).__name__}: {err}"
    rng = np.random.default_rng(0)
    X = rng.normal(size=(64, len(model.features))).astype(np.float32)
    X[rng.random(X.shape) < 0.1] = np.nan
    try:
        proba = model.predict_proba(X)
        predicted = model.predict(X)
    except InputError as err:
        return "PREDICT_REFUSED", str(err)
    except Exception as err:  # noqa: BLE001
        return "ERROR", f"predict: {type(err).__name__}: {err}"
    if proba.shape != (64, model.classes.size) or not np.isfinite(proba).all():
        return "WRONG", f"probabilities of shape {proba.shape}, finite: {np.isfinite(proba).all()}"
    if not np.allclose(proba.sum(axis=1), 1.0, atol=1e-6):
        return "WRONG", "probabilities do not sum to 1"
    if predicted.shape != (64,) or not np.isin(predicted, model.classes).all():
        return "WRONG", f"predicted {predicted[:5]} (classes {model.classes.tolist()})"
    return "OK", f"{len(model.features)} features, classes {model.classes.tolist()}"


def main():
    with open(sys.argv[1], encoding="utf-8") as handle:
        paths = [line.strip() for line in handle if line.strip()]
    for path in paths:
        name = os.path.basename(path)
        print(f"START\t{name}", flush=True)
        status, detail = _status(path)
        print(f"{status}\t{name}\t{' '.join(detail.split())}", flush=True)


if __name__ == "__main__":
    main()
