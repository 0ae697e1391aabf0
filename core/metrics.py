"""Accuracy of a ground classification against a reference.

ISPRS definitions (Sithole & Vosselman 2004): Type I = ground called object / all
ground; Type II = object called ground / all object; total = misclassified / all;
Cohen's kappa on the 2x2 table. Precision, recall and F1 are given for the ground class.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .errors import InputError


@dataclass(frozen=True)
class GroundAccuracy:
    tp: int  #: ground called ground
    fn: int  #: ground called object (Type I errors)
    fp: int  #: object called ground (Type II errors)
    tn: int  #: object called object

    @property
    def n(self) -> int:
        return self.tp + self.fn + self.fp + self.tn

    @property
    def type1(self) -> float:
        return self.fn / (self.tp + self.fn) if self.tp + self.fn else 0.0

    @property
    def type2(self) -> float:
        return self.fp / (self.fp + self.tn) if self.fp + self.tn else 0.0

    @property
    def total(self) -> float:
        return (self.fn + self.fp) / self.n if self.n else 0.0

    @property
    def accuracy(self) -> float:
        return 1.0 - self.total

    @property
    def kappa(self) -> float:
        n = self.n
        if n == 0:
            return 0.0
        po = (self.tp + self.tn) / n
        pe = ((self.tp + self.fn) * (self.tp + self.fp) + (self.fp + self.tn) * (self.fn + self.tn)) / (n * n)
        return (po - pe) / (1.0 - pe) if pe < 1.0 else 1.0

    @property
    def precision(self) -> float:
        return self.tp / (self.tp + self.fp) if self.tp + self.fp else 0.0

    @property
    def recall(self) -> float:
        return self.tp / (self.tp + self.fn) if self.tp + self.fn else 0.0

    @property
    def f1(self) -> float:
        p, r = self.precision, self.recall
        return 2 * p * r / (p + r) if p + r else 0.0

    def confusion_matrix(self) -> np.ndarray:
        """Rows: reference (ground, object); columns: predicted (ground, object)."""
        return np.array([[self.tp, self.fn], [self.fp, self.tn]])

    def as_dict(self) -> dict:
        d = asdict(self)
        for key in ("type1", "type2", "total", "kappa", "accuracy", "precision", "recall", "f1"):
            d[key] = getattr(self, key)
        return d

    def summary(self) -> str:
        return (f"Type I {100 * self.type1:.2f} %, Type II {100 * self.type2:.2f} %, "
                f"total {100 * self.total:.2f} %, kappa {100 * self.kappa:.2f} %, "
                f"F1(ground) {100 * self.f1:.2f} %")


def ground_accuracy(reference_ground, predicted_ground) -> GroundAccuracy:
    """Compare two boolean ground masks of the same points."""
    ref = np.asarray(reference_ground, dtype=bool)
    pred = np.asarray(predicted_ground, dtype=bool)
    if ref.shape != pred.shape:
        raise InputError(f"reference and prediction differ in size ({ref.shape} vs {pred.shape})")
    return GroundAccuracy(tp=int(np.count_nonzero(ref & pred)), fn=int(np.count_nonzero(ref & ~pred)),
                          fp=int(np.count_nonzero(~ref & pred)), tn=int(np.count_nonzero(~ref & ~pred)))


@dataclass(frozen=True)
class ClassReport:
    """Per-class precision, recall, F1 and support, overall accuracy, weighted averages and the
    confusion matrix (rows: reference, columns: predicted, in the order of ``classes``)."""
    classes: tuple
    confusion: np.ndarray

    @property
    def support(self) -> np.ndarray:
        return self.confusion.sum(axis=1)

    @property
    def precision(self) -> np.ndarray:
        predicted = self.confusion.sum(axis=0)
        return np.divide(np.diag(self.confusion), predicted, out=np.zeros(len(self.classes)), where=predicted > 0)

    @property
    def recall(self) -> np.ndarray:
        support = self.support
        return np.divide(np.diag(self.confusion), support, out=np.zeros(len(self.classes)), where=support > 0)

    @property
    def f1(self) -> np.ndarray:
        p, r = self.precision, self.recall
        return np.divide(2 * p * r, p + r, out=np.zeros(len(self.classes)), where=(p + r) > 0)

    @property
    def accuracy(self) -> float:
        total = self.confusion.sum()
        return float(np.trace(self.confusion) / total) if total else 0.0

    def weighted(self, values: np.ndarray) -> float:
        support = self.support
        return float((values * support).sum() / support.sum()) if support.sum() else 0.0

    def rows(self):
        """(class, precision, recall, F1, support) per class."""
        return [(c, float(p), float(r), float(f), int(s)) for c, p, r, f, s in
                zip(self.classes, self.precision, self.recall, self.f1, self.support)]

    def table(self, names=None) -> str:
        names = names or {}
        lines = ["| class | precision | recall | F1 | support |", "|---|---:|---:|---:|---:|"]
        for c, p, r, f, s in self.rows():
            lines.append(f"| {names.get(c, c)} | {p:.3f} | {r:.3f} | {f:.3f} | {s:,} |")
        lines.append(f"| overall accuracy | | | {self.accuracy:.3f} | {int(self.support.sum()):,} |")
        lines.append(f"| weighted average | {self.weighted(self.precision):.3f} | {self.weighted(self.recall):.3f} "
                     f"| {self.weighted(self.f1):.3f} | |")
        return "\n".join(lines)


def class_report(reference, predicted, classes=None) -> ClassReport:
    """Multi-class report of ``predicted`` against ``reference`` (any integer labels)."""
    reference = np.asarray(reference)
    predicted = np.asarray(predicted)
    if reference.shape != predicted.shape:
        raise InputError(f"reference and prediction differ in size ({reference.shape} vs {predicted.shape})")
    if classes is None:
        classes = np.union1d(np.unique(reference), np.unique(predicted))
    classes = np.asarray(classes)
    index = {int(c): i for i, c in enumerate(classes)}
    k = len(classes)
    lookup = np.full(256 if classes.max(initial=0) < 256 else int(classes.max()) + 1, -1, dtype=np.int64)
    for c, i in index.items():
        lookup[c] = i
    r = lookup[reference.astype(np.int64)]
    p = lookup[predicted.astype(np.int64)]
    keep = (r >= 0) & (p >= 0)
    confusion = np.bincount(r[keep] * k + p[keep], minlength=k * k).reshape(k, k)
    return ClassReport(tuple(int(c) for c in classes), confusion)
