"""The ground filters: each a small frozen, validated parameter object called on an (n, 3) array
that returns a ground mask (``smrf``, ``pmf``, ``csf``, ``ptd``, ``echogrid``, ``evc``), with its
numba kernels beside it (``_<filter>_*.py``). A filter sees one cloud or one buffered tile; it
knows nothing of files. May import: errors, progress, validate, grids; never another filter."""
