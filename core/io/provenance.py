"""Which software wrote an output: this GroundSieve's name and version (from the package's
metadata.txt), for the LAS header's generating software and the GeoTIFF's software tag."""
from __future__ import annotations

import functools
import os
import re

#: the folder of this GroundSieve package (its metadata.txt, its core/)
PACKAGE_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def version_of(root: str) -> str:
    """The version in ``root``'s metadata.txt ("unknown" when it has none)."""
    try:
        with open(os.path.join(root, "metadata.txt"), encoding="utf-8") as f:
            m = re.search(r"^version\s*=\s*(\S+)", f.read(), re.M)
        return m.group(1) if m else "unknown"
    except OSError:
        return "unknown"


@functools.lru_cache(maxsize=1)
def package_version() -> str:
    """This GroundSieve's version."""
    return version_of(PACKAGE_ROOT)


def software() -> str:
    """What a LAS header's generating software and a GeoTIFF's software tag say: "GroundSieve 0.1.0"
    (at most 32 bytes, the LAS field's size)."""
    return f"GroundSieve {package_version()}"[:32]
