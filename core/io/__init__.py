"""Point clouds in and out: LAS/LAZ and ISPRS text (``clouds``), surveyed checkpoints as text or CSV
(``checkpoints``) and atomic, checked output paths (``outputs``). May import: errors. The clouds' and
outputs' public names are re-exported here."""
from .clouds import (CLASS_GROUND, CLASS_UNCLASSIFIED, NOISE_CLASSES, READ_EXTENSIONS, TEXT_EXTENSIONS,
                     PointCloud, new_las, read_cloud, write_classified, write_las)
from .outputs import LAS_EXTENSIONS, atomic_path, check_output_path

__all__ = ["CLASS_GROUND", "CLASS_UNCLASSIFIED", "NOISE_CLASSES", "READ_EXTENSIONS", "TEXT_EXTENSIONS", "PointCloud",
           "new_las", "read_cloud", "write_classified", "write_las", "LAS_EXTENSIONS", "atomic_path",
           "check_output_path"]
